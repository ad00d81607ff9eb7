"""Tile-level set logic on hand-built sets and a synthetic two-plane scene with a known F."""

import math

import numpy as np
import pytest
import scipy.sparse as sp

from slime_match.geometry.fundamental import epipolar_distance, epipolar_distance_batch, fundamental_8point
from slime_match.slime import tiles
from slime_match.slime.blocks import make_tiles
from slime_match.slime.epipolar_kernels import epipolar_votes
from slime_match.slime.planes import MatchTable
from slime_match.slime.tile_kernels import greedy_cover
from slime_match.slime.tiles import (
    TileSets,
    _fundamental_from_moments,
    best_sets_per_tile,
    best_sets_per_tile_pair,
    epipolar_consistency,
    fuse_planes,
    global_orientation_filter,
    greedy_two_per_tile,
    plane_groups,
    tile_sets,
)


def _table(xy0, xy1, rho=None):
    m = len(xy0)
    rho = np.zeros(m) if rho is None else rho
    return MatchTable(
        xy0, xy1, np.zeros(m), rho, np.ones(m), np.ones(m), np.ones(m), np.zeros(m), np.zeros(m)
    )


def _sets(rows, n_matches, tile0, tile1, plane=None):
    r = np.concatenate([np.full(len(m), i) for i, m in enumerate(rows)])
    c = np.concatenate([np.asarray(m) for m in rows])
    mat = sp.csr_matrix((np.ones(len(c), bool), (r, c)), shape=(len(rows), n_matches))
    plane = np.arange(len(rows)) if plane is None else plane
    return TileSets.from_csr(mat, plane, tile0, tile1)


def _as_sets(ts):
    return [set(ts.members(s).tolist()) for s in range(len(ts))]


def test_tile_sets_exact():
    tiles = make_tiles(480, 640)  # 3 x 4 tiles; first row cores x: [0,192) [149,341) [299,491) [448,640)
    xy0 = np.array([[50.0, 50.0], [170.0, 50.0], [600.0, 400.0], [50.0, 50.0]])
    xy1 = np.array([[50.0, 50.0], [50.0, 50.0], [600.0, 400.0], [170.0, 50.0]])
    table = _table(xy0, xy1)
    planes = sp.csr_matrix(np.array([[1, 1, 0, 0], [0, 1, 1, 1]], bool))
    ts = tile_sets(table, planes, tiles, tiles)
    got = {(int(ts.plane[s]), int(ts.tile0[s]), int(ts.tile1[s])): _as_sets(ts)[s] for s in range(len(ts))}
    last = len(tiles) - 1
    expected = {
        (0, 0, 0): {0, 1},  # match 1 has x in tiles 0 and 1 (overlap), x' in tile 0
        (0, 1, 0): {1},
        (1, 0, 0): {1, 3},
        (1, 1, 0): {1},
        (1, 0, 1): {3},  # x' of match 3 in tiles 0 and 1
        (1, last, last): {2},
    }
    assert got == expected
    assert ts.n_matches == 4
    keys = list(zip(ts.plane.tolist(), ts.tile0.tolist(), ts.tile1.tolist()))
    assert keys == sorted(keys)  # sets by (l, c, c'), matches ascending within each
    assert all(np.all(np.diff(ts.members(s)) > 0) for s in range(len(ts)))
    # restrict: the same sets, each without the dropped match 1 (possibly empty)
    kept = ts.restrict(np.array([True, False, True, True]))
    assert [k for k in zip(kept.plane.tolist(), kept.tile0.tolist(), kept.tile1.tolist())] == keys
    assert _as_sets(kept) == [m - {1} for m in _as_sets(ts)]
    assert kept.sizes().tolist() == [len(m - {1}) for m in _as_sets(ts)]


def test_best_sets_per_tile_pair_is_coverage_greedy():
    # tile pair (0, 0): A = 0..9, B = 0..8 (no new matches after A), C = 10..14; tile pair (1, 2): D, E
    rows = [range(10), range(9), range(10, 15), range(20, 23), range(22, 30)]
    ts = _sets(rows, 30, tile0=[0, 0, 0, 1, 1], tile1=[0, 0, 0, 2, 2])
    assert best_sets_per_tile_pair(ts, q=1).tolist() == [0, 4]
    assert best_sets_per_tile_pair(ts, q=2).tolist() == [0, 2, 3, 4]
    # weights change the ranking: matches 10..14 become heavy
    w = np.ones(30)
    w[10:15] = 10.0
    assert best_sets_per_tile_pair(ts, w, q=1).tolist() == [2, 4]


