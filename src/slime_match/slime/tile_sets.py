"""Tile sets: the block planes split by image tiles, and the best sets per tile pair and per tile (Sec. 3.5).

All match sets are sets of rows of one :class:`~.match_table.MatchTable`, stored together in
a :class:`TileSets` (CSR layout: set -> sorted match indices, with its plane l and tile pair (c, c')).
Secs. 3.5-3.7 select among them (:mod:`.epipolar_vote`, :mod:`.fusion`)::

    sets = tile_sets(table, planes, tiles0, tiles1)               # all H^l_v
    star = sets.subset(best_sets_per_tile_pair(sets, w))          # H*   (q = 2 per tile pair)
    sup = star.subset(best_sets_per_tile(star, w))                # H    (q = 4 per tile, both images)
    keep = epipolar_consistency(table, sup)                       # M+
    filt = sup.restrict(keep)                                     # F^l_v = H^l_v & M+
    fbar = filt.subset(greedy_two_per_tile(filt, w, groups=plane_groups(filt, 1 / 3)))  # F-bar
    fused = fuse_planes(sets.restrict(keep), fbar, w)             # F^{l*}_v
    ok, theta, theta_plus = global_orientation_filter(table, fused)
    final = fused.subset(ok)                                      # F^theta

Cardinalities ``|.|`` are weighted by the table's duplicate weights when ``weights`` is given.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from slime_match._runtime.options import check_choice, check_integer
from slime_match.errors import ConfigError
from slime_match.slime.tile_kernels import greedy_cover, tile_pair_sets

from .blocks import Block, points_in_blocks
from .match_table import MatchTable

__all__ = ["SAME_HOMOGRAPHY", "TileConfig", "TileSets", "best_sets_per_tile", "best_sets_per_tile_pair", "tile_sets"]

log = logging.getLogger("slime_match")


SAME_HOMOGRAPHY = ("shared", "iou", "set")
VOTE_RULES = ("consensus", "paper")


@dataclass
class TileConfig:
    """Parameters of the tile-level set logic (paper Secs. 3.5-3.7).

    Attributes:
        q_pair: best sets kept per tile pair (H*).
        q_tile: best sets kept per tile of each image (H).
        t_perp: epipolar distance threshold in px.
        t_xi: a match is kept when it is an inlier of more than ``t_xi |H|`` of the F_dd'.
        vote: which rule selects M+ (``VOTE_RULES``): "paper", the ``t_xi |H|`` vote alone; "consensus",
            the vote, and when it keeps fewer than ``min_union`` matches, the largest epipolar geometry that
            ``min_planes`` distinct homographies share instead (``consensus.epipolar_consensus``).
        min_planes: distinct homographies that must agree on one epipolar geometry for it to count as
            confirmed (two fix it, each more confirms it).
        min_union: F_dd' is estimated only from unions with at least this many distinct matches (the
            8-point algorithm is underdetermined below 8; such pairs vote for nothing).
        t_ov: IoU above which two sets of the same tile pair are fused.
        same_homography: when sets of different planes count as one homography for F-bar's two per tile:
            "shared" (planes sharing more than t_ov of the smaller one's matches), "iou" (planes with IoU
            > t_ov) or "set" (never: every set takes a slot, the literal reading); see ``plane_groups``.
        bins: orientation histogram bins.
        t_theta_plus: tolerance to the global orientation, radians (pi/4).
        chunk: (F, match) pairs evaluated at once in the epipolar vote.
    """

    q_pair: int = 2
    q_tile: int = 4
    t_perp: float = 15.0
    t_xi: float = 9.0
    vote: str = "consensus"
    min_planes: int = 3
    min_union: int = 8
    t_ov: float = 1.0 / 3.0
    same_homography: str = "shared"
    bins: int = 16
    t_theta_plus: float = math.pi / 4.0
    chunk: int = 4_000_000

    def __post_init__(self) -> None:
        if min(self.q_pair, self.q_tile, self.bins, self.chunk) < 1 or self.min_union < 8:
            raise ConfigError("TileConfig: q_pair, q_tile, bins, chunk must be >= 1 and min_union >= 8")
        if self.t_perp <= 0 or self.t_xi < 0 or not 0 <= self.t_ov < 1 or self.t_theta_plus <= 0:
            raise ConfigError("TileConfig: need t_perp > 0, t_xi >= 0, 0 <= t_ov < 1, t_theta_plus > 0")
        check_choice("vote", self.vote, VOTE_RULES)
        check_integer("min_planes", self.min_planes, 3)
        if self.same_homography not in SAME_HOMOGRAPHY:
            raise ConfigError(f"TileConfig: same_homography {self.same_homography!r} is not one of "
                              f"{', '.join(SAME_HOMOGRAPHY)}")


DEFAULTS = TileConfig()  # the defaults, for the signatures of Secs. 3.5-3.7


@dataclass
class TileSets:
    """Many match sets over one match table, in CSR layout.

    Attributes:
        plane: (S,) int64 plane (block pair) index l of each set.
        tile0: (S,) int64 tile c in image 1.
        tile1: (S,) int64 tile c' in image 2.
        indptr: (S + 1,) int64; set s holds ``indices[indptr[s]:indptr[s + 1]]``.
        indices: (nnz,) int64 match indices (rows of the table), sorted within each set.
        n_matches: number M of rows of the table.
    """

    plane: np.ndarray
    tile0: np.ndarray
    tile1: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    n_matches: int

    def __len__(self) -> int:
        return int(self.plane.shape[0])

    @classmethod
    def from_csr(
        cls, mat: sp.csr_matrix, plane: np.ndarray, tile0: np.ndarray, tile1: np.ndarray
    ) -> TileSets:
        """Sets from the nonzero pattern of an (S, M) sparse matrix."""
        mat = sp.csr_matrix(mat)
        mat.eliminate_zeros()
        mat.sort_indices()
        return cls(
            np.asarray(plane, np.int64),
            np.asarray(tile0, np.int64),
            np.asarray(tile1, np.int64),
            mat.indptr.astype(np.int64),
            mat.indices.astype(np.int64),
            mat.shape[1],
        )

    @property
    def set_of_entry(self) -> np.ndarray:
        """(nnz,) set index of each entry of ``indices``."""
        return np.repeat(np.arange(len(self)), np.diff(self.indptr))

    def members(self, s: int) -> np.ndarray:
        """Match indices of set ``s``."""
        return self.indices[self.indptr[s] : self.indptr[s + 1]]

    def matrix(self, weights: np.ndarray | None = None) -> sp.csr_matrix:
        """(S, M) CSR matrix: ``weights[m]`` (float) where m is in the set, or bool when weights is None."""
        data = np.ones(len(self.indices), bool) if weights is None else np.asarray(weights)[self.indices]
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(len(self), self.n_matches))

    def sizes(self, weights: np.ndarray | None = None) -> np.ndarray:
        """(S,) cardinalities, weighted by the (M,) ``weights`` when given."""
        if weights is None:
            return np.diff(self.indptr).astype(np.float64)
        return np.bincount(self.set_of_entry, np.asarray(weights)[self.indices], minlength=len(self))

    def union(self) -> np.ndarray:
        """(M,) bool: matches in at least one set."""
        out = np.zeros(self.n_matches, bool)
        out[self.indices] = True
        return out

    def subset(self, ids: np.ndarray) -> TileSets:
        """The sets selected by an index array or a boolean mask, in that order."""
        ids = np.arange(len(self))[ids]
        return TileSets.from_csr(self.matrix()[ids], self.plane[ids], self.tile0[ids], self.tile1[ids])

    def restrict(self, keep: np.ndarray) -> TileSets:
        """Every set intersected with the (M,) bool ``keep`` (same sets, possibly empty)."""
        kept = np.flatnonzero(np.asarray(keep, bool)[self.indices])  # positions of the kept entries
        return TileSets(self.plane, self.tile0, self.tile1, np.searchsorted(kept, self.indptr), self.indices[kept],
                        self.n_matches)


def tile_sets(table: MatchTable, planes: sp.csr_matrix, tiles0: list[Block], tiles1: list[Block]) -> TileSets:
    """All tile-pair sets H^l_cc' = {m in P_l : x_m in tile c, x'_m in tile c'} (paper Eq. tile_set).

    The bound ``eps^H_l < t_perp`` of the equation holds by construction of P_l (:func:`expand_planes`).

    Args:
        table: (M rows) match table.
        planes: (L, M) boolean CSR, row l = P_l.
        tiles0: tiles of image 1 (``make_tiles``); a point may lie in several (overlapping cores).
        tiles1: tiles of image 2.

    Returns:
        The non-empty sets, sorted by (l, c, c').
    """
    planes = sp.csr_matrix(planes)
    if not planes.has_sorted_indices:
        planes = planes.sorted_indices()
    t0 = points_in_blocks(table.xy0, tiles0).T.tocsr()  # (M, C0)
    t1 = points_in_blocks(table.xy1, tiles1).T.tocsr()
    plane, tile0, tile1, indptr, indices = tile_pair_sets(
        planes.indptr.astype(np.int64), planes.indices.astype(np.int64), t0.indptr.astype(np.int64),
        t0.indices.astype(np.int64), t1.indptr.astype(np.int64), t1.indices.astype(np.int64), len(tiles0),
        len(tiles1))
    log.debug("tile_sets: %d memberships -> %d sets", planes.nnz, len(plane))
    return TileSets(plane, tile0, tile1, indptr, indices, len(table))


def _greedy_cover(sets: TileSets, group: np.ndarray, weights: np.ndarray | None, q: int) -> np.ndarray:
    """Coverage-greedy ranking within groups: the r-th pick maximises the (weighted) matches not covered by
    the group's previous picks.  Ties go to the lowest set index.

    Args:
        group: (S,) int64 group of each set.

    Returns:
        Indices of the picked sets (at most q per group; a set adding nothing is never picked).
    """
    w = np.ones(sets.n_matches) if weights is None else np.asarray(weights, np.float64)
    order = np.argsort(group, kind="stable")  # each group's sets, ascending
    start = np.r_[0, np.flatnonzero(np.diff(group[order])) + 1, len(order)] if len(order) else np.zeros(1)
    return greedy_cover(sets.indptr, sets.indices, w, start.astype(np.int64), order.astype(np.int64), q)


def best_sets_per_tile_pair(
    sets: TileSets, weights: np.ndarray | None = None, q: int = DEFAULTS.q_pair
) -> np.ndarray:
    """H*: the q coverage-greedy best sets of every tile pair (c, c') (paper Sec. 3.5).

    Args:
        sets: all H^l_v.
        weights: (M,) match weights (duplicates), 1 when None.
        q: sets per tile pair (2 in the paper).

    Returns:
        Sorted indices into ``sets``.
    """
    pair = sets.tile0 * (int(sets.tile1.max(initial=0)) + 1) + sets.tile1
    return _greedy_cover(sets, pair, weights, q)


def best_sets_per_tile(sets: TileSets, weights: np.ndarray | None = None, q: int = DEFAULTS.q_tile) -> np.ndarray:
    """H: the q coverage-greedy best sets of every tile c of image 1 (spanning all c' and planes) and of
    every tile c' of image 2 (spanning all c) (paper Sec. 3.5); apply it to H*.

    Returns:
        Sorted indices into ``sets`` (the union of both selections).
    """
    a = _greedy_cover(sets, sets.tile0, weights, q)
    b = _greedy_cover(sets, sets.tile1, weights, q)
    return np.union1d(a, b)
