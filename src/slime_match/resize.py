"""Working size of an image: the size matching runs at, and its frame, which maps points back to the original
(:class:`~slime_match.geometry.frames.Frame`: pixel centres at integers, edges kept).

The size policy scales an image by one factor (its aspect ratio kept) so that its shorter side reaches
``min_side`` (small images are upsampled) and its longer side stays within ``max_side`` (large images are
shrunk); ``max_side`` wins when an elongated image cannot meet both. The two images of a pair share one factor
when one factor meets both images' limits (:func:`pair_factors`), so that their relative scale, and what a
pixel threshold means in each, stay as given. A fixed ``size`` (an evaluation protocol's, such as ScanNet's
640 x 480) replaces the policy.
"""

from __future__ import annotations

import numpy as np

from slime_match.features.image_ops import resize_area, resize_lanczos
from slime_match.geometry.frames import Frame
from slime_match.io import MIN_IMAGE_SIDE


def working_factor(width: int, height: int, min_side: int | None = None, max_side: int | None = None) -> float:
    """Working px per original px for a ``width x height`` image: 1 when its sides are within the limits, else
    the factor that brings its shorter side up to ``min_side`` or its longer side down to ``max_side``
    (``max_side`` wins). None or 0 turns a limit off."""
    factor = 1.0
    if min_side and min(width, height) < min_side:
        factor = min_side / min(width, height)
    if max_side and max(width, height) * factor > max_side:
        factor = max_side / max(width, height)
    return factor


def pair_factors(
    size0: tuple[int, int], size1: tuple[int, int], min_side: int | None = None, max_side: int | None = None
) -> tuple[float, float]:
    """Working factors of two images of (W, H) ``size0`` and ``size1`` px: one factor for both, the closest to 1
    that brings each shorter side to at least ``min_side`` (and :data:`~slime_match.io.MIN_IMAGE_SIDE`) and each
    longer side to at most ``max_side``; when no factor meets both images' limits, each image's own
    :func:`working_factor`."""
    low = max((min_side or MIN_IMAGE_SIDE) / min(size) for size in (size0, size1))
    high = min([float("inf")] + [max_side / max(size) for size in (size0, size1) if max_side])
    if low <= high:
        shared = min(max(1.0, low), high)
        return shared, shared
    return working_factor(*size0, min_side, max_side), working_factor(*size1, min_side, max_side)


def working_size(
    width: int,
    height: int,
    max_side: int | None = None,
    size: tuple[int, int] | None = None,
    min_side: int | None = None,
    factor: float | None = None,
) -> tuple[int, int]:
    """(w, h) an image of ``width x height`` px is resized to: a fixed ``size`` wins (a landscape ``size`` is
    transposed for portrait images), else both sides are scaled by :func:`working_factor` (or by ``factor`` when
    given, e.g. from :func:`pair_factors`) and rounded."""
    if size is not None:
        long, short = max(size), min(size)
        return (int(long), int(short)) if width >= height else (int(short), int(long))
    if factor is None:
        factor = working_factor(width, height, min_side, max_side)
    if factor == 1.0:
        return int(width), int(height)
    return max(1, round(width * factor)), max(1, round(height * factor))


def resize_image(
    image: np.ndarray,
    max_side: int | None = None,
    size: tuple[int, int] | None = None,
    min_side: int | None = None,
    factor: float | None = None,
) -> tuple[np.ndarray, Frame]:
    """Resize an (H, W[, C]) image to its :func:`working_size` (``factor``, when given, replaces the limits);
    returns it and its frame (``Frame()`` and the same array when nothing changes).

    Shrinking uses area interpolation; the policy's upsampling (``min_side``) uses Lanczos3
    (:func:`~slime_match.features.image_ops.resize_lanczos`, the resampler of Slime's block levels), clipped to
    the input's range of values; a fixed ``size`` larger than the image is bilinear.
    """
    h, w = image.shape[:2]
    nw, nh = working_size(w, h, max_side, size, min_side, factor)
    if (nw, nh) == (w, h):
        return image, Frame()
    if size is None and nw > w:
        factor = working_factor(w, h, min_side, max_side) if factor is None else factor
        grown = resize_lanczos(image, factor)  # (nh, nw): the same rounding as working_size
        grown = np.clip(grown, image.min(), image.max()).astype(grown.dtype, copy=False)
        return grown, Frame.of_sizes((nw, nh), (w, h))
    return resize_area(image, (nw, nh)), Frame.of_sizes((nw, nh), (w, h))
