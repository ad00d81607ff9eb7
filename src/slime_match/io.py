"""Image loading (any bit depth / channel count -> float RGB) and atomic result files."""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from .errors import ImageError, SlimeMatchError, some_of

MIN_IMAGE_SIDE = 32
IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".ppm", ".pgm", ".bmp", ".tif", ".tiff", ".webp")  # image file suffixes

ImageLike = str | os.PathLike | np.ndarray | torch.Tensor


def load_image(source: ImageLike) -> np.ndarray:
    """Load an image as float32 RGB in [0, 1].

    Args:
        source: a file path, a numpy array (H, W), (H, W, 1|3|4) of uint8/uint16/float, or a torch tensor
            (C, H, W) or (H, W, C) with C in {1, 3, 4}. Float inputs are assumed in [0, 1] (values above
            1.5 are taken as 0..255; NaN and infinite pixels as black). Grey is replicated to RGB; alpha is
            dropped. Files are turned upright by their EXIF orientation tag, as image viewers show them
            (keypoints are in that frame).

    Returns:
        (H, W, 3) float32 array in [0, 1].

    Raises:
        ImageError: missing/unreadable/non-image file, wrong array shape, or a side < 32 px.
    """
    if isinstance(source, (str, os.PathLike)):
        array = _read_file(Path(source))
        name = str(source)
    elif isinstance(source, torch.Tensor):
        array = _tensor_to_hwc(source)
        name = "tensor input"
    elif isinstance(source, np.ndarray):
        array = source
        name = "array input"
    else:
        raise ImageError(f"unsupported image type {type(source).__name__}: give a path, numpy array or tensor")
    image = _to_float_rgb(array, name)
    height, width = image.shape[:2]
    if min(height, width) < MIN_IMAGE_SIDE:
        raise ImageError(f"{name}: image is {width}x{height} px, smaller than {MIN_IMAGE_SIDE} px on a side")
    return image


def image_size(path: str | os.PathLike) -> tuple[int, int]:
    """(width, height) in px of an image file as :func:`load_image` gives it (upright by its EXIF orientation).

    Raises:
        ImageError: missing, unreadable or non-image file.
    """
    height, width = _read_file(Path(path)).shape[:2]
    return width, height


def _read_file(path: Path) -> np.ndarray:
    if not path.exists():
        raise ImageError(f"{path}: no such file")
    if path.is_dir():
        raise ImageError(f"{path}: is a directory, not an image")
    data = np.fromfile(str(path), dtype=np.uint8)
    # any bit depth and channel count, EXIF orientation applied (IMREAD_UNCHANGED would ignore it)
    with _opencv_silent():  # a corrupt file gets our ImageError below, not OpenCV's decoder log lines too
        image = cv2.imdecode(data, cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR) if data.size else None
    if image is None:
        raise ImageError(f"{path}: not a readable image (corrupt file or unsupported format)")
    if image.ndim == 3:  # OpenCV gives BGR, alpha already dropped
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    return image


@contextmanager
def _opencv_silent():
    """OpenCV's own log (its C++ warnings and errors on stderr) off for the block, then back as it was.

    OpenCV 5 exposes the level in ``cv2.utils.logging``, OpenCV 4 as ``cv2.getLogLevel`` / ``cv2.setLogLevel``;
    level 0 is silent in both."""
    log = getattr(cv2.utils, "logging", None) or cv2
    level = log.getLogLevel()
    log.setLogLevel(0)  # LOG_LEVEL_SILENT
    try:
        yield
    finally:
        log.setLogLevel(level)


def _tensor_to_hwc(tensor: torch.Tensor) -> np.ndarray:
    array = tensor.detach().cpu()
    if array.dtype in (torch.bfloat16, torch.float16):  # numpy has no bfloat16
        array = array.float()
    if array.ndim == 4 and array.shape[0] == 1:
        array = array[0]
    if array.ndim == 3 and array.shape[0] in (1, 3, 4) and array.shape[-1] not in (1, 3, 4):
        array = array.permute(1, 2, 0)
    return array.numpy()


