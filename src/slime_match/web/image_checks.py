"""The images the server takes: their size read from the file's header before anything decodes them, so that
a small file of a huge image (a decompression bomb) is refused; and the few decodings the server process does
itself (an upload's check, an image shown in the browser), one at a time."""

from __future__ import annotations

import io
import threading
import warnings
from pathlib import Path

from ..io import IMAGE_EXTS, MIN_IMAGE_SIDE
from .api_errors import ApiError

MAX_IMAGE_PIXELS = 40_000_000  # larger images are refused before decoding (float32 RGB: 480 MB)
DECODING = threading.BoundedSemaphore(1)  # decodings in the server process at once


def image_size(source: Path | bytes, name: str, max_pixels: int = MAX_IMAGE_PIXELS) -> tuple[int, int]:
    """(width, height) in px of an image file or its bytes, read from the header only.

    Args:
        name: the image as the user knows it (a served folder's path, an upload's name), for the messages.

    Raises:
        ApiError: not an image file name (415), not an image (415), over ``max_pixels`` (413), or a side under
            the matcher's minimum (415).
    """
    from PIL import Image, UnidentifiedImageError

    if isinstance(source, Path) and source.suffix.lower() not in IMAGE_EXTS:
        raise ApiError(f"{name!r} is not an image file name: expected one of {', '.join(IMAGE_EXTS)}", 415)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # refused below, by our own limit
            with Image.open(io.BytesIO(source) if isinstance(source, bytes) else source) as opened:
                width, height = opened.size
    except Image.DecompressionBombError:
        raise ApiError(f"{name!r} is too large an image to decode safely", 413) from None
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError):
        raise ApiError(f"{name!r} is not an image (its header is not one of a known image format)", 415) from None
    if width * height > max_pixels:
        raise ApiError(f"{name!r} has {width}x{height} px ({width * height / 1e6:.0f} MP), over the limit of "
                       f"{max_pixels / 1e6:g} MP", 413)
    if min(width, height) < MIN_IMAGE_SIDE:
        raise ApiError(f"{name!r} has {width}x{height} px, smaller than {MIN_IMAGE_SIDE} px on a side (the "
                       "matcher's minimum)", 415)
    return int(width), int(height)
