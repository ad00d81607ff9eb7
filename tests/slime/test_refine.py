"""Sec. 3.8: the tile stage's candidate tests, the tile matches, near-duplicate clusters and the final global
DTM, and Slime's final matches."""

import cv2
import numpy as np
import pytest

from slime_match.config import make_config
from slime_match.errors import ConfigError
from slime_match.matching.dtm import DTMConfig
from slime_match.slime.blocks import make_tiles
from slime_match.slime.levels import build_levels
from slime_match.slime.refine import (
    FinalMatches,
    FlowGuide,
    PlaneGuide,
    TileMatches,
    cluster_representatives,
    final_matches,
    global_dtm,
    match_tiles,
    tile_test,
)

from .helpers import SIZE, squares


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
    assert np.array_equal(guide(y0, y1), expected)
    assert FlowGuide(np.zeros((0, 2)), np.zeros((0, 2)), 15.0)(y0, y1).sum() == 0


def test_flow_guide_finds_a_passing_guide_behind_many_nearer_failing_ones():
    """Twenty guides 15.5 px off in image 0 alone (4-D distance 15.5, failing) and one 14 px off in both
    images (4-D distance 19.8, passing): the candidate passes."""
    g0 = np.vstack([np.tile([[15.5, 0.0]], (20, 1)), [[14.0, 0.0]]])
    g1 = np.vstack([np.zeros((20, 2)), [[14.0, 0.0]]])
    guide = FlowGuide(g0, g1, 15.0)
    assert guide(np.zeros((1, 2)), np.zeros((1, 2))).tolist() == [True]
    assert FlowGuide(g0[:20], g1[:20], 15.0)(np.zeros((1, 2)), np.zeros((1, 2))).tolist() == [False]


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
    k0, k1, s, _ = global_dtm(xy0, xy1, scores, (220, 220), (220, 220))
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
    k0, k1, _, _ = global_dtm(np.vstack([x0, near0]), np.vstack([x1, near1]), rng.uniform(0, 1, 280), (220, 220),
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


def test_final_matches_without_tiles_are_the_plane_matches_sorted():
    """Sec. 3.8 did not run (``tiles`` None): F^theta's matches sorted by score (stable), nothing merged or
    filtered, whether or not the global DTM is asked for."""
    xy0 = np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 0.0], [7.0, 3.0]])
    xy1 = np.array([[5.0, 5.0], [6.0, 6.0], [5.0, 5.0], [9.0, 9.0]])
    scores = np.array([0.3, 0.1, 0.2, 0.1])
    for run_dtm in (False, True):
        final = final_matches(xy0, xy1, scores, None, (20, 20), (20, 20), run_dtm)
        assert isinstance(final, FinalMatches)
        np.testing.assert_array_equal(final.xy0, [[1.0, 1.0], [7.0, 3.0], [0.0, 0.0], [0.0, 0.0]])
        np.testing.assert_array_equal(final.xy1, [[6.0, 6.0], [9.0, 9.0], [5.0, 5.0], [5.0, 5.0]])
        np.testing.assert_array_equal(final.scores, [0.1, 0.1, 0.2, 0.3])
        for got, given in ((final.input_xy0, xy0), (final.input_xy1, xy1), (final.input_scores, scores)):
            np.testing.assert_array_equal(got, given)
        assert final.counts == {"final": 4}


def test_final_matches_with_tiles_and_no_dtm_merge_exact_duplicates():
    """With tile matches and no global DTM: F^theta's then the tile matches, exact duplicates merged (the
    best-scored kept), sorted by score; the input is kept for ``--save-stages``."""
    xy0 = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
    xy1 = np.array([[10.0, 10.0], [11.0, 11.0], [12.0, 12.0]])
    scores = np.array([0.5, 0.1, 0.3])
    tiles = TileMatches(np.array([[1.0, 1.0], [3.0, 3.0], [2.0, 2.0]]),
                        np.array([[11.0, 11.0], [13.0, 13.0], [12.0, 12.0]]), np.array([0.2, 0.05, 0.3]))
    final = final_matches(xy0, xy1, scores, tiles, (20, 20), (20, 20), run_dtm=False)
    np.testing.assert_array_equal(final.xy0, [[3.0, 3.0], [1.0, 1.0], [2.0, 2.0], [0.0, 0.0]])
    np.testing.assert_array_equal(final.xy1, [[13.0, 13.0], [11.0, 11.0], [12.0, 12.0], [10.0, 10.0]])
    np.testing.assert_array_equal(final.scores, [0.05, 0.1, 0.3, 0.5])  # (1, 1) kept at 0.1, not 0.2
    np.testing.assert_array_equal(final.input_xy0, np.vstack([xy0, tiles.xy0]))
    np.testing.assert_array_equal(final.input_xy1, np.vstack([xy1, tiles.xy1]))
    np.testing.assert_array_equal(final.input_scores, [0.5, 0.1, 0.3, 0.2, 0.05, 0.3])
    assert final.counts == {"final": 4}
    arrays = final.arrays()
    assert sorted(arrays) == ["dtm_input_score", "dtm_input_xy0", "dtm_input_xy1", "final_xy0", "final_xy1"]
    np.testing.assert_array_equal(arrays["final_xy0"], final.xy0)
    np.testing.assert_array_equal(arrays["dtm_input_score"], final.input_scores)


