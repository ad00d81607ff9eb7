"""What Slime tells its user: the stage that left no match and why, and the layouts that make a run slow."""

from slime_match.slime.blocks import make_tiles
from slime_match.slime.diagnostics import (
    MANY_BLOCK_PAIRS,
    MANY_TILES,
    empty_result_reason,
    layout_warning,
    tile_count_warning,
)
from slime_match.slime.tile_sets import TileConfig


def _counts(**values: int) -> dict[str, int]:
    return {"block_planes": 5, "superset_H": 40, "epipolar_kept": 100, "ftheta_matches": 90, "tile_matches": 7,
            **values}


def test_empty_result_reason_names_the_stage():
    tiles = TileConfig()
    assert "no block pair gave a plane" in empty_result_reason(_counts(block_planes=0), tiles)
    # |H| (|H| - 1) ordered pairs of sets can never exceed 9 |H| votes when |H| <= 10
    impossible = empty_result_reason(_counts(superset_H=10, epipolar_kept=0), tiles)
    assert "cannot keep a match with only 10 tile match sets" in impossible and "of the 90 epipolar geometries" in impossible
    shared = empty_result_reason(_counts(superset_H=11, epipolar_kept=0), tiles)
    assert "do not share one epipolar geometry" in shared and "shared by 3 planes (the consensus vote)" in shared
    paper = empty_result_reason(_counts(superset_H=11, epipolar_kept=0), TileConfig(vote="paper"))
    assert "do not share one epipolar geometry" in paper and "consensus" not in paper
    assert "Sec. 3.7" in empty_result_reason(_counts(ftheta_matches=0), tiles)
    assert "kept none of the 90 plane matches and 7 tile matches" in empty_result_reason(_counts(), tiles)


def test_layout_warning_only_for_many_block_pairs():
    assert layout_warning(20, 20) is None
    assert layout_warning(MANY_BLOCK_PAIRS, 1) is None
    assert "4001 block pairs" in layout_warning(MANY_BLOCK_PAIRS + 1, 1)


def test_tile_count_warning_names_max_side():
    assert tile_count_warning(len(make_tiles(1536, 2048)), 12) is None
    message = tile_count_warning(12, len(make_tiles(2560, 3200)))
    assert "12 and 357 tiles" in message and "--max-side" in message


def test_tile_count_warning_from_more_than_many_tiles_in_either_image():
    assert tile_count_warning(MANY_TILES, MANY_TILES) is None
    assert "151 and 3 tiles" in tile_count_warning(MANY_TILES + 1, 3)
    assert "3 and 151 tiles" in tile_count_warning(3, MANY_TILES + 1)
    assert tile_count_warning(len(make_tiles(1536, 2048)), 1) is None  # 2048 x 1536 still passes


def test_empty_result_reason_follows_the_stage_counts():
    """The reason names the first stage that kept nothing, in paper order; the vote's message depends on
    whether t_xi |H| votes are reachable (|H| - 1 > t_xi) with the configured t_xi."""
    tiles = TileConfig(t_xi=3.0)
    reachable = empty_result_reason(_counts(superset_H=5, epipolar_kept=0), tiles)
    assert "do not share one epipolar geometry" in reachable and "the 5 tile match sets" in reachable
    unreachable = empty_result_reason(_counts(superset_H=4, epipolar_kept=0), tiles)
    assert "cannot keep a match with only 4 tile match sets" in unreachable
    assert "must agree with more than 3 x 4 (t_xi |H|) of the 12 epipolar geometries" in unreachable
    assert "of the 12 epipolar geometries" in unreachable
    # an earlier stage wins over a later one
    first = empty_result_reason(_counts(block_planes=0, epipolar_kept=0), tiles)
    assert "no block pair gave a plane" in first
