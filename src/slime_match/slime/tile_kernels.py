"""Compiled loop of the coverage-greedy set selection (paper Sec. 3.5, numba).

Slime ranks thousands of tile sets, q rounds per tile pair and per tile; in numpy each round tested every
entry against the covered (group, match) keys with ``np.isin``. Here each group is ranked on its own,
with one flag per match.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
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
