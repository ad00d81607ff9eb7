"""The bundled rectified stereo pair: scikit-image's Middlebury motorcycle with its disparity."""

from __future__ import annotations

import math

import numpy as np

from slime_match.eval.datasets.pair import Pair


def read_motorcycle() -> list[Pair]:
    """scikit-image's Middlebury motorcycle stereo pair (arrays) with its left disparity map."""
    from skimage.data import stereo_motorcycle

    left, right, disp = stereo_motorcycle()
    F = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]) / math.sqrt(2)
    return [Pair("motorcycle", left, right, "disparity", F=F, disparity=disp.astype(np.float32))]
