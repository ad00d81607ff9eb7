"""Tile sets (Sec. 3.5): plane memberships split by tile pair, and the coverage-greedy choice of the best sets
per tile pair and per tile, on hand-built sets."""

import numpy as np
import scipy.sparse as sp

from slime_match.slime.blocks import make_tiles
from slime_match.slime.tile_kernels import greedy_cover
from slime_match.slime.tile_sets import best_sets_per_tile, best_sets_per_tile_pair, tile_sets

from .helpers import make_sets, make_table, set_members


def test_tile_sets_exact():
    tiles = make_tiles(480, 640)  # 3 x 4 tiles; first row cores x: [0,192) [149,341) [299,491) [448,640)
    xy0 = np.array([[50.0, 50.0], [170.0, 50.0], [600.0, 400.0], [50.0, 50.0]])
    xy1 = np.array([[50.0, 50.0], [50.0, 50.0], [600.0, 400.0], [170.0, 50.0]])
    table = make_table(xy0, xy1)
    planes = sp.csr_matrix(np.array([[1, 1, 0, 0], [0, 1, 1, 1]], bool))
    ts = tile_sets(table, planes, tiles, tiles)
    got = {(int(ts.plane[s]), int(ts.tile0[s]), int(ts.tile1[s])): set_members(ts)[s] for s in range(len(ts))}
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
    assert set_members(kept) == [m - {1} for m in set_members(ts)]
    assert kept.sizes().tolist() == [len(m - {1}) for m in set_members(ts)]


def test_best_sets_per_tile_pair_is_coverage_greedy():
    # tile pair (0, 0): A = 0..9, B = 0..8 (no new matches after A), C = 10..14; tile pair (1, 2): D, E
    rows = [range(10), range(9), range(10, 15), range(20, 23), range(22, 30)]
    ts = make_sets(rows, 30, tile0=[0, 0, 0, 1, 1], tile1=[0, 0, 0, 2, 2])
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
    ts = make_sets(rows, 40, tile0=[0] * 6, tile1=[0, 1, 2, 3, 4, 5])
    assert best_sets_per_tile(ts, q=4).tolist() == [0, 1, 2, 3, 4, 5]  # each set is the best of its c'
    only0 = best_sets_per_tile(make_sets(rows, 40, tile0=[0] * 6, tile1=[0] * 6), q=4)
    assert only0.tolist() == [0, 2, 3, 4]  # set 1 adds nothing after set 0; set 5 is fifth
