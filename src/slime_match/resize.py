"""Working size of an image: resize it so that it fits a size limit, and map points back to the original.

Pixel coordinates are ``(x, y)`` with the centre of the top-left pixel at ``(0, 0)``; the scale factors
``(sx, sy)`` are original / resized size, so a resized-frame point ``x`` is ``(x + 0.5) * sx - 0.5`` in the
original frame (pixel centres map to pixel centres).
"""

from __future__ import annotations

import numpy as np

from slime_match.features.image_ops import resize_area


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
) -> tuple[np.ndarray, tuple[float, float]]:
    """Resize an (H, W[, C]) image to its :func:`working_size` (with
    :func:`~slime_match.features.image_ops.resize_area`: area interpolation when shrinking); returns it and
    the (sx, sy) factors original / resized ((1, 1) and the same array when nothing changes)."""
    h, w = image.shape[:2]
    nw, nh = working_size(w, h, max_side, size)
    if (nw, nh) == (w, h):
        return image, (1.0, 1.0)
    return resize_area(image, (nw, nh)), (w / nw, h / nh)


def to_original(xy: np.ndarray, scale: tuple[float, float]) -> np.ndarray:
    """(N, 2) resized-frame points to the original frame, given (sx, sy) = original / resized."""
    s = np.asarray(scale, np.float64)
    return (np.asarray(xy, np.float64) + 0.5) * s - 0.5


def to_original_matrix(scale: tuple[float, float]) -> np.ndarray:
    """(3, 3) homogeneous form of :func:`to_original`: resized-frame pixels to original-frame pixels."""
    sx, sy = scale
    return np.array([[sx, 0.0, 0.5 * (sx - 1.0)], [0.0, sy, 0.5 * (sy - 1.0)], [0.0, 0.0, 1.0]])


def homography_to_original(
    H: np.ndarray, scale0: tuple[float, float], scale1: tuple[float, float]
) -> np.ndarray:
    """(..., 3, 3) homographies between two resized frames, as homographies between the original frames."""
    return to_original_matrix(scale1) @ np.asarray(H, np.float64) @ np.linalg.inv(to_original_matrix(scale0))
