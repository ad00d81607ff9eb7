"""Block-pair planes: the match table, relative orientation, plane expansion and pruning (Secs. 3.3-3.4).

Every block pair l gives a plane: a homography ``H_l`` and its matches ``M_l``.  All the matches of all
block pairs, in original-image pixels, form one :class:`MatchTable`.  :func:`expand_planes` computes for
every plane the set ``P_l`` of table matches compatible with ``H_l`` (reprojection error, plane side,
relative orientation and relative scale); matches in no ``P_l`` are pruned.

Reading of the paper's relative-scale test: the text says the patch scale ratio ``psi = sigma' / sigma``
"must be roughly preserved within the reprojection", "in analogous way to the orientations", but its
equation only bounds the homography's own local scale, ``psi^H_n in [1/t_sigma, t_sigma]``.  By analogy with
the orientation test ``|rho - rho^H_n| < t_theta`` we compare the two: ``psi^H_n / psi in [1/t_sigma,
t_sigma]`` (``relative_scale="patch"``, default).  The literal equation is available as
``relative_scale="homography"``.  For the inverse mapping (``x'``, ``H^-1``) the expected relative
orientation and scale are those from image 2 to image 1, ``-rho`` and ``1 / psi``.
"""

from __future__ import annotations

import itertools
import logging
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields

import numpy as np
import scipy.sparse as sp

from slime_match.errors import ConfigError
from slime_match.slime import plane_kernels

__all__ = [
    "MatchTable",
    "PlaneConfig",
    "deduplicate",
    "expand_planes",
    "group_relative_orientation",
    "relative_orientation",
    "wrap_angle",
]

log = logging.getLogger("slime_match")

_RELATIVE_SCALE_MODES = ("patch", "homography")


@dataclass
class PlaneConfig:
    """Plane expansion thresholds (paper Sec. 3.4).

    Attributes:
        t_perp: two-sided reprojection error bound in px.
        t_theta: relative orientation tolerance in radians (3/8 pi = 67.5 deg).
        t_sigma: relative scale tolerance (ratio).
        relative_scale: "patch" (compare psi^H_n with the patch ratio psi) or "homography" (the paper's
            literal equation: bound psi^H_n alone), see the module docstring.
    """

    t_perp: float = 15.0
    t_theta: float = 3.0 * math.pi / 8.0
    t_sigma: float = 3.0
    relative_scale: str = "patch"

    def __post_init__(self) -> None:
        if self.relative_scale not in _RELATIVE_SCALE_MODES:
            raise ConfigError(
                f"unknown relative_scale {self.relative_scale!r}; choose one of {_RELATIVE_SCALE_MODES}"
            )
        if self.t_perp <= 0 or self.t_theta <= 0 or self.t_sigma < 1:
            raise ConfigError("PlaneConfig: need t_perp > 0, t_theta > 0, t_sigma >= 1")


