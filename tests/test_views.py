"""Simulated views (ASIFT tilts): geometry, images, rotation sampling, configuration, and the view frames of
blocks and block planes."""

import math

import numpy as np
import pytest

from slime_match.errors import ConfigError
from slime_match.geometry.frames import Frame
from slime_match.slime.block_planes import BlockPairMatches, block_planes_to_original
from slime_match.slime.blocks import BlockConfig, make_blocks, make_view_blocks, points_in_blocks
from slime_match.views import View, ViewConfig, simulate_view, view_geometry, views_of_tilt


def _corners(width: int, height: int) -> np.ndarray:
    return np.array([[0, 0], [width - 1, 0], [0, height - 1], [width - 1, height - 1]], float)


@pytest.mark.parametrize("tilt,angle", [(1.0, 0.0), (2.0, 0.0), (2.0, 36.0), (4.0, 108.0), (2.0 ** 0.5, 90.0)])
def test_view_geometry_keeps_the_whole_image_inside_the_view(tilt, angle):
    view = view_geometry((640, 480), tilt, angle)
    corners = view.frame.from_original(_corners(640, 480))
    assert np.all(corners >= -0.5 - 1e-9) and np.all(corners <= np.array(view.size) - 0.5 + 1e-9)
    # the view is the bounding box: some corner pixel centre comes within 2 px of each of its sides
    assert corners[:, 0].min() < 1.5 and corners[:, 1].min() < 1.5
    assert np.all(corners.max(0) > np.array(view.size) - 2.5)
    np.testing.assert_allclose(view.frame.to_original(corners), _corners(640, 480), atol=1e-9)


def test_view_geometry_compresses_x_by_the_tilt_and_keeps_areas_in_ratio():
    view = view_geometry((400, 300), 4.0, 0.0)
    assert view.size == (100, 300)
    a = view.frame.matrix()[:2, :2]
    np.testing.assert_allclose(a, np.diag([0.25, 1.0]), atol=1e-12)
    turned = view_geometry((400, 300), 2.0, 90.0).frame.matrix()[:2, :2]
    assert abs(abs(np.linalg.det(turned)) - 0.5) < 1e-12


def test_simulated_view_puts_a_dot_where_the_affine_map_says():
    image = np.zeros((120, 160, 3), np.float32)
    dot = np.array([97.0, 41.0])
    yy, xx = np.mgrid[0:120, 0:160]
    image[..., :] = np.exp(-((xx - dot[0]) ** 2 + (yy - dot[1]) ** 2) / (2 * 3.0 ** 2))[..., None]
    for tilt, angle in ((1.0, 0.0), (2.0, 36.0), (4.0, 72.0)):
        warped, view = simulate_view(image, tilt, angle)
        assert warped.shape == (view.size[1], view.size[0], 3) and warped.dtype == np.float32
        grey = warped[..., 0]
        expected = view.frame.from_original(dot[None])[0]
        peak = np.array(np.unravel_index(np.argmax(grey), grey.shape))[::-1]
        near = (np.abs(np.arange(grey.shape[1]) - expected[0]) <= 4)[None] & \
               (np.abs(np.arange(grey.shape[0]) - expected[1]) <= 6)[:, None]
        weights = grey * near
        centroid = np.array([np.sum(weights * np.arange(grey.shape[1])[None]), np.sum(weights * np.arange(
            grey.shape[0])[:, None])]) / weights.sum()
        assert np.linalg.norm(peak - expected) <= 1.5, (tilt, angle, peak, expected)
        assert np.linalg.norm(centroid - expected) <= 0.5, (tilt, angle, centroid, expected)


def test_the_identity_view_is_the_image():
    image = np.random.default_rng(0).random((50, 70, 3)).astype(np.float32)
    warped, view = simulate_view(image, 1.0, 0.0)
    np.testing.assert_allclose(warped, image, atol=1e-5)
    assert view.size == (70, 50)


def test_asift_rotation_sampling():
    assert views_of_tilt(2.0) == pytest.approx([0, 36, 72, 108, 144])
    assert len(views_of_tilt(4.0)) == 10 and views_of_tilt(4.0)[1] == pytest.approx(18.0)
    assert len(views_of_tilt(2 ** 0.5)) == 4 and max(views_of_tilt(2 ** 0.5)) < 180


