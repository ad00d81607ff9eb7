"""F-bar, plane fusion and the global orientation filter (Secs. 3.6-3.7).

F-bar takes at most two homographies per tile from the sets that passed the epipolar vote
(:func:`greedy_two_per_tile`, with :func:`plane_groups` telling which planes are one homography); each of its
sets is fused with the sets of the same tile pair that overlap it (:func:`fuse_planes`, F^{l*}); the sets whose
dominant orientation is off the global one are dropped (:func:`global_orientation_filter`, F^theta).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from slime_match.slime.tile_kernels import fused_sets

from .match_table import MatchTable
from .orientations import group_relative_orientation, wrap_angle
from .tile_sets import DEFAULTS, TileSets

__all__ = ["fuse_planes", "global_orientation_filter", "greedy_two_per_tile", "plane_groups"]

_BIN_ROUNDING = 1e-9  # radians: bin centres k 2 pi / bins differ from whole multiples of a bin by rounding only


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
    pool: TileSets, selected: TileSets, weights: np.ndarray | None = None, t_ov: float = DEFAULTS.t_ov
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
    bins: int = DEFAULTS.bins,
    t_theta_plus: float = DEFAULTS.t_theta_plus,
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
