"""Working size of an image: resize it so that it fits a size limit; its frame maps points back to the
original (:class:`~slime_match.geometry.frames.Frame`: pixel centres at integers, edges kept).
"""

from __future__ import annotations

import numpy as np

from slime_match.features.image_ops import resize_area
from slime_match.geometry.frames import Frame


def working_size(
    width: int, height: int, max_side: int | None = None, size: tuple[int, int] | None = None
) -> tuple[int, int]:
    """(w, h) an image of ``width x height`` px is resized to: a fixed ``size`` wins (a landscape ``size`` is
    transposed for portrait images), else the longest side is brought down to ``max_side`` (never up)."""
    if size is not None:
        long, short = max(size), min(size)
        return (int(long), int(short)) if width >= height else (int(short), int(long))
    if max_side is not None and max(width, height) > max_side:
        s = max_side / max(width, height)
        return max(1, round(width * s)), max(1, round(height * s))
    return int(width), int(height)


def resize_image(
    image: np.ndarray, max_side: int | None = None, size: tuple[int, int] | None = None
) -> tuple[np.ndarray, Frame]:
    """Resize an (H, W[, C]) image to its :func:`working_size` (area interpolation when shrinking); returns it
    and its frame (``Frame()`` and the same array when nothing changes)."""
    h, w = image.shape[:2]
    nw, nh = working_size(w, h, max_side, size)
    if (nw, nh) == (w, h):
        return image, Frame()
    return resize_area(image, (nw, nh)), Frame.of_sizes((nw, nh), (w, h))