def test_greedy_cover_ties_and_sets_adding_nothing():
    rows = [[0, 1], [2, 3], [0, 1, 2], [5], [6]]  # group 0: sets 0-2, group 1: sets 3-4
    indptr = np.r_[0, np.cumsum([len(r) for r in rows])]
    indices = np.concatenate(rows).astype(np.int64)
    start, order = np.array([0, 3, 5]), np.arange(5)
    # group 0: set 2 (3 new), then set 1 (match 3), then nothing (set 0 adds nothing); group 1: a tie, 3 then 4
    assert greedy_cover(indptr, indices, np.ones(7), start, order, 3).tolist() == [1, 2, 3, 4]
    assert greedy_cover(indptr, indices, np.ones(7), start, order, 1).tolist() == [2, 3]
    heavy = np.array([1, 1, 1, 1, 1, 1, 5.0])
    assert greedy_cover(indptr, indices, heavy, start, order, 1).tolist() == [2, 4]


def test_best_sets_per_tile_spans_the_other_image():
    # tile 0 in image 1 has 6 sets over different tiles c' in image 2; only 4 best (by coverage) survive
    rows = [range(10), range(9), range(10, 18), range(18, 25), range(25, 31), range(31, 36)]
    ts = _sets(rows, 40, tile0=[0] * 6, tile1=[0, 1, 2, 3, 4, 5])
    assert best_sets_per_tile(ts, q=4).tolist() == [0, 1, 2, 3, 4, 5]  # each set is the best of its c'
    only0 = best_sets_per_tile(_sets(rows, 40, tile0=[0] * 6, tile1=[0] * 6), q=4)
    assert only0.tolist() == [0, 2, 3, 4]  # set 1 adds nothing after set 0; set 5 is fifth


def _two_plane_scene(seed=0, n=200):
    rng = np.random.default_rng(seed)
    k = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    a = 0.15
    r = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    t = np.array([-1.0, 0.1, 0.05])

    def on_plane(normal, d):
        uv = rng.uniform([20, 20], [620, 460], (n, 2))
        ray = np.linalg.inv(k) @ np.vstack([uv.T, np.ones(n)])
        return (ray * (d / (normal @ ray))).T

    x3 = np.vstack([on_plane(np.array([0, 0, 1.0]), 6.0), on_plane(np.array([0.29, 0, 0.96]), 3.0)])
    p0 = (k @ x3.T).T
    p1 = (k @ (r @ x3.T + t[:, None])).T
    x0 = p0[:, :2] / p0[:, 2:] + rng.normal(0, 0.5, (2 * n, 2))
    x1 = p1[:, :2] / p1[:, 2:] + rng.normal(0, 0.5, (2 * n, 2))
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    f = np.linalg.inv(k).T @ tx @ r @ np.linalg.inv(k)
    # a wrong plane: matches consistent with a homography but far from the true epipolar lines
    hw = np.array([[0.9, 0.1, 60], [-0.1, 0.9, -40], [0, 0, 1.0]])
    w0 = rng.uniform([0, 0], [640, 480], (400, 2))
    w1 = w0 @ hw[:2, :2].T + hw[:2, 2]
    far = epipolar_distance(f, w0, w1) > 30
    return np.vstack([x0, w0[far][:60]]), np.vstack([x1, w1[far][:60]]), f


def test_moments_fundamental_matches_eight_point():
    x0, x1, _ = _two_plane_scene()
    idx = np.r_[0:30, 200:230]
    h0 = np.hstack([x0[idx], np.ones((60, 1))])
    h1 = np.hstack([x1[idx], np.ones((60, 1))])
    kk = (h1[:, :, None] * h0[:, None, :]).reshape(-1, 9)
    f = _fundamental_from_moments((kk.T @ kk)[None])[0]
    assert abs(np.linalg.det(f)) < 1e-12
    f_ref = fundamental_8point(x0[idx], x1[idx])[0]
    f_ref = f_ref / np.linalg.norm(f_ref) * np.sign(np.sum(f_ref * f))
    assert np.abs(f - f_ref).max() < 1e-3  # RMS vs mean-distance normalisation: tiny difference
    assert epipolar_distance(f, x0[idx], x1[idx]).max() < 3.0


