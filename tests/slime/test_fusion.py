"""Plane fusion and the global orientation filter (Sec. 3.7) on hand-built tile sets."""

import numpy as np
import pytest

from slime_match.slime.fusion import fuse_planes, global_orientation_filter, greedy_two_per_tile, plane_groups

from .helpers import make_sets, make_table, set_members


def test_greedy_two_per_tile():
    sizes = [10, 9, 8, 7, 6, 0]
    rows, start = [], 0
    for s in sizes:
        rows.append(range(start, start + s))
        start += s
    # sets 0, 1, 2 share tile 0 of image 1; set 3 shares tile 5 of image 2 with set 0 and 1
    ts = make_sets(rows, start, tile0=[0, 0, 0, 1, 2, 3], tile1=[5, 5, 6, 5, 7, 8])
    assert greedy_two_per_tile(ts).tolist() == [0, 1, 4]


def test_greedy_two_per_tile_skips_near_copies_of_one_plane():
    # sets 0 and 1: the same tile pair, IoU 8/12 (near copies of one plane); set 2: another plane on tile 0;
    # set 3: a third plane on tile 0. Without t_ov the copy takes the second slot of tile 0.
    rows = [range(10), range(2, 12), range(20, 28), range(30, 36)]
    ts = make_sets(rows, 40, tile0=[0, 0, 0, 0], tile1=[1, 1, 2, 3])
    assert greedy_two_per_tile(ts).tolist() == [0, 1]
    assert greedy_two_per_tile(ts, t_ov=1 / 3).tolist() == [0, 2]


def test_plane_groups_shared_and_iou():
    # plane 0: matches 0..9 in two sets of different tile pairs; plane 1: 5..12; plane 2: 8..30
    rows = [range(6), range(4, 10), range(5, 13), range(8, 31)]
    ts = make_sets(rows, 40, tile0=[0, 1, 0, 2], tile1=[0, 1, 0, 2], plane=np.array([0, 0, 1, 2]))
    # shared: 2 heads (largest); it shares 5 of plane 1's 8 matches (> 1/3); plane 0 shares 2/10 with it
    assert plane_groups(ts, 1 / 3, "shared").tolist() == [0, 2, 2]
    # IoU: plane 2 / plane 1 = 5/26, plane 0 / plane 1 = 5/13 > 1/3
    assert plane_groups(ts, 1 / 3, "iou").tolist() == [0, 0, 2]
    assert plane_groups(ts, 0.9, "shared").tolist() == [0, 1, 2]


def test_greedy_two_per_tile_counts_homographies_not_sets():
    # tile 0 of image 1 meets one plane through three tile pairs (sets 0, 1, 2), then plane 1 and plane 2
    rows = [range(10), range(10, 19), range(19, 27), range(30, 37), range(40, 46)]
    ts = make_sets(rows, 50, tile0=[0, 0, 0, 0, 0], tile1=[1, 2, 3, 4, 5], plane=np.array([0, 0, 0, 1, 2]))
    assert greedy_two_per_tile(ts).tolist() == [0, 1]  # literal: every set takes a slot
    assert greedy_two_per_tile(ts, groups=np.arange(3)).tolist() == [0, 1, 2, 3]  # plane 0 holds one slot
    # planes 1 and 2 grouped (near-copies): the third plane fits as well
    assert greedy_two_per_tile(ts, groups=np.array([0, 1, 1])).tolist() == [0, 1, 2, 3, 4]


def test_fuse_planes_by_iou():
    # same tile pair: A = 0..8, B = 3..11 (IoU 6/12 = 0.5), C = 8..20 (IoU with A 1/21); D other tile pair
    rows = [range(9), range(3, 12), range(8, 21), range(9)]
    pool = make_sets(rows, 30, tile0=[0, 0, 0, 1], tile1=[0, 0, 0, 1])
    fused = fuse_planes(pool, pool.subset([0, 2]))
    assert set_members(fused) == [set(range(12)), set(range(8, 21))]  # C-B IoU 4/18, C-A 1/21: no fusion
    assert fused.plane.tolist() == [0, 2]


def test_fuse_planes_matches_the_definition_on_random_weighted_sets():
    """Against the definition, set by set: F^{l*}_v = the selected set and every pool set of its tile pair
    with weighted IoU > t_ov (empty sets included, a selected set absent from the pool)."""
    g = np.random.default_rng(5)
    n = 60
    rows = [g.choice(n, g.integers(0, 25), replace=False) for _ in range(40)]
    pool = make_sets(rows, n, tile0=g.integers(0, 3, 40), tile1=g.integers(0, 3, 40))
    w = g.integers(1, 4, n).astype(np.float64)
    selected = pool.subset([0, 3, 7, 11, 19]).restrict(np.arange(n) != 5)
    fused = fuse_planes(pool, selected, w, t_ov=0.2)
    members = set_members(pool)
    for k, s in enumerate(set_members(selected)):
        expected = set(s)
        for t in range(len(pool)):
            same_pair = (pool.tile0[t], pool.tile1[t]) == (selected.tile0[k], selected.tile1[k])
            inter = sum(w[m] for m in s & members[t])
            union = sum(w[m] for m in s | members[t])
            if same_pair and inter > 0 and inter / union > 0.2:
                expected |= members[t]
        assert set_members(fused)[k] == expected
    assert any(len(f) > len(s) for f, s in zip(set_members(fused), set_members(selected)))
    np.testing.assert_array_equal(fused.plane, selected.plane)


def test_global_orientation_filter_drops_rotated_plane():
    rng = np.random.default_rng(0)
    m = 90
    rho = np.concatenate([rng.normal(0.3, 0.05, 60), rng.normal(0.3 + np.pi / 2, 0.05, 30)])
    table = make_table(rng.uniform(0, 100, (m, 2)), rng.uniform(0, 100, (m, 2)), angle1=rho)
    rows = [range(20), range(20, 40), range(40, 60), range(60, 90)]
    ts = make_sets(rows, m, tile0=[0, 1, 2, 3], tile1=[0, 1, 2, 3])
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
    table = make_table(np.zeros((len(rho), 2)), np.zeros((len(rho), 2)), angle1=rho)
    ts = make_sets([range(5 * i, 5 * i + 5) for i in range(len(offsets))], len(rho), tile0=list(range(9)),
               tile1=list(range(9)))
    keep, _, theta_plus = global_orientation_filter(table, ts)
    assert keep.tolist() == [abs(k) <= 2 for k in offsets]
    np.testing.assert_allclose(np.cos(theta_plus - mode * step), 1.0)
