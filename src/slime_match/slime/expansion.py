"""Plane expansion and match pruning (Sec. 3.4).

Every block pair l gives a plane: a homography ``H_l`` and its matches ``M_l``, all of them in one
:class:`~.match_table.MatchTable` in original-image pixels.  :func:`expand_planes` computes for
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
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from slime_match.errors import ConfigError
from slime_match.slime import plane_kernels

from .match_table import MatchTable

__all__ = ["RELATIVE_SCALE_MODES", "Expansion", "PlaneConfig", "expand_planes"]

log = logging.getLogger("slime_match")

RELATIVE_SCALE_MODES = ("patch", "homography")


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
        if self.relative_scale not in RELATIVE_SCALE_MODES:
            raise ConfigError(
                f"unknown relative_scale {self.relative_scale!r}; choose one of {RELATIVE_SCALE_MODES}"
            )
        if self.t_perp <= 0 or self.t_theta <= 0 or self.t_sigma < 1:
            raise ConfigError("PlaneConfig: need t_perp > 0, t_theta > 0, t_sigma >= 1")


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


@dataclass
class Expansion:
    """Sec. 3.4's output: the (L, M) boolean CSR plane memberships, row l = P_l."""

    memberships: sp.csr_matrix

    @property
    def counts(self) -> dict[str, int]:
        return {"expanded_memberships": int(self.memberships.nnz)}

    def arrays(self) -> dict[str, np.ndarray]:
        """(plane, match) of every membership, for ``--save-stages``."""
        coo = self.memberships.tocoo()
        return {"expanded_plane": coo.row.astype(np.int64), "expanded_match": coo.col.astype(np.int64)}