def test_epipolar_votes_count_the_fundamental_matrices_within_the_threshold():
    rng = np.random.default_rng(0)
    f = rng.normal(size=(7, 3, 3))
    x0, x1 = rng.uniform(-2, 2, (50, 2)), rng.uniform(-2, 2, (50, 2))
    votes = np.full(50, 3.0)  # added to, not overwritten
    epipolar_votes(f, np.ascontiguousarray(x0.T), np.ascontiguousarray(x1.T), 0.5**2, votes)
    expected = 3 + (epipolar_distance_batch(f, x0, x1) < 0.5).sum(0)
    np.testing.assert_array_equal(votes, expected)
    assert 3 < votes.mean() < 10  # some votes, not all


def test_epipolar_consistency_keeps_the_scene_and_drops_a_wrong_plane(monkeypatch):
    x0, x1, _ = _two_plane_scene()
    n = 200
    table = _table(x0, x1)
    rng = np.random.default_rng(1)
    rows = [rng.choice(np.arange(n) + (n if d >= 12 else 0), 40, replace=False) for d in range(24)]
    rows += [np.arange(2 * n, 2 * n + 40), np.arange(2 * n + 20, 2 * n + 60)]  # overlapping wrong sets
    d = len(rows)
    ts = _sets(rows, len(table), tile0=np.arange(d) % 5, tile1=np.arange(d) % 7)
    keep = epipolar_consistency(table, ts)
    member = ts.union()
    assert keep[:400][member[:400]].all()
    assert not keep[400:].any()
    assert not keep[~member].any()
    # the vote threshold scales with |H|: with t_xi huge nothing survives
    assert not epipolar_consistency(table, ts, t_xi=100).any()
    # chunking does not change the result
    np.testing.assert_array_equal(epipolar_consistency(table, ts, chunk=5000), keep)
    # nor do threads, here sharing even the smallest chunks
    monkeypatch.setattr(tiles, "_THREADS_MIN_F", 1)
    monkeypatch.setattr(tiles, "_THREADS_MIN_TESTS", 1)
    np.testing.assert_array_equal(epipolar_consistency(table, ts, chunk=5000, threads=3), keep)


def test_greedy_two_per_tile():
    sizes = [10, 9, 8, 7, 6, 0]
    rows, start = [], 0
    for s in sizes:
        rows.append(range(start, start + s))
        start += s
    # sets 0, 1, 2 share tile 0 of image 1; set 3 shares tile 5 of image 2 with set 0 and 1
    ts = _sets(rows, start, tile0=[0, 0, 0, 1, 2, 3], tile1=[5, 5, 6, 5, 7, 8])
    assert greedy_two_per_tile(ts).tolist() == [0, 1, 4]


def test_greedy_two_per_tile_skips_near_copies_of_one_plane():
    # sets 0 and 1: the same tile pair, IoU 8/12 (near copies of one plane); set 2: another plane on tile 0;
    # set 3: a third plane on tile 0. Without t_ov the copy takes the second slot of tile 0.
    rows = [range(10), range(2, 12), range(20, 28), range(30, 36)]
    ts = _sets(rows, 40, tile0=[0, 0, 0, 0], tile1=[1, 1, 2, 3])
    assert greedy_two_per_tile(ts).tolist() == [0, 1]
    assert greedy_two_per_tile(ts, t_ov=1 / 3).tolist() == [0, 2]


def test_plane_groups_shared_and_iou():
    # plane 0: matches 0..9 in two sets of different tile pairs; plane 1: 5..12; plane 2: 8..30
    rows = [range(6), range(4, 10), range(5, 13), range(8, 31)]
    ts = _sets(rows, 40, tile0=[0, 1, 0, 2], tile1=[0, 1, 0, 2], plane=np.array([0, 0, 1, 2]))
    # shared: 2 heads (largest); it shares 5 of plane 1's 8 matches (> 1/3); plane 0 shares 2/10 with it
    assert plane_groups(ts, 1 / 3, "shared").tolist() == [0, 2, 2]
    # IoU: plane 2 / plane 1 = 5/26, plane 0 / plane 1 = 5/13 > 1/3
    assert plane_groups(ts, 1 / 3, "iou").tolist() == [0, 0, 2]
    assert plane_groups(ts, 0.9, "shared").tolist() == [0, 1, 2]


def test_greedy_two_per_tile_counts_homographies_not_sets():
    # tile 0 of image 1 meets one plane through three tile pairs (sets 0, 1, 2), then plane 1 and plane 2
    rows = [range(10), range(10, 19), range(19, 27), range(30, 37), range(40, 46)]
    ts = _sets(rows, 50, tile0=[0, 0, 0, 0, 0], tile1=[1, 2, 3, 4, 5], plane=np.array([0, 0, 0, 1, 2]))
    assert greedy_two_per_tile(ts).tolist() == [0, 1]  # literal: every set takes a slot
    assert greedy_two_per_tile(ts, groups=np.arange(3)).tolist() == [0, 1, 2, 3]  # plane 0 holds one slot
    # planes 1 and 2 grouped (near-copies): the third plane fits as well
    assert greedy_two_per_tile(ts, groups=np.array([0, 1, 1])).tolist() == [0, 1, 2, 3, 4]