def test_final_matches_with_tiles_and_dtm_are_the_global_dtm():
    rng = np.random.default_rng(3)
    x0 = rng.uniform(0, 200, (300, 2))
    x1 = x0 + [10.0, 5.0]
    x1[:30] = rng.uniform(0, 200, (30, 2))  # outliers
    scores = rng.uniform(0, 1, 300)
    tiles = TileMatches(x0[:120] + 0.25, x1[:120] + 0.25, rng.uniform(0, 1, 120))
    config = DTMConfig()
    final = final_matches(x0[120:], x1[120:], scores[120:], tiles, (220, 220), (220, 220), True, config)
    k0, k1, s, _ = global_dtm(np.vstack([x0[120:], tiles.xy0]), np.vstack([x1[120:], tiles.xy1]),
                           np.concatenate([scores[120:], tiles.scores]), (220, 220), (220, 220), config)
    assert 200 < len(s) < 420
    for got, want in ((final.xy0, k0), (final.xy1, k1), (final.scores, s)):
        np.testing.assert_array_equal(got, want)


def test_tile_matches_empty_counts_and_arrays():
    empty = TileMatches.empty()
    assert empty.xy0.shape == (0, 2) and empty.xy1.shape == (0, 2) and empty.scores.shape == (0,)
    assert empty.counts == {"tile_matches": 0}
    tiles = TileMatches(np.ones((3, 2)), np.zeros((3, 2)), np.arange(3.0))
    assert tiles.counts == {"tile_matches": 3}
    arrays = tiles.arrays()
    assert sorted(arrays) == ["tile_matches_xy0", "tile_matches_xy1"]
    assert arrays["tile_matches_xy0"] is tiles.xy0 and arrays["tile_matches_xy1"] is tiles.xy1


def test_match_tiles_returns_the_tested_tile_matches_in_original_pixels(levels):
    """The tile pairs of a shifted image, matched under theta = 0: TileMatches in original px that follow the
    shift; the candidate test sees original px and the tile pair's planes, and a test that passes nothing
    leaves no tile match."""
    pipeline = levels[0]
    image, _ = squares()
    moved = cv2.warpAffine(image, np.float32([[1, 0, 6], [0, 1, 4]]), SIZE[::-1], borderMode=cv2.BORDER_REFLECT)
    tiles = make_tiles(*SIZE)
    levels0 = build_levels(pipeline, image, tiles, regions_only=True)
    levels1 = build_levels(pipeline, moved, tiles, regions_only=True)
    pairs = np.array([[c, c] for c in range(len(tiles))])
    seen = []

    def everything(y0, y1, planes):
        seen.append((y0.copy(), y1.copy(), planes.tolist()))
        return np.ones(len(y0), bool)

    found = match_tiles(pipeline, levels0, levels1, tiles, tiles, pairs, np.zeros(len(pairs)),
                        np.arange(len(pairs)) % 2, everything)
    assert isinstance(found, TileMatches) and len(found.xy0) > 20
    assert found.xy0.dtype == np.float64 and found.xy1.shape == found.xy0.shape == (len(found.scores), 2)
    shift = np.median(found.xy1 - found.xy0, axis=0)
    np.testing.assert_allclose(shift, [6.0, 4.0], atol=0.5)
    assert sorted(planes for *_, planes in seen) == sorted([k % 2] for k in range(len(pairs)))
    assert max(y0[:, 0].max() for y0, _, _ in seen) > 192  # original px, not a tile's own frame
    none = match_tiles(pipeline, levels0, levels1, tiles, tiles, pairs, np.zeros(len(pairs)),
                       np.zeros(len(pairs), np.int64), lambda y0, y1, planes: np.zeros(len(y0), bool))
    assert len(none.xy0) == 0 and none.counts == {"tile_matches": 0}
