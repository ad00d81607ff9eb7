"""Compiled loops of the tile sets (paper Secs. 3.5 and 3.7, numba): building them, the coverage-greedy
selection and the fusion of overlapping sets.

A plane's matches fall into thousands of tile-pair sets, each match into up to four tiles of each image.
In numpy, building the sets took (membership, tile pair) temporaries of millions of entries and a sparse
matrix conversion, each selection round tested every entry against the covered (group, match) keys with
``np.isin``, and the fusion multiplied the selected sets by all sets (sparse, 0.1-0.25 s a call). Here each
plane, group of sets or selected set is handled on its own in one pass.
"""

from __future__ import annotations

import numpy as np

from .._runtime.compiled import kernel


@kernel
def greedy_cover(indptr, indices, weights, group_start, group_sets, q):
    """The coverage-greedy picks of every group of sets.

    Args:
        indptr, indices: the sets in CSR layout, set s = ``indices[indptr[s]:indptr[s + 1]]`` (match
            indices, distinct within a set).
        weights: (M,) float64 weight of each match.
        group_start, group_sets: the sets of group g are ``group_sets[group_start[g]:group_start[g + 1]]``,
            ascending.
        q: picks per group.

    Returns:
        (P,) int64 the picked sets, ascending. Round r of a group picks the set with the largest weight of
        matches not covered by the group's earlier picks, the lowest index on ties, and none when that
        weight is 0.
    """
    covered = np.zeros(len(weights), np.bool_)
    picked = np.empty(len(group_sets), np.int64)
    n_picked = 0
    for g in range(len(group_start) - 1):
        first, last = group_start[g], group_start[g + 1]
        for _ in range(q):
            best, best_gain = -1, 0.0
            for k in range(first, last):
                s = group_sets[k]
                gain = 0.0
                for e in range(indptr[s], indptr[s + 1]):
                    if not covered[indices[e]]:
                        gain += weights[indices[e]]
                if gain > best_gain:
                    best, best_gain = s, gain
            if best < 0:
                break
            picked[n_picked] = best
            n_picked += 1
            for e in range(indptr[best], indptr[best + 1]):
                covered[indices[e]] = True
        for k in range(first, last):
            s = group_sets[k]
            for e in range(indptr[s], indptr[s + 1]):
                covered[indices[e]] = False
    return np.sort(picked[:n_picked])


@kernel
def tile_pair_sets(plane_indptr, plane_indices, tiles0_indptr, tiles0_indices, tiles1_indptr, tiles1_indices,
                   n_tiles0, n_tiles1):
    """Every non-empty set {m in P_l : x_m in tile c, x'_m in tile c'}, sorted by (l, c, c').

    Args:
        plane_indptr, plane_indices: P_l in CSR layout (L planes, match indices ascending within a plane).
        tiles0_indptr, tiles0_indices: the tiles of image 1 holding each match, CSR layout (M rows).
        tiles1_indptr, tiles1_indices: the same in image 2.
        n_tiles0, n_tiles1: numbers C and C' of tiles of the two images.

    Returns:
        plane, tile0, tile1: (S,) int64 each set's l, c and c'.
        indptr (S + 1,), indices (nnz,): the sets' matches in CSR layout, ascending within each set.
    """
    total = 0
    for e in range(len(plane_indices)):
        m = plane_indices[e]
        total += (tiles0_indptr[m + 1] - tiles0_indptr[m]) * (tiles1_indptr[m + 1] - tiles1_indptr[m])
    indices = np.empty(total, np.int64)
    most = min(total, (len(plane_indptr) - 1) * n_tiles0 * n_tiles1)  # sets at most
    plane = np.empty(most, np.int64)
    tile_pair = np.empty(most, np.int64)
    indptr = np.zeros(most + 1, np.int64)
    slot = np.zeros(n_tiles0 * n_tiles1, np.int64)  # per tile pair c C' + c': count, then next free entry
    n_sets = 0
    filled = 0
    for l in range(len(plane_indptr) - 1):  # a counting sort of the plane's entries by tile pair
        first_set = n_sets
        for e in range(plane_indptr[l], plane_indptr[l + 1]):
            m = plane_indices[e]
            for a in range(tiles0_indptr[m], tiles0_indptr[m + 1]):
                for b in range(tiles1_indptr[m], tiles1_indptr[m + 1]):
                    slot[tiles0_indices[a] * n_tiles1 + tiles1_indices[b]] += 1
        for key in range(len(slot)):
            if slot[key]:
                plane[n_sets], tile_pair[n_sets], indptr[n_sets] = l, key, filled
                n_sets += 1
                filled, slot[key] = filled + slot[key], filled
        for e in range(plane_indptr[l], plane_indptr[l + 1]):  # matches ascending: so within each set
            m = plane_indices[e]
            for a in range(tiles0_indptr[m], tiles0_indptr[m + 1]):
                for b in range(tiles1_indptr[m], tiles1_indptr[m + 1]):
                    key = tiles0_indices[a] * n_tiles1 + tiles1_indices[b]
                    indices[slot[key]] = m
                    slot[key] += 1
        for k in range(first_set, n_sets):
            slot[tile_pair[k]] = 0
    indptr[n_sets] = filled
    return (plane[:n_sets].copy(), tile_pair[:n_sets] // n_tiles1, tile_pair[:n_sets] % n_tiles1,
            indptr[:n_sets + 1].copy(), indices)


