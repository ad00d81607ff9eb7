"""Plane selection on image tiles, epipolar consistency, plane fusion, global orientation (Secs. 3.5-3.7).

All match sets are sets of rows of one :class:`~slime_match.slime.planes.MatchTable`, stored together in
a :class:`TileSets` (CSR layout: set -> sorted match indices, with its plane l and tile pair (c, c')).
The Slime flow is::

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

import functools
import logging
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from slime_match.errors import ConfigError
from slime_match.slime.blocks import Block, points_in_blocks
from slime_match.slime.epipolar_kernels import epipolar_votes
from slime_match.slime.planes import MatchTable, group_relative_orientation, wrap_angle
from slime_match.slime.tile_kernels import fused_sets, greedy_cover, tile_pair_sets

__all__ = [
    "TileConfig",
    "TileSets",
    "best_sets_per_tile",
    "best_sets_per_tile_pair",
    "epipolar_consistency",
    "fuse_planes",
    "global_orientation_filter",
    "greedy_two_per_tile",
    "plane_groups",
    "tile_sets",
]

log = logging.getLogger("slime_match")


_SAME_HOMOGRAPHY = ("shared", "iou", "set")


@dataclass
class TileConfig:
    """Parameters of the tile-level set logic (paper Secs. 3.5-3.7).

    Attributes:
        q_pair: best sets kept per tile pair (H*).
        q_tile: best sets kept per tile of each image (H).
        t_perp: epipolar distance threshold in px.
        t_xi: a match is kept when it is an inlier of more than ``t_xi |H|`` of the F_dd'.
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
        if self.same_homography not in _SAME_HOMOGRAPHY:
            raise ConfigError(f"TileConfig: same_homography {self.same_homography!r} is not one of "
                              f"{', '.join(_SAME_HOMOGRAPHY)}")


_D = TileConfig()  # defaults for the function signatures
_BIN_ROUNDING = 1e-9  # radians: bin centres k 2 pi / bins differ from whole multiples of a bin by rounding only


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
    sets: TileSets, weights: np.ndarray | None = None, q: int = _D.q_pair
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


def best_sets_per_tile(sets: TileSets, weights: np.ndarray | None = None, q: int = _D.q_tile) -> np.ndarray:
    """H: the q coverage-greedy best sets of every tile c of image 1 (spanning all c' and planes) and of
    every tile c' of image 2 (spanning all c) (paper Sec. 3.5); apply it to H*.

    Returns:
        Sorted indices into ``sets`` (the union of both selections).
    """
    a = _greedy_cover(sets, sets.tile0, weights, q)
    b = _greedy_cover(sets, sets.tile1, weights, q)
    return np.union1d(a, b)


def _similarity(xy: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, float]:
    """Centroid and scale s with ``(x - c) / s`` at RMS distance sqrt(2) from the origin."""
    c = np.average(xy, axis=0, weights=w)
    rms = math.sqrt(np.average(((xy - c) ** 2).sum(1), weights=w))
    return c, max(rms, 1e-9) / math.sqrt(2.0)


