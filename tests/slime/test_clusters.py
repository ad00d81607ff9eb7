"""Greedy clusters (the compiled sweep and cover behind near-duplicate matches and merged keypoints) against
their definition."""

import numpy as np
import pytest

from slime_match.slime.clusters import greedy_clusters


def _greedy_clusters_by_definition(points, scores, radius):
    cluster = np.full(len(points), -1)
    rep = []
    for i in np.argsort(scores, kind="stable"):
        if cluster[i] < 0:
            near = (np.abs(points - points[i]).max(axis=1) <= radius) & (cluster < 0)
            cluster[near] = len(rep)
            rep.append(i)
    return np.array(rep, np.int64), cluster


@pytest.mark.parametrize("dims", [1, 3, 4])
def test_greedy_clusters_match_the_definition(dims):
    """Compiled sweep + cover against the definition: ties in score, exact duplicates, points exactly at the
    radius (integer grid), a column of equal first coordinates."""
    rng = np.random.default_rng(dims)
    points = rng.integers(0, 40, (600, dims)).astype(float)
    points[:50, 0] = 7.0
    points = np.vstack([points, points[:30]])
    scores = rng.integers(0, 5, len(points)).astype(float)
    for radius in (0.0, 1.0, 2.5):
        rep, cluster = greedy_clusters(points, scores, radius)
        want_rep, want_cluster = _greedy_clusters_by_definition(points, scores, radius)
        assert np.array_equal(rep, want_rep) and np.array_equal(cluster, want_cluster)
    rep, cluster = greedy_clusters(np.zeros((0, 2)), np.zeros(0), 1.0)
    assert rep.shape == (0,) and cluster.shape == (0,)
