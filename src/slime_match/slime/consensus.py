"""The largest consistent epipolar geometry of the tile sets: the fallback of the Sec. 3.6 vote.

The paper's vote keeps a match when more than ``t_xi |H|`` of the F_dd' agree with it. Its threshold grows
with the number of sets while the support of a correct match grows with the square of the number of
correct sets, so when most block planes are wrong (wide baselines, appearance change) the correct ones
cannot pass and the vote keeps nothing. The consensus asks another question: which F_dd' is shared by the
most planes? Each F_dd' of two sets of different homographies is scored by the distinct homographies having a
set that agrees with it (most of the set's matches within ``t_perp``), then refitted on its supporting matches
(local optimisation); it is accepted when at least ``min_planes`` homographies support it, and M+ is then its
inliers among the supporting sets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .epipolar_vote import PairFundamentals, fundamental_from_moments
from .fusion import plane_groups
from .match_table import MatchTable
from .tile_sets import DEFAULTS, TileSets

__all__ = ["Consensus", "epipolar_consensus"]

_F_CHUNK = 64  # fundamental matrices scored at once
_REFITS = 3  # local optimisation rounds


@dataclass
class Consensus:
    """The best-supported epipolar geometry of a superset of tile sets.

    Attributes:
        keep: (M,) bool, its inliers among the matches of its supporting sets (all False when fewer than
            ``min_planes`` homographies support it).
        planes: distinct homographies (plane groups) supporting it.
        sets: (D,) bool, the supporting sets (most of their matches within ``t_perp`` of F).
        F: (3, 3) fundamental matrix in table px (``x1^T F x0 = 0``), or None when no pair could be scored.
    """

    keep: np.ndarray
    planes: int
    sets: np.ndarray
    F: np.ndarray | None


def _distances2(f: np.ndarray, x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """(B, N) squared larger point-to-epipolar-line distance of the N matches x0, x1 (2, N) for B F (B, 3, 3)."""
    a = f[:, :, 0:1] * x0[0] + f[:, :, 1:2] * x0[1] + f[:, :, 2:3]  # F x, (B, 3, N)
    b = f[:, 0:1, :].transpose(0, 2, 1) * x1[0] + f[:, 1:2, :].transpose(0, 2, 1) * x1[1] \
        + f[:, 2:3, :].transpose(0, 2, 1)  # F^T x', (B, 3, N)
    r2 = (x1[0] * a[:, 0] + x1[1] * a[:, 1] + a[:, 2]) ** 2
    return r2 / np.minimum(a[:, 0] ** 2 + a[:, 1] ** 2, b[:, 0] ** 2 + b[:, 1] ** 2).clip(1e-300)


def _score(inliers: np.ndarray, pairs: PairFundamentals, group: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Support of B geometries from their (B, N) member inlier masks: (B,) supporting homographies (those
    with a set whose matches are mostly inliers), (B, D) the supporting sets, and (B, N) their inliers."""
    counts = np.asarray(pairs.sets_by_member @ inliers.T.astype(np.float64)).T  # (B, D)
    support = 2 * counts > pairs.count_set
    n_groups = int(group.max(initial=-1)) + 1
    hits = np.zeros((len(inliers), n_groups), bool)
    rows, cols = np.nonzero(support)
    hits[rows, group[cols]] = True
    held = np.asarray(support.astype(np.float64) @ pairs.sets_by_member) > 0  # (B, N)
    return hits.sum(1), support, inliers & held


def epipolar_consensus(
    table: MatchTable,
    sets: TileSets,
    t_perp: float = DEFAULTS.t_perp,
    min_union: int = DEFAULTS.min_union,
    t_ov: float = DEFAULTS.t_ov,
    min_planes: int = DEFAULTS.min_planes,
    pairs: PairFundamentals | None = None,
) -> Consensus:
    """The F_dd' supported by the most distinct homographies among the superset ``sets``, refitted.

    Args:
        table: (M rows) match table; sets: the superset H of tile sets.
        t_perp: epipolar distance threshold in px.
        min_union: pairs whose union has fewer distinct matches are not scored.
        t_ov: overlap above which planes count as one homography (``fusion.plane_groups``).
        min_planes: distinct supporting homographies needed to accept the geometry.
        pairs: the sets' :class:`PairFundamentals` when already built.

    Returns:
        The :class:`Consensus`; ``keep`` is all False when fewer than ``min_planes`` homographies agree.
    """
    keep = np.zeros(len(table), bool)
    none = Consensus(keep, 0, np.zeros(len(sets), bool), None)
    if len(sets) < 2:
        return none
    pairs = pairs or PairFundamentals(table, sets)
    group = plane_groups(sets, t_ov)[sets.plane]  # (D,) homography of each set
    candidates = np.flatnonzero(group[pairs.ia] != group[pairs.ib])
    tol2 = (t_perp / pairs.scale) ** 2

    def support(f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return _score(_distances2(f, pairs.x0, pairs.x1) < tol2, pairs, group)

    best = (-1, -1, None)  # (homographies, inliers, F)
    for start in range(0, len(candidates), _F_CHUNK):
        mom, cnt = pairs.union_moments(candidates[start:start + _F_CHUNK])
        if not (cnt >= min_union).any():
            continue
        f = fundamental_from_moments(mom[cnt >= min_union].reshape(-1, 9, 9))
        n_groups, _, chosen = support(f)
        n_in = chosen.sum(1)
        i = int(np.lexsort((-n_in, -n_groups))[0])
        if (n_groups[i], n_in[i]) > best[:2]:
            best = (int(n_groups[i]), int(n_in[i]), f[i])
    if best[2] is None:
        return none
    f = best[2]
    for _ in range(_REFITS):  # local optimisation: refit on the supporting homographies' inliers
        n_groups, _, chosen = support(f[None])
        if chosen.sum() < min_union:
            break
        refit = fundamental_from_moments(pairs.outer[chosen[0]].sum(0).reshape(1, 9, 9))[0]
        refit_groups, _, refit_chosen = support(refit[None])
        if (refit_groups[0], refit_chosen.sum()) < (n_groups[0], chosen.sum()):
            break
        f = refit
    n_groups, sets_support, chosen = support(f[None])
    if n_groups[0] >= min_planes:
        keep[pairs.members[chosen[0]]] = True
    return Consensus(keep, int(n_groups[0]), sets_support[0], _to_table_frame(f, pairs))


def _to_table_frame(f: np.ndarray, pairs: PairFundamentals) -> np.ndarray:
    """F of the similarity frame as F of table px (the frames differ by a shift and one scale per image)."""
    t0, t1 = np.eye(3), np.eye(3)
    for t, c in ((t0, pairs.centre0), (t1, pairs.centre1)):
        t[:2, :2] /= pairs.scale
        t[:2, 2] = -c / pairs.scale
    out = t1.T @ f @ t0
    return out / np.linalg.norm(out)
