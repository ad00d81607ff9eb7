"""What every benchmark method wrapper shares: the call contract's types and small helpers.

A method is a callable ``(image0, image1) -> (xy0, xy1, scores, seconds)``: (H, W, 3) float32 RGB images in
[0, 1]; (K, 2) float64 keypoints in pixels of the given images; (K,) float64 dissimilarities (lower is
better); the wall-clock seconds of the matching alone.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import cv2
import numpy as np
import torch

from slime_match.errors import ConfigError

MethodOutput = tuple[np.ndarray, np.ndarray, np.ndarray, float]
MethodFn = Callable[[np.ndarray, np.ndarray], MethodOutput]


def synchronize() -> None:
    """Wait for queued CUDA work so that timings are complete."""
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        torch.cuda.synchronize()


def to_grey(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) float RGB in [0, 1] -> (H, W) float32 luminance."""
    return cv2.cvtColor(np.ascontiguousarray(image, dtype=np.float32), cv2.COLOR_RGB2GRAY)


def empty_output() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """No matches: xy0 (0, 2), xy1 (0, 2), scores (0,)."""
    return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)


def dataclass_from(cls: type, options: dict[str, Any], what: str) -> Any:
    """``cls(**options)``; an option ``cls`` lacks raises ConfigError naming ``what`` and the valid ones."""
    names = set(cls.__dataclass_fields__)
    bad = sorted(set(options) - names)
    if bad:
        raise ConfigError(f"unknown option(s) {bad} for {what}; valid: {sorted(names)}")
    return cls(**options)