def _to_float_rgb(array: np.ndarray, name: str) -> np.ndarray:
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] not in (3, 4)):
        raise ImageError(f"{name}: expected an (H, W), (H, W, 3) or (H, W, 4) image, got shape {array.shape}")
    if array.dtype == np.uint8:
        image = array.astype(np.float32) / 255.0
    elif array.dtype == np.uint16:
        image = array.astype(np.float32) / 65535.0
    elif np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer):
        image = array.astype(np.float32)
        finite = np.isfinite(image)
        if not finite.all():
            image = np.where(finite, image, 0.0)
        if image.max(initial=0.0) > 1.5:
            image = image / 255.0
    else:
        raise ImageError(f"{name}: unsupported pixel type {array.dtype}")
    if image.ndim == 2:
        image = np.repeat(image[:, :, None], 3, axis=2)
    return np.ascontiguousarray(np.clip(image[:, :, :3], 0.0, 1.0))


def to_tensor(image: np.ndarray, device: str | torch.device = "cpu") -> torch.Tensor:
    """(H, W, 3) float array -> (3, H, W) float32 tensor on ``device``."""
    return torch.from_numpy(np.ascontiguousarray(image.transpose(2, 0, 1))).to(device=device, dtype=torch.float32)


def load_npz(path: str | os.PathLike, what: str, required: tuple[str, ...] = (), hint: str = ""
             ) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` file this package wrote.

    Args:
        path: the file.
        what: what the file should be, for the messages (e.g. "matches file").
        required: names of arrays it must hold.
        hint: appended to the messages (e.g. how to write such a file).

    Raises:
        SlimeMatchError: the file is missing, not an .npz archive, unreadable or without a required array.
    """
    path = Path(path)
    if not path.is_file():
        problem = f"no such {what}"
    elif not zipfile.is_zipfile(path):
        problem = f"not a {what} (not an .npz archive)"
    else:
        try:
            with np.load(path) as data:
                arrays = {name: data[name] for name in data.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:
            problem = f"not a readable {what} ({error})"
        else:
            missing = [name for name in required if name not in arrays]
            if not missing:
                return arrays
            problem = f"not a {what}: it has no {some_of(missing, 3)}"
    raise SlimeMatchError(f"{path}: {problem}{hint}")


def _atomic_write(path: Path, write) -> None:
    """Write through a temporary file in the same folder, then rename: never a half-written file. The file
    gets the permissions of a plain ``open`` under the process umask (mkstemp's own are owner-only)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~current_umask())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def current_umask() -> int:
    """The process umask, read from /proc where it can be (setting it to read it back races other threads)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def save_npz(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    """Save arrays to ``path`` (.npz) atomically."""

    def write(tmp: str) -> None:
        with open(tmp, "wb") as handle:
            np.savez(handle, **arrays)

    _atomic_write(Path(path), write)


def save_json(path: str | os.PathLike, obj: Any) -> None:
    """Save a JSON-serialisable object to ``path`` atomically (numpy scalars/arrays converted)."""

    def write(tmp: str) -> None:
        with open(tmp, "w") as handle:
            json.dump(obj, handle, indent=2, default=_json_default)
            handle.write("\n")

    _atomic_write(Path(path), write)


def save_text(path: str | os.PathLike, text: str) -> None:
    """Save a text file (UTF-8) atomically."""
    _atomic_write(Path(path), lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def save_figure(path: str | os.PathLike, figure) -> None:
    """Save a matplotlib figure atomically (format from the file suffix)."""
    suffix = Path(path).suffix.lstrip(".") or "png"
    _atomic_write(Path(path), lambda tmp: figure.savefig(tmp, format=suffix, dpi=110, bbox_inches="tight"))


def jsonable(obj: Any) -> Any:
    """``obj`` as it reads back from :func:`save_json` (tuples as lists, numpy values and paths converted)."""
    return json.loads(json.dumps(obj, default=_json_default))


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