def test_fuse_planes_by_iou():
    # same tile pair: A = 0..8, B = 3..11 (IoU 6/12 = 0.5), C = 8..20 (IoU with A 1/21); D other tile pair
    rows = [range(9), range(3, 12), range(8, 21), range(9)]
    pool = _sets(rows, 30, tile0=[0, 0, 0, 1], tile1=[0, 0, 0, 1])
    fused = fuse_planes(pool, pool.subset([0, 2]))
    assert _as_sets(fused) == [set(range(12)), set(range(8, 21))]  # C-B IoU 4/18, C-A 1/21: no fusion
    assert fused.plane.tolist() == [0, 2]


def test_fuse_planes_matches_the_definition_on_random_weighted_sets():
    """Against the definition, set by set: F^{l*}_v = the selected set and every pool set of its tile pair
    with weighted IoU > t_ov (empty sets included, a selected set absent from the pool)."""
    g = np.random.default_rng(5)
    n = 60
    rows = [g.choice(n, g.integers(0, 25), replace=False) for _ in range(40)]
    pool = _sets(rows, n, tile0=g.integers(0, 3, 40), tile1=g.integers(0, 3, 40))
    w = g.integers(1, 4, n).astype(np.float64)
    selected = pool.subset([0, 3, 7, 11, 19]).restrict(np.arange(n) != 5)
    fused = fuse_planes(pool, selected, w, t_ov=0.2)
    members = _as_sets(pool)
    for k, s in enumerate(_as_sets(selected)):
        expected = set(s)
        for t in range(len(pool)):
            same_pair = (pool.tile0[t], pool.tile1[t]) == (selected.tile0[k], selected.tile1[k])
            inter = sum(w[m] for m in s & members[t])
            union = sum(w[m] for m in s | members[t])
            if same_pair and inter > 0 and inter / union > 0.2:
                expected |= members[t]
        assert _as_sets(fused)[k] == expected
    assert any(len(f) > len(s) for f, s in zip(_as_sets(fused), _as_sets(selected)))
    np.testing.assert_array_equal(fused.plane, selected.plane)


def test_global_orientation_filter_drops_rotated_plane():
    rng = np.random.default_rng(0)
    m = 90
    rho = np.concatenate([rng.normal(0.3, 0.05, 60), rng.normal(0.3 + np.pi / 2, 0.05, 30)])
    table = _table(rng.uniform(0, 100, (m, 2)), rng.uniform(0, 100, (m, 2)), rho)
    rows = [range(20), range(20, 40), range(40, 60), range(60, 90)]
    ts = _sets(rows, m, tile0=[0, 1, 2, 3], tile1=[0, 1, 2, 3])
    keep, theta, theta_plus = global_orientation_filter(table, ts)
    assert keep.tolist() == [True, True, True, False]
    assert theta_plus == np.float64(2 * np.pi / 16)  # the bin centre nearest to 0.3 rad
    np.testing.assert_allclose(theta, [np.pi / 8] * 3 + [np.pi / 8 + np.pi / 2])


@pytest.mark.parametrize("mode", range(16))
def test_global_orientation_filter_keeps_sets_exactly_45_degrees_off(mode):
    # the global bin `mode` (three sets) and one set each at +-1, +-2 (exactly 45 deg) and +-3 bins away:
    # only the 3-bin sets are off by more than 45 deg, whatever the rounding of the bin centres
    step = 2 * np.pi / 16
    offsets = [0, 0, 0, 1, -1, 2, -2, 3, -3]
    rho = np.repeat([(mode + k) * step for k in offsets], 5)
    table = _table(np.zeros((len(rho), 2)), np.zeros((len(rho), 2)), rho)
    ts = _sets([range(5 * i, 5 * i + 5) for i in range(len(offsets))], len(rho), tile0=list(range(9)),
               tile1=list(range(9)))
    keep, _, theta_plus = global_orientation_filter(table, ts)
    assert keep.tolist() == [abs(k) <= 2 for k in offsets]
    np.testing.assert_allclose(np.cos(theta_plus - mode * step), 1.0)