def test_view_config_checks_its_values():
    assert ViewConfig().mode == "auto" and ViewConfig(tilts=[2, 4]).tilts == (2.0, 4.0)
    with pytest.raises(ConfigError, match="views.mode"):
        ViewConfig(mode="sometimes")
    with pytest.raises(ConfigError, match="tilts"):
        ViewConfig(tilts=(1.0, 2.0))
    with pytest.raises(ConfigError, match="min_support"):
        ViewConfig(min_support=0)


def test_view_inside_drops_the_reflected_border():
    view = view_geometry((100, 80), 2.0, 30.0)
    points = np.array([[50.0, 40.0], [0.0, 40.0], [-5.0, 10.0], [99.0, 79.0], [97.0, 77.0]])
    np.testing.assert_array_equal(view.inside(points), [True, False, False, False, True])


def test_frame_with_a_view_composes_the_affine_map_first():
    view = view_geometry((300, 200), 2.0, 36.0)
    frame = Frame((0.5, 0.5), (10.0, 4.0), view.affine)
    xy = np.array([[12.0, 7.0], [250.0, 150.0]])
    level = (view.frame.from_original(xy) + 0.5) * 0.5 - 0.5 - np.array([10.0, 4.0])
    np.testing.assert_allclose(frame.from_original(xy), level, atol=1e-9)
    np.testing.assert_allclose(frame.to_original(level), xy, atol=1e-9)
    homogeneous = np.c_[xy, np.ones(2)] @ frame.matrix().T
    np.testing.assert_allclose(homogeneous[:, :2], level, atol=1e-9)


def test_view_blocks_share_the_original_scales_and_own_only_points_inside_the_image():
    config = BlockConfig()
    view = view_geometry((640, 480), 2.0, 0.0)
    blocks = make_view_blocks(480, 640, view, config)
    plain = make_blocks(480, 640, config)
    assert {b.scale_index for b in blocks} == {0, 1, 2}
    for k in range(3):  # the same factor per scale as the image's own blocks
        assert {b.factor for b in blocks if b.scale_index == k} == {next(b.factor for b in plain if b.scale_index == k)}
    assert all(b.view == view for b in blocks)
    rng = np.random.default_rng(1)
    xy = np.r_[rng.uniform(0, 639, (300, 2)) * [1, 479 / 639], [[-3.0, 5.0], [700.0, 10.0]]]
    member = points_in_blocks(xy, blocks).toarray()
    assert not member[:, -2:].any()  # outside the image: in no view block
    assert member[:, :-2].any(0).mean() > 0.95  # the view covers the image
    for k in np.flatnonzero(member[:, 0]):  # the point lies in the core of its blocks, in level px
        x, y = blocks[k].level_frame.from_original(xy[:1])[0]
        x0, y0, x1, y1 = blocks[k].core
        assert x0 - 0.5 <= x < x1 - 0.5 or x1 == blocks[k].scaled_size[0]
        assert y0 - 0.5 <= y < y1 - 0.5 or y1 == blocks[k].scaled_size[1]


def test_a_view_plane_maps_back_to_the_original_homography_and_patch_frame():
    """A plane found between a view's level and image 1's level maps to the homography between the originals,
    and the view's upright patches get their direction and size in the original."""
    config = BlockConfig()
    view = view_geometry((640, 480), 2.0, 36.0)
    blocks0 = make_view_blocks(480, 640, view, config)
    blocks1 = make_blocks(480, 640, config)
    b0, b1 = blocks0[5], blocks1[7]
    truth = np.array([[0.9, 0.1, 20.0], [-0.05, 1.1, -8.0], [1e-5, 2e-5, 1.0]])  # original 0 -> original 1
    m0, m1 = b0.level_frame.matrix(), b1.level_frame.matrix()
    level_h = m1 @ truth @ np.linalg.inv(m0)
    xy_orig = np.array([[300.0, 200.0], [320.0, 260.0]])
    xy0 = b0.level_frame.from_original(xy_orig)
    p = np.c_[xy_orig, np.ones(2)] @ truth.T
    xy1 = b1.level_frame.from_original(p[:, :2] / p[:, 2:])
    bpm = BlockPairMatches(np.array([[5, 7]]), level_h[None], np.array([0.3]), np.zeros(2, np.int64), xy0, xy1,
                           np.array([2.0, 2.0]), np.array([3.0, 3.0]), np.array([0.1, 0.2]))
    table, h, side = block_planes_to_original(bpm, blocks0, blocks1)
    np.testing.assert_allclose(h[0] / h[0][2, 2], truth, atol=1e-9)
    np.testing.assert_allclose(table.xy0, xy_orig, atol=1e-9)
    back = np.linalg.inv(m0)[:2, :2]  # level px -> original px
    assert table.angle0[0] == pytest.approx(math.atan2(back[1, 0], back[0, 0]))
    assert table.scale0[0] == pytest.approx(2.0 * math.sqrt(abs(np.linalg.det(back))))
    assert side[0] == 1.0