@kernel
def fused_sets(sel_indptr, sel_indices, sel_key, pool_indptr, pool_indices, pool_key, weights, t_ov):
    """Sec. 3.7's fusion: each selected set united with the pool sets of its tile pair that overlap it.

    Args:
        sel_indptr, sel_indices: the selected sets in CSR layout (match indices, sorted within a set).
        sel_key, pool_key: (S,), (P,) int64 tile-pair key of each selected and pool set.
        pool_indptr, pool_indices: the pool sets in CSR layout (sorted within a set).
        weights: (M,) float64 weight of each match; t_ov: the IoU a pool set must exceed.

    Returns:
        indptr (S + 1,), indices: per selected set, its matches and those of every pool set t of the same
        key whose weighted intersection v with it is positive and v / (|s| + |t| - v) > t_ov, sorted. Sums
        run over matches in ascending order.
    """
    order = np.argsort(pool_key, kind="mergesort")
    sorted_key = pool_key[order]
    inside = np.zeros(len(weights), np.bool_)
    taken = np.zeros(len(weights), np.bool_)
    indptr = np.zeros(len(sel_key) + 1, np.int64)
    chunks = []
    for s in range(len(sel_key)):
        size_s = 0.0
        for e in range(sel_indptr[s], sel_indptr[s + 1]):
            inside[sel_indices[e]] = True
            taken[sel_indices[e]] = True
            size_s += weights[sel_indices[e]]
        members = list(sel_indices[sel_indptr[s]:sel_indptr[s + 1]])
        first = np.searchsorted(sorted_key, sel_key[s], side="left")
        last = np.searchsorted(sorted_key, sel_key[s], side="right")
        for k in range(first, last):
            t = order[k]
            v, size_t = 0.0, 0.0
            for e in range(pool_indptr[t], pool_indptr[t + 1]):
                size_t += weights[pool_indices[e]]
                if inside[pool_indices[e]]:
                    v += weights[pool_indices[e]]
            if v > 0 and v / (size_s + size_t - v) > t_ov:
                for e in range(pool_indptr[t], pool_indptr[t + 1]):
                    if not taken[pool_indices[e]]:
                        taken[pool_indices[e]] = True
                        members.append(pool_indices[e])
        out = np.sort(np.array(members, np.int64))
        for m in out:
            inside[m] = False
            taken[m] = False
        chunks.append(out)
        indptr[s + 1] = indptr[s] + len(out)
    indices = np.empty(indptr[-1], np.int64)
    for s in range(len(chunks)):
        indices[indptr[s]:indptr[s + 1]] = chunks[s]
    return indptr, indices
