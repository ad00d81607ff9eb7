"""Orientation histograms of Slime: relative orientations of matches, their dominant bin, angle wrapping.

Bins are cyclic, ``bins`` of them centred on ``k 2 pi / bins`` (so 0, the upright case, is a bin centre): the
block-pair re-run (Sec. 3.3), the per-set and global orientations (Sec. 3.7) and the fixed-orientation
descriptors (Secs. 3.3 and 3.8) share them.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["group_relative_orientation", "orientation_bin", "relative_orientation", "wrap_angle"]


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles (any shape, radians) wrapped to (-pi, pi]."""
    return math.pi - np.mod(math.pi - np.asarray(a, dtype=np.float64), 2.0 * math.pi)


def group_relative_orientation(
    rho: np.ndarray, group: np.ndarray, n_groups: int, bins: int = 16, weights: np.ndarray | None = None
) -> np.ndarray:
    """Dominant relative orientation of many groups of matches at once (histogram mode).

    The histogram has ``bins`` cyclic bins centred on ``k 2 pi / bins`` (so 0, the upright case, is a bin
    centre); the result is the centre of the fullest bin (the lowest one on ties).

    Args:
        rho: (K,) relative orientations theta' - theta, radians.
        group: (K,) int group index of each entry, in [0, n_groups).
        n_groups: number of groups G.
        bins: number of histogram bins.
        weights: (K,) entry weights (1 when None).

    Returns:
        (G,) orientations in (-pi, pi]; NaN for empty groups.
    """
    width = 2.0 * math.pi / bins
    b = np.mod(np.round(np.asarray(rho, dtype=np.float64) / width).astype(np.int64), bins)
    hist = np.bincount(
        np.asarray(group, dtype=np.int64) * bins + b, weights=weights, minlength=n_groups * bins
    ).reshape(n_groups, bins)
    out = wrap_angle(np.argmax(hist, axis=1) * width)
    out[hist.sum(axis=1) <= 0] = np.nan
    return out


def relative_orientation(
    angle0: np.ndarray, angle1: np.ndarray, bins: int = 16, weights: np.ndarray | None = None
) -> float:
    """Global relative orientation of a set of matches (paper Secs. 3.3 and 3.6).

    Args:
        angle0: (K,) patch orientations theta in image 1, radians.
        angle1: (K,) patch orientations theta' in image 2, radians.
        bins: number of cyclic histogram bins of rho = theta' - theta (16 in the paper).
        weights: (K,) match weights (1 when None).

    Returns:
        Centre of the fullest bin in (-pi, pi] (bins centred on multiples of 2 pi / bins); NaN when K = 0.
    """
    rho = np.asarray(angle1, dtype=np.float64) - np.asarray(angle0, dtype=np.float64)
    return float(group_relative_orientation(rho, np.zeros(len(rho), np.int64), 1, bins, weights)[0])


def orientation_bin(angle: float, bins: int) -> int:
    """Index of the histogram bin whose centre is ``angle`` (radians), bins of 2 pi / bins from 0."""
    return round(angle / (2 * math.pi / bins)) % bins