def test_a_plain_level_keeps_upright_patches_upright():
    config = BlockConfig()
    blocks = make_blocks(480, 640, config)
    b = blocks[3]
    bpm = BlockPairMatches(np.array([[3, 3]]), np.eye(3)[None], np.array([0.0]), np.zeros(1, np.int64),
                           np.array([[50.0, 60.0]]), np.array([[50.0, 60.0]]), np.array([2.0]), np.array([2.0]),
                           np.array([0.1]))
    table, h, _ = block_planes_to_original(bpm, blocks, blocks)
    assert table.angle0[0] == 0.0
    assert table.scale0[0] == pytest.approx(2.0 / math.sqrt(b.fx * b.fy))
    np.testing.assert_allclose(h[0] / h[0][2, 2], np.eye(3), atol=1e-12)


def test_view_is_hashable_and_part_of_a_block_repr():
    view = view_geometry((64, 48), 2.0, 0.0)
    assert isinstance(hash(view), int) and isinstance(view, View)
    assert "tilt=2.0" in repr(make_view_blocks(48, 64, view)[0])


def test_joined_block_planes_keep_each_planes_matches_and_add_the_counts():
    from slime_match.slime.block_planes import BlockPlanes
    from slime_match.slime.match_table import MatchTable, deduplicate

    def planes(n_planes: int, start: float, blocks: int) -> BlockPlanes:
        rows = 3 * n_planes
        xy = start + np.arange(rows * 2, dtype=float).reshape(rows, 2)
        source = np.repeat(np.arange(n_planes), 3)
        raw = MatchTable(xy, xy + 1, np.zeros(rows), np.zeros(rows), np.ones(rows), np.ones(rows), np.ones(rows),
                         source, np.arange(rows, dtype=float))
        level = BlockPairMatches(np.c_[np.arange(n_planes), np.zeros(n_planes, int)] % blocks,
                                 np.tile(np.eye(3), (n_planes, 1, 1)), np.zeros(n_planes), source, xy, xy + 1,
                                 np.ones(rows), np.ones(rows), np.arange(rows, dtype=float))
        return BlockPlanes(level, raw, deduplicate(raw)[0], np.tile(np.eye(3), (n_planes, 1, 1)), np.ones(n_planes),
                           {"block_pairs": 10 * n_planes, "block_planes": n_planes})

    first, second = planes(2, 0.0, 4), planes(3, 1000.0, 5)
    second.raw.xy0[0] = first.raw.xy0[0]  # one exact duplicate across the two: merged in the table
    second.raw.xy1[0] = first.raw.xy1[0]
    joined = first.joined(second, 4)
    assert len(joined.H) == 5 and len(joined.side) == 5
    np.testing.assert_array_equal(joined.raw.source, [0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4])
    np.testing.assert_array_equal(joined.level_matches.pairs, [[0, 0], [1, 0], [4, 0], [5, 0], [6, 0]])
    in_image_1 = first.joined(second, 0, 7)  # a simulated view of image 1: its blocks numbered after image 1's
    np.testing.assert_array_equal(in_image_1.level_matches.pairs, [[0, 0], [1, 0], [0, 7], [1, 7], [2, 7]])
    np.testing.assert_array_equal(joined.level_matches.match_pair[6:], [2, 2, 2, 3, 3, 3, 4, 4, 4])
    assert len(joined.table) == 14 and joined.table.weight.sum() == 15
    assert joined.counts == {"block_pairs": 50, "block_planes": 5, "block_matches": 15, "block_matches_unique": 14}
