"""Greedy clustering of near-identical points (duplicate keypoints of overlapping blocks, near-duplicate
matches of overlapping block and tile pairs)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


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
    points = np.asarray(points, np.float64)
    cluster = np.full(len(points), -1, np.int64)
    if not len(points):
        return np.zeros(0, np.int64), cluster
    tree = cKDTree(points)
    rep = []
    for i in np.argsort(scores, kind="stable"):
        if cluster[i] < 0:  # only representatives query their neighbours
            members = np.asarray(tree.query_ball_point(points[i], radius, p=np.inf), np.int64)
            cluster[members[cluster[members] < 0]] = len(rep)
            rep.append(i)
    return np.asarray(rep, np.int64), cluster
