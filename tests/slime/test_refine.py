"""Sec. 3.8: the tile stage's candidate tests, the tile matches, near-duplicate clusters and the final global
DTM, and Slime's final matches."""

import numpy as np
import pytest

from slime_match.config import make_config
from slime_match.errors import ConfigError
from slime_match.slime.refine import (
    FlowGuide,
    PlaneGuide,
    cluster_representatives,
    global_dtm,
    tile_test,
)


def test_flow_guide_equals_brute_force():
    rng = np.random.default_rng(1)
    g0, g1 = rng.uniform(0, 300, (200, 2)), rng.uniform(0, 300, (200, 2))
    pick = rng.integers(0, 200, 500)
    y0 = g0[pick] + rng.normal(0, 8, (500, 2))
    y1 = g1[pick] + rng.normal(0, 8, (500, 2))
    y1[:250] = rng.uniform(0, 300, (250, 2))
    guide = FlowGuide(g0, g1, 15.0)
    d0 = np.linalg.norm(y0[:, None] - g0[None], axis=2)
    d1 = np.linalg.norm(y1[:, None] - g1[None], axis=2)
    expected = (np.maximum(d0, d1) < 15.0).any(axis=1)
    assert expected.sum() > 50
    assert np.array_equal(guide(y0, y1, neighbours=200), expected)
    assert FlowGuide(np.zeros((0, 2)), np.zeros((0, 2)), 15.0)(y0, y1).sum() == 0


def test_plane_guide_keeps_what_fits_one_of_the_given_planes():
    """Candidates within t of a plane (two-sided), on its side, pass for that plane only; the other plane of the
    pair, or a plane not given, does not let them through."""
    shift = np.array([[1.0, 0.0, 40.0], [0.0, 1.0, -20.0], [0.0, 0.0, 1.0]])
    zoom = np.array([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]])
    flipped = -shift  # the same mapping with w < 0 on every point: the other side of that plane
    guide = PlaneGuide(np.stack([shift, zoom, flipped]), np.array([1.0, 1.0, 1.0]), 15.0)
    y0 = np.array([[100.0, 100.0], [100.0, 100.0], [100.0, 100.0], [50.0, 60.0]])
    y1 = np.array([[150.0, 80.0], [155.0, 80.0], [201.0, 207.0], [90.0, 40.0]])  # errors under shift: 10, 15, .., 0
    assert guide(y0, y1, np.array([0])).tolist() == [True, False, False, True]
    assert guide(y0, y1, np.array([1])).tolist() == [False, False, True, False]  # zoom: (200, 200) vs (201, 207)
    assert guide(y0, y1, np.array([0, 1])).tolist() == [True, False, True, True]
    assert guide(y0, y1, np.array([2])).tolist() == [False] * 4
    assert guide(y0, y1, np.array([], np.int64)).tolist() == [False] * 4
    assert guide(y0[:0], y1[:0], np.array([0])).shape == (0,)


def test_tile_tests_choose_flow_or_plane():
    """"flow" ignores the planes, "plane" ignores the flows."""
    flow = FlowGuide(np.array([[0.0, 0.0]]), np.array([[500.0, 500.0]]), 15.0)
    plane = PlaneGuide(np.eye(3)[None], np.ones(1), 15.0)
    y0 = np.array([[5.0, 0.0], [300.0, 300.0], [700.0, 0.0]])
    y1 = np.array([[505.0, 500.0], [305.0, 300.0], [0.0, 700.0]])
    planes = np.array([0])
    assert tile_test("flow", flow, plane)(y0, y1, planes).tolist() == [True, False, False]
    assert tile_test("plane", flow, plane)(y0, y1, planes).tolist() == [False, True, False]
    with pytest.raises(ValueError, match="tile test 'either'"):
        tile_test("either", flow, plane)
    with pytest.raises(ConfigError, match="invalid tile_test 'nearest'"):
        make_config("slime", tile_test="nearest")
    with pytest.raises(ConfigError, match="Slime option"):
        make_config("hz+", tile_test="plane")


def test_global_dtm_merges_exact_duplicates():
    rng = np.random.default_rng(2)
    x0 = rng.uniform(0, 200, (300, 2))
    x1 = x0 + [10.0, 5.0]
    xy0, xy1 = np.vstack([x0, x0[:100]]), np.vstack([x1, x1[:100]])
    scores = rng.uniform(0, 1, 400)
    k0, k1, s = global_dtm(xy0, xy1, scores, (220, 220), (220, 220))
    rows = np.hstack([k0, k1])
    assert len(np.unique(rows, axis=0)) == len(rows) and len(rows) > 250
    assert np.all(np.diff(s) >= 0)


def test_cluster_representatives_and_shared_verdicts():
    """Matches within 4 px of a better one at both ends join its cluster, represented by its best-scored
    match; in global_dtm the members of a cluster share its verdict (kept or dropped together)."""
    xy0 = np.array([[10.2, 10.1], [11.9, 10.4], [10.5, 11.5], [30.0, 30.0], [10.2, 10.1]])
    xy1 = np.array([[20.0, 20.0], [20.5, 21.0], [25.0, 20.0], [40.0, 40.0], [20.1, 20.2]])
    scores = np.array([0.5, 0.2, 0.1, 0.3, 0.4])
    rep, cluster = cluster_representatives(xy0, xy1, scores)
    assert cluster[0] == cluster[1] == cluster[4] and len({cluster[0], cluster[2], cluster[3]}) == 3
    assert sorted(rep.tolist()) == [1, 2, 3]  # the best-scored member of each cluster
    rng = np.random.default_rng(4)
    x0 = rng.uniform(5, 195, (200, 2))
    x1 = x0 + [10.0, 5.0]
    near0, near1 = x0[:80] + rng.uniform(-0.4, 0.4, (80, 2)), x1[:80] + rng.uniform(-0.4, 0.4, (80, 2))
    k0, k1, _ = global_dtm(np.vstack([x0, near0]), np.vstack([x1, near1]), rng.uniform(0, 1, 280), (220, 220),
                           (220, 220))
    kept = {tuple(r) for r in np.round(np.hstack([k0, k1]), 6)}
    both = np.round(np.hstack([np.vstack([x0, near0]), np.vstack([x1, near1])]), 6)
    _, member = cluster_representatives(np.vstack([x0, near0]), np.vstack([x1, near1]), np.zeros(280))
    for c in np.unique(member):
        verdicts = {tuple(r) in kept for r in both[member == c]}
        assert len(verdicts) == 1
    assert len(k0) > 250


def test_cluster_representatives_are_apart_and_members_near():
    rng = np.random.default_rng(7)
    xy0 = rng.uniform(0, 60, (3000, 2))
    xy1 = xy0 * 1.1 + rng.normal(0, 2, (3000, 2))
    scores = rng.uniform(0, 1, 3000)
    rep, cluster = cluster_representatives(xy0, xy1, scores, radius=4.0)
    ends = np.hstack([xy0, xy1])
    gap = np.abs(ends[rep][:, None] - ends[rep][None]).max(axis=2)
    np.fill_diagonal(gap, np.inf)
    assert gap.min() > 4.0  # no representative within the radius of another at both ends
    assert np.abs(ends - ends[rep[cluster]]).max() <= 4.0  # every member near its representative
    assert np.all(cluster[rep] == np.arange(len(rep)))
    assert np.all(scores[rep[cluster]] <= scores)  # the representative is the best-scored member