@dataclass
class MatchTable:
    """All block-pair matches of one image pair, in original-image coordinates.

    Attributes:
        xy0: (M, 2) float64 keypoints in image 1, px.
        xy1: (M, 2) float64 keypoints in image 2, px.
        angle0: (M,) float64 patch orientations theta in image 1, radians.
        angle1: (M,) float64 patch orientations theta' in image 2, radians.
        scale0: (M,) float64 patch scales sigma in image 1, px.
        scale1: (M,) float64 patch scales sigma' in image 2, px.
        weight: (M,) float64 multiplicity (number of merged exact duplicates, 1 otherwise).
        source: (M,) int64 index of the block pair (plane) the match came from.
        score: (M,) float64 match dissimilarity, lower is better.
    """

    xy0: np.ndarray
    xy1: np.ndarray
    angle0: np.ndarray
    angle1: np.ndarray
    scale0: np.ndarray
    scale1: np.ndarray
    weight: np.ndarray
    source: np.ndarray
    score: np.ndarray

    def __post_init__(self) -> None:
        self.xy0 = np.asarray(self.xy0, dtype=np.float64).reshape(-1, 2)
        self.xy1 = np.asarray(self.xy1, dtype=np.float64).reshape(-1, 2)
        for name in ("angle0", "angle1", "scale0", "scale1", "weight", "score"):
            setattr(self, name, np.asarray(getattr(self, name), dtype=np.float64).reshape(-1))
        self.source = np.asarray(self.source, dtype=np.int64).reshape(-1)
        m = len(self.xy0)
        if any(len(getattr(self, f.name)) != m for f in fields(self)):
            raise ValueError("MatchTable: all fields must have the same length")

    def __len__(self) -> int:
        return int(self.xy0.shape[0])

    def subset(self, index: np.ndarray) -> MatchTable:
        """Rows selected by a boolean mask or an index array."""
        return MatchTable(*(getattr(self, f.name)[index] for f in fields(self)))

    @property
    def rho(self) -> np.ndarray:
        """(M,) relative orientations theta' - theta wrapped to (-pi, pi]."""
        return wrap_angle(self.angle1 - self.angle0)


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles (any shape, radians) wrapped to (-pi, pi]."""
    return math.pi - np.mod(math.pi - np.asarray(a, dtype=np.float64), 2.0 * math.pi)


def deduplicate(table: MatchTable, tol: float = 1e-6) -> tuple[MatchTable, np.ndarray]:
    """Merge exact duplicate matches (same xy0 and xy1 up to ``tol`` px) into one weighted row.

    The merged row keeps the attributes of the first occurrence, the best (lowest) score, and the sum of the
    weights.

    Args:
        table: (M rows) match table.
        tol: coordinate quantum in px.

    Returns:
        The (U rows) deduplicated table and (M,) int64 ``inverse`` with ``table row i -> new row inverse[i]``.
    """
    if len(table) == 0:
        return table, np.zeros(0, np.int64)
    key = np.round(np.hstack([table.xy0, table.xy1]) / tol).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    out = table.subset(first)
    out.weight = np.bincount(inverse, weights=table.weight, minlength=len(first))
    out.score = np.full(len(first), np.inf)
    np.minimum.at(out.score, inverse, table.score)
    return out, inverse


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


def expand_planes(
    table: MatchTable, h: np.ndarray, side: np.ndarray, config: PlaneConfig | None = None, threads: int = 1
) -> sp.csr_matrix:
    """Plane expansion and match pruning: the sets P_l of table matches compatible with each H_l.

    A match (x, x', theta, theta', sigma, sigma') joins P_l when all of (paper Sec. 3.4):
        * two-sided reprojection error ``max(|x' - H x|, |x - H^-1 x'|) < t_perp``;
        * plane side: ``sign((H [x; 1])_3) == side[l]``;
        * relative orientation: ``|rho - rho^H_n| < t_theta`` (cyclic) for some neighbour n of x, or
          ``|-rho - rho^{H^-1}_n'| < t_theta`` for some neighbour n' of x' (8 possibilities);
        * relative scale: ``psi^H_n / psi in [1/t_sigma, t_sigma]`` for some n, or
          ``psi^{H^-1}_n' psi in [1/t_sigma, t_sigma]`` for some n' (``relative_scale="patch"``; with
          "homography" the ratio is ``psi^H_n`` and ``psi^{H^-1}_n'`` alone).

    Args:
        table: (M rows) all block-pair matches.
        h: (L, 3, 3) plane homographies, image 1 -> image 2.
        side: (L,) sign (+1/-1) of the third homogeneous coordinate of ``H_l x`` on the plane's own matches.
        config: thresholds; paper defaults when None.
        threads: threads sharing the planes (the compiled loop releases the GIL; the same result for any).

    Returns:
        (L, M) boolean CSR matrix, row l = P_l.
    """
    config = config or PlaneConfig()
    h = np.asarray(h, dtype=np.float64).reshape(-1, 3, 3)
    side = np.sign(np.asarray(side, dtype=np.float64).reshape(-1))
    n_planes, n_matches = len(h), len(table)
    if n_planes == 0 or n_matches == 0:
        return sp.csr_matrix((n_planes, n_matches), dtype=bool)
    psi = table.scale1 / table.scale0 if config.relative_scale == "patch" else np.ones(n_matches)
    forward, backward = h.reshape(-1, 9), np.linalg.inv(h).reshape(-1, 9)

    def expand(part: slice) -> tuple[np.ndarray, np.ndarray]:
        pl, mi = plane_kernels.expansion_pairs(forward[part], backward[part], side[part], table.xy0, table.xy1,
                                               table.rho, psi, config.t_perp, config.t_theta, config.t_sigma)
        return pl + part.start, mi

    if threads > 1:
        bounds = np.unique(np.linspace(0, n_planes, min(n_planes, 4 * threads) + 1).astype(int))
        with ThreadPoolExecutor(threads) as pool:  # a few parts per thread: even loads
            found = list(pool.map(expand, [slice(a, b) for a, b in itertools.pairwise(bounds)]))
        pl, mi = (np.concatenate(column) for column in zip(*found))
    else:
        pl, mi = expand(slice(0, n_planes))
    log.debug("expand_planes: %d planes x %d matches -> %d memberships", n_planes, n_matches, len(pl))
    indptr = np.concatenate([[0], np.cumsum(np.bincount(pl, minlength=n_planes))])  # pl is ascending
    return sp.csr_matrix((np.ones(len(pl), dtype=bool), mi, indptr), shape=(n_planes, n_matches))
