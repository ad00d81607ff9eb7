"""Reading the files of a dataset folder: 3x3 matrices, images, exclusion masks, folders."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from slime_match.errors import ConfigError
from slime_match.io import IMAGE_EXTS


def read_matrix(path: Path) -> np.ndarray:
    """(3, 3) float64 matrix from a text file."""
    m = np.loadtxt(path, dtype=np.float64)
    if m.shape != (3, 3):
        raise ConfigError(f"{path}: expected a 3x3 matrix, got shape {m.shape}")
    return m


def read_image(image: Path | np.ndarray) -> np.ndarray:
    """Image array of a file (as stored, cv2.IMREAD_UNCHANGED); arrays pass through."""
    if isinstance(image, np.ndarray):
        return image
    img = cv2.imread(str(image), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FileNotFoundError(f"cannot read image {image}")
    return img


def read_mask(path: Path) -> np.ndarray | None:
    """(H, W) bool exclusion mask (non-zero = excluded) of an image file; None when the file is absent."""
    if not path.is_file():
        return None
    m = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if m is None:
        raise FileNotFoundError(f"cannot read mask {path}")
    return m > 0


def find_image(folder: Path, stem: str) -> Path | None:
    """Image file ``folder/<stem><ext>`` with any known extension (either case); None when absent."""
    for ext in IMAGE_EXTS:
        for cand in (folder / f"{stem}{ext}", folder / f"{stem}{ext.upper()}"):
            if cand.is_file():
                return cand
    return None


def require_dir(path: Path | str, what: str) -> Path:
    """``path`` as a Path; FileNotFoundError naming ``what`` when it is not a folder."""
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"{what}: folder {path} does not exist")
    return path
