"""Plane selection (Secs. 3.5-3.7 in a row): the PlaneSelection of a synthetic two-plane scene with a wrong
plane, and its counts and ``--save-stages`` arrays."""

import numpy as np
import scipy.sparse as sp

from slime_match.slime.blocks import make_tiles
from slime_match.slime.epipolar_vote import epipolar_consistency
from slime_match.slime.selection import PlaneSelection, select_planes
from slime_match.slime.tile_sets import TileConfig, best_sets_per_tile, best_sets_per_tile_pair, tile_sets

from .helpers import make_sets, make_table, set_members, two_plane_scene


def _keys(sets):
    return list(zip(sets.plane.tolist(), sets.tile0.tolist(), sets.tile1.tolist()))


def test_select_planes_keeps_the_scene_and_drops_a_wrong_plane():
    """Three plane memberships (the scene's two planes, and 20 matches of a wrong plane far from the epipolar
    lines; the scene's other matches in no plane): the tile sets, H*, H and the vote are those of the stage
    functions; the vote and F^theta keep matches of both planes and none of the wrong one, each F^theta set is
    its fused set, F-bar's set within it, at the global orientation 0."""
    x0, x1, _ = two_plane_scene()
    table = make_table(x0, x1)
    n = len(table)
    rows = np.repeat(np.arange(3), [200, 200, 20])
    expanded = sp.csr_matrix((np.ones(420, bool), (rows, np.arange(420))), shape=(3, n))
    tiles = make_tiles(480, 640)
    config = TileConfig()
    selection = select_planes(table, expanded, tiles, tiles, config)
    assert isinstance(selection, PlaneSelection)
    sets = tile_sets(table, expanded, tiles, tiles)
    assert _keys(selection.sets) == _keys(sets) and set_members(selection.sets) == set_members(sets)
    star = sets.subset(best_sets_per_tile_pair(sets, table.weight, q=config.q_pair))
    superset = star.subset(best_sets_per_tile(star, table.weight, q=config.q_tile))
    assert _keys(selection.superset) == _keys(superset)
    np.testing.assert_array_equal(selection.keep, epipolar_consistency(table, superset))
    assert selection.keep[:400].sum() > 300 and not selection.keep[400:].any()
    assert set(selection.superset.plane.tolist()) == {0, 1, 2}  # the wrong plane reached the vote
    kept = selection.ftheta.union()
    assert kept[:200].any() and kept[200:400].any() and not kept[400:].any()
    assert set(selection.ftheta.plane.tolist()) == {0, 1}
    fused = {key: members for key, members in zip(_keys(selection.fused), set_members(selection.fused))}
    fbar = {key: members for key, members in zip(_keys(selection.fbar), set_members(selection.fbar))}
    for key, members in zip(_keys(selection.ftheta), set_members(selection.ftheta)):
        assert members == fused[key] and fbar[key] <= members
    assert selection.theta_plus == 0.0 and np.all(selection.theta == 0.0)
    assert len(selection.theta) == len(selection.ftheta)
    counts = selection.counts
    assert counts == {"tile_sets": len(sets), "superset_H": len(superset),
                      "epipolar_kept": int(selection.keep.sum()), "epipolar_planes": 2, "fbar_sets": len(selection.fbar),
                      "ftheta_sets": len(selection.ftheta), "ftheta_matches": int(kept.sum())}
    assert selection.vote == "paper" and selection.vote_reason == (
        "the paper's epipolar vote kept 400 matches consistent with the epipolar geometry of enough pairs of planes "
        "(M+), on 2 planes")


def test_plane_selection_counts_and_arrays():
    sets = make_sets([[0, 1], [1, 2, 3], [4], [5, 6]], 8, tile0=[0, 0, 1, 2], tile1=[0, 1, 1, 2])
    keep = np.array([True, True, False, True, True, False, True, False])
    fbar = sets.subset([1, 3]).restrict(keep)
    fused = make_sets([[0, 1, 3], [6]], 8, tile0=[0, 2], tile1=[1, 2], plane=np.array([1, 3]))
    selection = PlaneSelection(sets, sets.subset([0, 1, 3]), keep, fbar, fused, fused.subset([0]),
                               np.array([0.25]), 0.5, "consensus", "why", 3)
    assert selection.counts == {"tile_sets": 4, "superset_H": 3, "epipolar_kept": 5, "epipolar_planes": 3, "fbar_sets": 2,
                                "ftheta_sets": 1, "ftheta_matches": 3}
    arrays = selection.arrays()
    families = [f"{name}_{field}" for name in ("superset", "fbar", "ftheta")
                for field in ("plane", "tile0", "tile1", "indptr", "indices")]
    assert sorted(arrays) == sorted(["epipolar_keep", "ftheta_theta", "theta_plus", *families])
    np.testing.assert_array_equal(arrays["epipolar_keep"], keep)
    assert arrays["theta_plus"].shape == () and float(arrays["theta_plus"]) == 0.5
    assert arrays["ftheta_theta"].tolist() == [0.25]
    assert arrays["superset_plane"].tolist() == [0, 1, 3]
    assert arrays["superset_indptr"].tolist() == [0, 2, 5, 7]
    assert arrays["superset_indices"].tolist() == [0, 1, 1, 2, 3, 5, 6]
    assert arrays["fbar_indices"].tolist() == [1, 3, 6] and arrays["fbar_indptr"].tolist() == [0, 2, 3]
    assert arrays["ftheta_plane"].tolist() == [1] and arrays["ftheta_tile0"].tolist() == [0]
    assert arrays["ftheta_tile1"].tolist() == [1] and arrays["ftheta_indices"].tolist() == [0, 1, 3]