def _union_normalisers(mom: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hartley (RMS) normalisations of both images from (P, 9, 9) moment matrices of kron(x', x).

    Returns:
        (P, 3, 3) T for image 1 and (P, 3, 3) T' for image 2.
    """
    n = np.maximum(mom[:, 8, 8], 1e-12)

    def one(ix: int, iy: int) -> np.ndarray:
        cx, cy = mom[:, 8, ix] / n, mom[:, 8, iy] / n
        var = (mom[:, ix, ix] + mom[:, iy, iy]) / n - cx**2 - cy**2
        s = np.sqrt(2.0 / np.maximum(var, 1e-24))
        t = np.zeros((len(n), 3, 3))
        t[:, 0, 0] = t[:, 1, 1] = s
        t[:, 0, 2], t[:, 1, 2], t[:, 2, 2] = -s * cx, -s * cy, 1.0
        return t

    # kron(x', x) index i * 3 + j = x'_i x_j: x = (6, 7), x' = (2, 5), 1 = 8
    return one(6, 7), one(2, 5)


def _fundamental_from_moments(mom: np.ndarray) -> np.ndarray:
    """Normalised 8-point fundamental matrices from (P, 9, 9) moments ``sum w kron(x', x) kron(x', x)^T``.

    Returns:
        (P, 3, 3) rank-2 F (in the coordinates of the moments) with ``x'^T F x = 0``, unit Frobenius norm.
    """
    t0, t1 = _union_normalisers(mom)
    k = np.einsum("pij,pkl->pikjl", t1, t0).reshape(-1, 9, 9)  # T' (x) T
    mn = k @ mom @ k.transpose(0, 2, 1)
    mn /= np.maximum(np.abs(mn).max(axis=(1, 2), keepdims=True), 1e-300)
    _, vec = np.linalg.eigh(mn)
    fn = vec[:, :, 0].reshape(-1, 3, 3)
    u, s, vt = np.linalg.svd(fn)
    s[:, 2] = 0.0
    f = t1.transpose(0, 2, 1) @ (u * s[:, None]) @ vt @ t0
    return f / np.linalg.norm(f, axis=(1, 2), keepdims=True)


_THREADS_MIN_F = 256  # fundamental matrices to estimate, and (F, match) tests, from which threads share a chunk
_THREADS_MIN_TESTS = 100_000


def _map(pool: ThreadPoolExecutor, fn, parts: list) -> list:
    return list(pool.map(fn, parts)) if len(parts) > 1 else [fn(p) for p in parts]


def _votes(f: np.ndarray, x0: np.ndarray, x1: np.ndarray, tol2: float, part: np.ndarray) -> np.ndarray:
    """(P,) votes of the matches ``part`` (P,) of x0, x1 (2, N) among the fundamental matrices f (B, 3, 3)."""
    out = np.zeros(len(part))
    epipolar_votes(f, x0.take(part, 1), x1.take(part, 1), tol2, out)  # take: C-contiguous rows, which the
    return out  # compiled loop needs to vectorise


def epipolar_consistency(
    table: MatchTable,
    sets: TileSets,
    t_perp: float = _D.t_perp,
    t_xi: float = _D.t_xi,
    min_union: int = _D.min_union,
    chunk: int = _D.chunk,
    threads: int = 1,
) -> np.ndarray:
    """M+: matches consistent with many of the fundamental matrices of pairs of sets (paper Sec. 3.6).

    For every unordered pair d < d' of sets, F_dd' is the normalised 8-point solution on the union
    H_d U H_d' (each match once, duplicate weights as multiplicity).  The 9x9 normal matrices are not
    rebuilt per pair: with ``k = kron(x', x)`` the union's moment ``sum w k k^T`` is
    ``Mom_d + Mom_d' - Mom_(d & d')``, where the intersection moments are accumulated only for the set pairs
    that share matches; the Hartley normalisation of the union comes from the same moments (centroid and RMS
    distance), so ``A^T A`` in normalised coordinates is ``K Mom K^T`` with ``K = T' (x) T``.  Points are first
    moved to a global similarity frame to keep the moments well conditioned.  A match is kept when
    ``sum_{d != d'} [xi^F_dd' < t_perp] > t_xi |H|`` over ordered pairs, as the paper writes it
    (F_dd' = F_d'd, so each unordered pair counts twice); xi is the larger point-to-epipolar-line distance.
    The vote stops early for the matches already decided (exact: same result as the full count).

    Args:
        table: (M rows) match table (``weight`` is the duplicate multiplicity).
        sets: the superset H of tile sets.
        t_perp: epipolar distance threshold in px.
        t_xi: vote threshold factor.
        min_union: pairs whose union has fewer distinct matches are skipped (no vote).
        chunk: (F, match) pairs evaluated at once (``epipolar_kernels.epipolar_votes``).
        threads: threads sharing each chunk's F estimation and vote (numpy's eigh and the vote release the
            GIL; the same result for any number).

    Returns:
        (M,) bool, True for the matches of M+ (only matches of some set can be True).
    """
    keep = np.zeros(len(table), bool)
    n_sets = len(sets)
    if n_sets < 2:
        return keep
    members = np.flatnonzero(sets.union())
    local = np.full(len(table), -1, np.int64)
    local[members] = np.arange(len(members))
    w = table.weight[members]
    # global similarity frames: a common scale for both images so the threshold is one number
    c0, s0 = _similarity(table.xy0[members], w)
    c1, s1 = _similarity(table.xy1[members], w)
    scale = max(s0, s1)
    x0 = np.hstack([(table.xy0[members] - c0) / scale, np.ones((len(members), 1))])
    x1 = np.hstack([(table.xy1[members] - c1) / scale, np.ones((len(members), 1))])
    kk = (x1[:, :, None] * x0[:, None, :]).reshape(-1, 9)
    outer = (kk[:, :, None] * kk[:, None, :]).reshape(-1, 81) * w[:, None]
    s_mat = sp.csr_matrix(
        (np.ones(len(sets.indices)), local[sets.indices], sets.indptr), shape=(n_sets, len(members))
    )
    mom_set = np.asarray(s_mat @ outer)  # (D, 81)
    count_set = np.diff(sets.indptr)
    # intersections of the pairs of sets sharing matches: (d, d', m) triples via the columns of s_mat
    by_match = s_mat.T.tocsr()
    cm = np.diff(by_match.indptr)
    reps = cm * cm
    e = np.repeat(np.arange(len(members)), reps)
    k = np.arange(int(reps.sum())) - np.repeat(np.cumsum(reps) - reps, reps)
    da = by_match.indices[by_match.indptr[e] + k // cm[e]].astype(np.int64)
    db = by_match.indices[by_match.indptr[e] + k % cm[e]].astype(np.int64)
    sel = da < db
    da, db = da[sel], db[sel]
    triu = da * n_sets - da * (da + 1) // 2 + (db - da - 1)  # linear index in np.triu_indices order
    shared, inv = np.unique(triu, return_inverse=True)
    r = sp.csr_matrix((np.ones(inv.size), (inv.reshape(-1), e[sel])), shape=(len(shared), len(members)))
    mom_shared = np.asarray(r @ outer)
    count_shared = np.asarray(r.sum(axis=1)).ravel()

    ia, ib = np.triu_indices(n_sets, 1)
    n_pairs = len(ia)
    # pairs in a fixed shuffled order, so that every match is decided as early as possible: it passes once
    # it has more than t_xi |H| / 2 unordered votes and fails once the remaining pairs cannot get it there
    order = np.random.default_rng(0).permutation(n_pairs)
    need = t_xi * n_sets / 2.0
    votes = np.zeros(len(members))
    active = np.arange(len(members))
    px0, px1 = np.ascontiguousarray(x0[:, :2].T), np.ascontiguousarray(x1[:, :2].T)  # (2, N)
    tol2 = (t_perp / scale) ** 2
    with ThreadPoolExecutor(max(1, threads)) as pool:
        done = 0
        while done < n_pairs and len(active):
            idx = order[done : done + max(1, chunk // len(active))]
            done += len(idx)
            pa, pb = ia[idx], ib[idx]
            mom = mom_set[pa] + mom_set[pb]
            cnt = count_set[pa] + count_set[pb]
            pos = np.minimum(np.searchsorted(shared, idx), max(len(shared) - 1, 0))
            hit = shared[pos] == idx if len(shared) else np.zeros(len(idx), bool)
            mom[hit] -= mom_shared[pos[hit]]
            cnt[hit] -= count_shared[pos[hit]].astype(cnt.dtype)
            ok = cnt >= min_union
            if ok.any():
                f_parts = np.array_split(mom[ok].reshape(-1, 9, 9), threads if ok.sum() >= _THREADS_MIN_F else 1)
                f = np.concatenate(_map(pool, _fundamental_from_moments, f_parts))
                slices = np.array_split(active, threads if len(f) * len(active) >= _THREADS_MIN_TESTS else 1)
                votes[active] += np.concatenate(_map(pool, functools.partial(_votes, f, px0, px1, tol2), slices))
            passed = votes[active] > need
            keep[members[active[passed]]] = True
            active = active[~passed & (votes[active] + (n_pairs - done) > need)]
    log.debug(
        "epipolar_consistency: %d sets, %d F, %d/%d kept", n_sets, n_pairs, int(keep.sum()), len(members)
    )
    return keep


def plane_groups(sets: TileSets, overlap: float, measure: str = "shared") -> np.ndarray:
    """Planes that are one homography: each plane's matches are the union of its sets, and from the largest
    plane down, each plane not yet grouped heads a group and takes the ungrouped planes whose matches overlap
    its own by more than ``overlap``.

    Args:
        sets: tile sets with their planes l.
        overlap: threshold on the overlap of two planes' match sets A, B (t_ov = 1/3).
        measure: "shared" (|A & B| / min(|A|, |B|)) or "iou" (|A & B| / |A | B|).

    Returns:
        (L,) int64 group of each plane l (the index of the group's largest plane), L = max plane + 1.
    """
    n_planes = int(sets.plane.max(initial=-1)) + 1
    entries = sp.csr_matrix((np.ones(len(sets.indices)), (sets.plane[sets.set_of_entry], sets.indices)),
                            shape=(n_planes, sets.n_matches))
    entries.data[:] = 1.0  # duplicates were summed on construction: a match in several sets of one plane counts once
    size = np.asarray(entries.sum(axis=1)).ravel()
    inter = (entries @ entries.T).tocoo()
    i, j, v = inter.row, inter.col, inter.data
    scale = np.minimum(size[i], size[j]) if measure == "shared" else size[i] + size[j] - v
    near = (v / np.maximum(scale, 1e-12)) > overlap
    near = sp.csr_matrix((np.ones(int(near.sum()), bool), (i[near], j[near])), shape=(n_planes, n_planes))
    group = np.arange(n_planes)
    grouped = np.zeros(n_planes, bool)
    for head in np.argsort(-size, kind="stable"):  # sequential by definition; one step per plane
        if grouped[head]:
            continue
        members = near.indices[near.indptr[head]:near.indptr[head + 1]]
        members = members[~grouped[members]]
        group[members] = head
        grouped[members] = grouped[head] = True
    return group


def greedy_two_per_tile(
    sets: TileSets, weights: np.ndarray | None = None, max_per_tile: int = 2, t_ov: float | None = None,
    groups: np.ndarray | None = None,
) -> np.ndarray:
    """F-bar: sets by decreasing cardinality, each added unless one of its tiles (c in image 1 or c' in
    image 2) would then hold more than ``max_per_tile`` homographies; empty sets are skipped (paper Sec. 3.6).

    Without ``groups`` each set is a homography of its own (the literal reading: "at maximum only two sets
    in F-bar can share the same tile"). With ``groups`` ((L,) group of each plane, see ``plane_groups``) the
    sets of one group are one homography, so a plane that spans several tile pairs of a tile, or its
    near-copies from overlapping block pairs, take one of the tile's slots and not all of them ("no tile has
    more than two homographies, the background and foreground planes").

    With ``t_ov``, a set overlapping an added set of the same tile pair by IoU > t_ov is the same plane
    (the fusion of Sec. 3.7 merges them anyway): it is skipped without taking a tile's slot.

    Returns:
        Indices of the added sets, in the order they were added.
    """
    size = sets.sizes(weights)
    order = np.argsort(-size, kind="stable")
    order = order[size[order] > 0]
    homography = np.arange(len(sets)) if groups is None else np.asarray(groups)[sets.plane]
    held0: list[set] = [set() for _ in range(int(sets.tile0.max(initial=-1)) + 1)]
    held1: list[set] = [set() for _ in range(int(sets.tile1.max(initial=-1)) + 1)]
    same_plane = _near_copies(sets, weights, t_ov) if t_ov is not None else None
    added = np.zeros(len(sets), bool)
    out = []
    for s in order:  # sequential by definition; one step per set, not per match
        if same_plane is not None and added[same_plane.indices[same_plane.indptr[s]:same_plane.indptr[s + 1]]].any():
            continue
        h, tile0, tile1 = homography[s], held0[sets.tile0[s]], held1[sets.tile1[s]]
        if (h in tile0 or len(tile0) < max_per_tile) and (h in tile1 or len(tile1) < max_per_tile):
            tile0.add(h)
            tile1.add(h)
            added[s] = True
            out.append(s)
    return np.asarray(out, np.int64)


def _near_copies(sets: TileSets, weights: np.ndarray | None, t_ov: float) -> sp.csr_matrix:
    """(S, S) CSR: pairs of distinct sets of the same tile pair with (weighted) IoU > t_ov."""
    w = np.ones(sets.n_matches) if weights is None else np.asarray(weights, np.float64)
    inter = (sets.matrix(w) @ sets.matrix().astype(np.float64).T).tocoo()
    i, j, v = inter.row, inter.col, inter.data
    size = sets.sizes(w)
    same_pair = (sets.tile0[i] == sets.tile0[j]) & (sets.tile1[i] == sets.tile1[j]) & (i != j)
    ok = same_pair & (v / (size[i] + size[j] - v) > t_ov)
    return sp.csr_matrix((np.ones(int(ok.sum()), bool), (i[ok], j[ok])), shape=(len(sets), len(sets)))


def fuse_planes(
    pool: TileSets, selected: TileSets, weights: np.ndarray | None = None, t_ov: float = _D.t_ov
) -> TileSets:
    """F^{l*}_v: each selected set fused with the sets of the same tile pair overlapping it by IoU > t_ov.

    Args:
        pool: all candidate sets F^{l'}_v (typically ``tile_sets(...).restrict(keep)``).
        selected: the sets of F-bar (same table).
        weights: (M,) match weights for the cardinalities, 1 when None.
        t_ov: IoU threshold (1/3).

    Returns:
        One fused set per selected set, with its plane and tile labels.
    """
    w = np.ones(pool.n_matches) if weights is None else np.asarray(weights, np.float64)
    n_tiles1 = int(max(pool.tile1.max(initial=0), selected.tile1.max(initial=0))) + 1
    indptr, indices = fused_sets(selected.indptr, selected.indices, selected.tile0 * n_tiles1 + selected.tile1,
                                 pool.indptr, pool.indices, pool.tile0 * n_tiles1 + pool.tile1, w, float(t_ov))
    return TileSets(selected.plane, selected.tile0, selected.tile1, indptr, indices, selected.n_matches)


def global_orientation_filter(
    table: MatchTable,
    sets: TileSets,
    bins: int = _D.bins,
    t_theta_plus: float = _D.t_theta_plus,
) -> tuple[np.ndarray, np.ndarray, float]:
    """F^theta: drop the sets whose dominant relative orientation is off the global one by more than t_theta_plus.

    Both orientations are histogram bin centres, so they differ by whole bins: at the default pi/4 a set two
    bins (exactly 45 deg) away is kept, three bins away dropped (Sec. 3.7: "cannot differ more than 45 deg").

    Args:
        table: (M rows) match table (weights count in the per-set histograms).
        sets: fused sets F^{l*}_v.
        bins: histogram bins (16).
        t_theta_plus: tolerance in radians (pi/4).

    Returns:
        (S,) bool kept sets; (S,) per-set orientation theta^l_v in radians (NaN for empty sets); the global
        orientation theta+ (histogram mode of the per-set orientations, one vote per set).
    """
    ent = sets.set_of_entry
    theta = group_relative_orientation(
        table.rho[sets.indices], ent, len(sets), bins, table.weight[sets.indices]
    )
    valid = ~np.isnan(theta)
    if not valid.any():
        return np.zeros(len(sets), bool), theta, math.nan
    theta_plus = float(
        group_relative_orientation(theta[valid], np.zeros(int(valid.sum()), np.int64), 1, bins)[0]
    )
    with np.errstate(invalid="ignore"):
        keep = valid & (np.abs(wrap_angle(theta - theta_plus)) <= t_theta_plus + _BIN_ROUNDING)
    return keep, theta, theta_plus
