"""Greedy clustering of near-identical points (duplicate keypoints of overlapping blocks, near-duplicate
matches of overlapping block and tile pairs), compiled (numba): a Slime call clusters ~10^4 points in each
of its seven calls."""

from __future__ import annotations

import numpy as np

from .._runtime.compiled import kernel


def greedy_clusters(points: np.ndarray, scores: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Points grouped greedily around the best-scored ones.

    In score order, each point not yet clustered becomes a representative and takes every unclustered point
    within ``radius`` of it in every coordinate (Chebyshev distance), so representatives are never that close
    to each other.

    Args:
        points: (K, D) coordinates (px); scores: (K,) lower is better (ties: input order).

    Returns:
        (C,) index of each cluster's representative, in score order; (K,) cluster of each point.
    """
    points = np.ascontiguousarray(points, np.float64)
    first, neighbours = _neighbour_lists(points, float(radius))
    return _greedy_cover(np.argsort(scores, kind="stable"), first, neighbours)


@kernel
def _neighbour_lists(points, radius):
    """The other points within ``radius`` of each point (Chebyshev distance), found by a sweep along the first
    coordinate: point i's are ``neighbours[first[i]:first[i + 1]]`` ((K + 1,) and (2 * pairs,) int64)."""
    n, d = points.shape
    order = np.argsort(points[:, 0], kind="mergesort")
    first = np.zeros(n + 1, np.int64)
    neighbours = np.empty(0, np.int64)
    fill = np.zeros(n, np.int64)
    for sweep in range(2):  # count, then fill
        for a in range(n):
            i = order[a]
            for b in range(a + 1, n):
                j = order[b]
                if points[j, 0] - points[i, 0] > radius:
                    break
                near = True
                for k in range(1, d):
                    if abs(points[j, k] - points[i, k]) > radius:
                        near = False
                        break
                if near and sweep == 0:
                    first[i + 1] += 1
                    first[j + 1] += 1
                elif near:
                    neighbours[fill[i]] = j
                    neighbours[fill[j]] = i
                    fill[i] += 1
                    fill[j] += 1
        if sweep == 0:
            first = np.cumsum(first)
            neighbours = np.empty(first[n], np.int64)
            fill = first[:n].copy()
    return first, neighbours


@kernel
def _greedy_cover(order, first, neighbours):
    """``greedy_clusters`` on the neighbour lists of ``_neighbour_lists``, visiting the points in ``order``."""
    cluster = np.full(len(order), -1, np.int64)
    rep = np.empty(len(order), np.int64)
    count = 0
    for i in order:
        if cluster[i] < 0:
            cluster[i] = count
            for e in range(first[i], first[i + 1]):
                if cluster[neighbours[e]] < 0:
                    cluster[neighbours[e]] = count
            rep[count] = i
            count += 1
    return rep[:count], cluster
