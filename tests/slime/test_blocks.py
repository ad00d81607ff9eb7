"""Blocks and tiles: grid geometry, coordinate maps, core membership."""

import cv2
import numpy as np
import pytest

from slime_match.errors import ConfigError
from slime_match.slime.blocks import (
    BlockConfig,
    make_blocks,
    make_tiles,
    points_in_blocks,
)


def _grid_shape(blocks, scale_index):
    sel = [b for b in blocks if b.scale_index == scale_index]
    return max(b.row for b in sel) + 1, max(b.col for b in sel) + 1


@pytest.mark.parametrize(
    "height,width,shapes,n_tiles",
    [(480, 640, [(1, 2), (2, 3), (3, 4)], 12), (640, 800, [(1, 2), (2, 3), (3, 4)], 20)],
)
def test_worked_examples(height, width, shapes, n_tiles):
    blocks = make_blocks(height, width)
    assert [_grid_shape(blocks, k) for k in range(3)] == shapes
    assert len(blocks) == sum(r * c for r, c in shapes)
    assert len(make_tiles(height, width)) == n_tiles
    # shorter side of scale s is 192 + 128 (s - 1) px, exactly s blocks along it
    for k, s in enumerate((1, 2, 3)):
        b = next(b for b in blocks if b.scale_index == k)
        assert min(b.scaled_size) == 192 + 128 * (s - 1)


@pytest.mark.parametrize("height,width", [(480, 640), (640, 800), (1080, 1920), (333, 1001), (700, 500)])
def test_block_geometry_rules(height, width):
    cfg = BlockConfig()
    for blocks in (make_blocks(height, width, cfg), make_tiles(height, width, cfg)):
        for k in {b.scale_index for b in blocks}:
            sel = [b for b in blocks if b.scale_index == k]
            w_s, h_s = sel[0].scaled_size
            for axis, length in ((0, w_s), (1, h_s)):
                cores = sorted({(b.core[axis], b.core[axis + 2]) for b in sel})
                assert cores[0][0] == 0 and cores[-1][1] == length  # cores cover the axis end to end
                starts = np.array([c[0] for c in cores])
                steps = np.diff(starts)
                assert np.all(np.abs(steps - 128) <= 24 + 0.5)  # stride adjusted within 128 +- 24
                assert all(b - a <= 192 for a, b in cores)
                assert min(b - a for a, b in cores) >= 64  # no sliver
            for b in sel:
                h, w = b.shape
                assert h <= 256 and w <= 256
                assert b.box[0] == b.core[0] - 32 and b.box[1] == b.core[1] - 32


def test_coordinate_maps_roundtrip_and_crop():
    blocks = make_blocks(480, 640)
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 480, (50, 2))
    for b in blocks:
        np.testing.assert_allclose(b.frame.to_original(b.frame.from_original(xy)), xy, atol=1e-9)
    b = blocks[1]  # scale 1 (factor 0.4), second column
    # pixel-centre alignment of the resize: original pixel centre 0 maps to -0.3 at factor 0.4
    np.testing.assert_allclose(b.level_frame.from_original(np.array([[0.0, 0.0]])), [[-0.3, -0.3]])
    img = rng.random((192, 256)).astype(np.float32)
    crop = b.crop(img)
    assert crop.shape == b.shape
    assert np.all(crop[:32] == 0) and np.all(crop[224:] == 0)  # padding outside the image
    x0 = b.box[0]
    np.testing.assert_array_equal(crop[32:224, : 256 - x0], img[:, x0:])
    assert np.all(crop[:, 256 - x0 :] == 0)


def test_points_in_blocks_membership():
    tiles = make_tiles(480, 640)
    xy = np.array([[10.0, 10.0], [150.0, 100.0], [639.4, 479.4], [-0.4, 200.0], [300.0, 300.0]])
    mem = points_in_blocks(xy, tiles).toarray()
    assert mem.shape == (len(tiles), len(xy))
    assert mem.sum(axis=0).min() >= 1  # every image point is in some core
    # (150, 100) is in the overlap of the first two columns (cores [0,192) and [149,341)) of row 0
    assert {(tiles[i].row, tiles[i].col) for i in np.nonzero(mem[:, 1])[0]} == {(0, 0), (0, 1)}
    assert mem[:, 0].sum() == 1 and mem[0, 0]
    assert mem[len(tiles) - 1, 2]  # bottom-right corner
    # scaled blocks: membership must agree with the block's own core test in scaled coordinates
    blocks = make_blocks(480, 640)
    pts = np.random.default_rng(1).uniform([0, 0], [640, 480], (2000, 2))
    mem = points_in_blocks(pts, blocks).toarray()
    for i, b in enumerate(blocks):
        np.testing.assert_array_equal(mem[i], b.in_core_local(b.frame.from_original(pts)))
    for k in range(3):  # each scale covers the whole image
        rows = [i for i, b in enumerate(blocks) if b.scale_index == k]
        assert mem[rows].any(axis=0).all()


def test_bad_config():
    with pytest.raises(ConfigError):
        BlockConfig(padding=200)
    with pytest.raises(ConfigError):
        BlockConfig(scales=(0, 1))
    with pytest.raises(ConfigError, match="distinct"):
        BlockConfig(scales=(1, 2, 1))


def test_off_border_marks_points_near_the_image_border_of_a_crop():
    """A corner block's crop starts 32 px before the image: its points within 2 px of the image's first row or
    column, or of its last ones, are on the border (where the zero-filled padding makes an edge)."""
    block = make_blocks(480, 640)[0]  # scale 1, first column: box (-32, -32, 224, 224) of a 256 x 192 image
    assert block.box[:2] == (-32, -32) and block.scaled_size == (256, 192)
    local = np.array([[32.0, 40.0], [33.4, 40.0], [33.6, 40.0], [100.0, 32.0 + 190.0], [100.0, 32.0 + 189.0]])
    assert block.off_border_local(local).tolist() == [False, False, True, False, True]
    assert block.off_border_local(local, margin=0.0).tolist() == [True] * 5


def test_block_detection_drops_the_crops_border_keypoints():
    """HarrisZ+ fires on the edge between a crop's zero-filled padding and the image; the blocks keep none of
    its keypoints within 2 px of the image border (the whole-image detection keeps its own)."""
    import torch

    from slime_match.features.harrisz import detect_harrisz

    rng = np.random.default_rng(3)
    texture = cv2.GaussianBlur(rng.random((192, 256)).astype(np.float32), (0, 0), 3) * 0.5 + 0.25
    block = make_blocks(480, 640)[0]
    local = detect_harrisz(torch.from_numpy(block.crop(texture))[None]).xy.numpy()
    on_edge = ~block.off_border_local(local) & block.in_core_local(local)
    assert on_edge.sum() >= 3  # the artificial edge's keypoints, which the blocks drop
