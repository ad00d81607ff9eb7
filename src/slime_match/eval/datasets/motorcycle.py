"""The bundled rectified stereo pair: scikit-image's Middlebury motorcycle with its disparity."""

from __future__ import annotations

import math

import numpy as np

from slime_match.errors import ConfigError
from slime_match.eval.datasets.pair import Pair


def stereo_motorcycle() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """scikit-image's Middlebury motorcycle stereo pair: left and right (H, W, 3) uint8 RGB images and the left
    image's disparity (H, W) float, where left (x, y) corresponds to right (x - d, y) (non-finite: unknown).

    Raises:
        ConfigError: scikit-image (the package's ``demo`` extra) is not installed.
    """
    try:
        from skimage.data import stereo_motorcycle as load
    except ImportError as error:
        raise ConfigError("the motorcycle stereo pair comes with scikit-image: pip install 'slime-match[demo]' "
                          "(or scikit-image)") from error
    return load()


def read_motorcycle() -> list[Pair]:
    """scikit-image's Middlebury motorcycle stereo pair (arrays) with its left disparity map."""
    left, right, disp = stereo_motorcycle()
    F = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]) / math.sqrt(2)
    return [Pair("motorcycle", left, right, "disparity", F=F, disparity=disp.astype(np.float32))]
