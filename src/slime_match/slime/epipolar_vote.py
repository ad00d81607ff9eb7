"""The epipolar vote: the matches consistent with many fundamental matrices of pairs of tile sets (Sec. 3.6)."""

from __future__ import annotations

import functools
import logging
import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp

from slime_match.slime.epipolar_kernels import epipolar_votes

from .match_table import MatchTable
from .tile_sets import DEFAULTS, TileSets

__all__ = ["PairFundamentals", "epipolar_consistency", "fundamental_from_moments"]

log = logging.getLogger("slime_match")


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


class PairFundamentals:
    """The fundamental matrices F_dd' of pairs of sets, each the normalised 8-point solution on the union
    H_d U H_d' (each match once, duplicate weights as multiplicity).

    The 9x9 normal matrices are not rebuilt per pair: with ``k = kron(x', x)`` the union's moment
    ``sum w k k^T`` is ``Mom_d + Mom_d' - Mom_(d & d')``, where the intersection moments are accumulated only
    for the set pairs that share matches; the Hartley normalisation of the union comes from the same moments
    (centroid and RMS distance), so ``A^T A`` in normalised coordinates is ``K Mom K^T`` with ``K = T' (x) T``.
    Points are first moved to a global similarity frame (one scale for both images, so that a distance
    threshold is one number) to keep the moments well conditioned.

    Attributes:
        members: (N,) rows of the table in some set; x0, x1: (2, N) their points in the similarity frame,
            ``(xy - centre) / scale`` with (2,) ``centre0``, ``centre1`` in px and one ``scale`` (px per unit).
        sets_by_member: (D, N) CSR 0/1 matrix, set d holds member n.
        ia, ib: (P,) the unordered pairs d < d' in ``np.triu_indices`` order.
    """

    def __init__(self, table: MatchTable, sets: TileSets) -> None:
        n_sets = len(sets)
        self.members = members = np.flatnonzero(sets.union())
        local = np.full(len(table), -1, np.int64)
        local[members] = np.arange(len(members))
        w = table.weight[members]
        c0, s0 = _similarity(table.xy0[members], w)
        c1, s1 = _similarity(table.xy1[members], w)
        self.centre0, self.centre1 = c0, c1
        self.scale = scale = max(s0, s1)
        x0 = np.hstack([(table.xy0[members] - c0) / scale, np.ones((len(members), 1))])
        x1 = np.hstack([(table.xy1[members] - c1) / scale, np.ones((len(members), 1))])
        self.x0, self.x1 = np.ascontiguousarray(x0[:, :2].T), np.ascontiguousarray(x1[:, :2].T)
        kk = (x1[:, :, None] * x0[:, None, :]).reshape(-1, 9)
        self.outer = outer = (kk[:, :, None] * kk[:, None, :]).reshape(-1, 81) * w[:, None]
        self.sets_by_member = s_mat = sp.csr_matrix(
            (np.ones(len(sets.indices)), local[sets.indices], sets.indptr), shape=(n_sets, len(members))
        )
        self.mom_set = np.asarray(s_mat @ outer)  # (D, 81)
        self.count_set = np.diff(sets.indptr)
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
        self.shared, inv = np.unique(triu, return_inverse=True)
        r = sp.csr_matrix((np.ones(inv.size), (inv.reshape(-1), e[sel])), shape=(len(self.shared), len(members)))
        self.mom_shared = np.asarray(r @ outer)
        self.count_shared = np.asarray(r.sum(axis=1)).ravel()
        self.ia, self.ib = np.triu_indices(n_sets, 1)

    def union_moments(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(K, 81) moments and (K,) distinct-match counts of the unions of the pairs ``idx`` (K,)."""
        pa, pb = self.ia[idx], self.ib[idx]
        mom = self.mom_set[pa] + self.mom_set[pb]
        cnt = self.count_set[pa] + self.count_set[pb]
        shared = self.shared
        pos = np.minimum(np.searchsorted(shared, idx), max(len(shared) - 1, 0))
        hit = shared[pos] == idx if len(shared) else np.zeros(len(idx), bool)
        mom[hit] -= self.mom_shared[pos[hit]]
        cnt[hit] -= self.count_shared[pos[hit]].astype(cnt.dtype)
        return mom, cnt


def fundamental_from_moments(mom: np.ndarray) -> np.ndarray:
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
    t_perp: float = DEFAULTS.t_perp,
    t_xi: float = DEFAULTS.t_xi,
    min_union: int = DEFAULTS.min_union,
    chunk: int = DEFAULTS.chunk,
    threads: int = 1,
    pairs: PairFundamentals | None = None,
) -> np.ndarray:
    """M+: matches consistent with many of the fundamental matrices of pairs of sets (paper Sec. 3.6).

    For every unordered pair d < d' of sets, F_dd' is estimated on the union (:class:`PairFundamentals`).
    A match is kept when ``sum_{d != d'} [xi^F_dd' < t_perp] > t_xi |H|`` over ordered pairs, as the paper
    writes it (F_dd' = F_d'd, so each unordered pair counts twice); xi is the larger point-to-epipolar-line
    distance. The vote stops early for the matches already decided (exact: same result as the full count).

    Args:
        table: (M rows) match table (``weight`` is the duplicate multiplicity).
        sets: the superset H of tile sets.
        t_perp: epipolar distance threshold in px.
        t_xi: vote threshold factor.
        min_union: pairs whose union has fewer distinct matches are skipped (no vote).
        chunk: (F, match) pairs evaluated at once (``epipolar_kernels.epipolar_votes``).
        threads: threads sharing each chunk's F estimation and vote (numpy's eigh and the vote release the
            GIL; the same result for any number).
        pairs: the sets' :class:`PairFundamentals` when already built.

    Returns:
        (M,) bool, True for the matches of M+ (only matches of some set can be True).
    """
    keep = np.zeros(len(table), bool)
    n_sets = len(sets)
    if n_sets < 2:
        return keep
    pairs = pairs or PairFundamentals(table, sets)
    members = pairs.members
    n_pairs = len(pairs.ia)
    # pairs in a fixed shuffled order, so that every match is decided as early as possible: it passes once
    # it has more than t_xi |H| / 2 unordered votes and fails once the remaining pairs cannot get it there
    order = np.random.default_rng(0).permutation(n_pairs)
    need = t_xi * n_sets / 2.0
    votes = np.zeros(len(members))
    active = np.arange(len(members))
    tol2 = (t_perp / pairs.scale) ** 2
    with ThreadPoolExecutor(max(1, threads)) as pool:
        done = 0
        while done < n_pairs and len(active):
            idx = order[done : done + max(1, chunk // len(active))]
            done += len(idx)
            mom, cnt = pairs.union_moments(idx)
            ok = cnt >= min_union
            if ok.any():
                f_parts = np.array_split(mom[ok].reshape(-1, 9, 9), threads if ok.sum() >= _THREADS_MIN_F else 1)
                f = np.concatenate(_map(pool, fundamental_from_moments, f_parts))
                slices = np.array_split(active, threads if len(f) * len(active) >= _THREADS_MIN_TESTS else 1)
                votes[active] += np.concatenate(
                    _map(pool, functools.partial(_votes, f, pairs.x0, pairs.x1, tol2), slices))
            passed = votes[active] > need
            keep[members[active[passed]]] = True
            active = active[~passed & (votes[active] + (n_pairs - done) > need)]
    log.debug(
        "epipolar_consistency: %d sets, %d F, %d/%d kept", n_sets, n_pairs, int(keep.sum()), len(members)
    )
    return keep
