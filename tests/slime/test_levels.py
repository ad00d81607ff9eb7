"""Slime block levels: one detection per scale, per block (the paper's prototype), or per block with the shared
keypoints of overlapping blocks merged and described once."""

import copy

import cv2
import numpy as np
import pytest
import torch

from slime_match._runtime.forking import torch_threads
from slime_match.config import make_config
from slime_match.errors import ConfigError
from slime_match.features.image_ops import resize_lanczos
from slime_match.io import load_image
from slime_match.pipelines import BaseConfig, make_base_pipeline
from slime_match.slime.blocks import make_blocks, make_tiles, points_in_blocks
from slime_match.slime.fixed_descriptors import FixedDescriptors
from slime_match.slime.jobs import piece_size
from slime_match.slime.levels import (
    LevelRequest,
    _detected_keypoints,
    _Detection,
    build_levels,
    build_levels_many,
    merge_keypoints,
)

from .helpers import WEIGHT_FREE, nearest, squares


def test_per_block_levels_one_per_block_with_core_keypoints(levels):
    _, blocks, _, shared, per_block = levels
    assert len(shared) == 1 and shared[0].blocks == [0, 1]
    assert [lv.blocks for lv in per_block] == [[0], [1]]
    assert blocks[1].box[0] > 0 and blocks[0].box[1] < 0  # both origin signs are exercised
    for lv, block in zip(per_block, blocks):
        assert lv.origin == (float(block.box[0]), float(block.box[1]))
        assert np.array_equal(lv.members[0], np.arange(len(lv.features)))
        inside = points_in_blocks(block.level_frame.to_original(lv.features.xy.numpy()), [block]).toarray()[0]
        assert len(lv.features) > 20 and inside.all()


def test_square_corners_found_at_the_same_scaled_positions_by_both_modes(levels):
    _, blocks, corners, shared, per_block = levels
    scaled = blocks[0].level_frame.from_original(corners)
    d_shared, i_shared = nearest(scaled, shared[0].features.xy.numpy())
    xy_block = np.concatenate([lv.features.xy.numpy() for lv in per_block])
    d_block, i_block = nearest(scaled, xy_block)
    assert d_shared.max() < 2.0 and d_block.max() < 2.0, (d_shared.max(), d_block.max())
    gap = np.linalg.norm(shared[0].features.xy.numpy()[i_shared] - xy_block[i_block], axis=1)
    assert gap.max() < 1.0, gap.max()
    # shape frames move with the centres
    for lv in per_block:
        assert torch.equal(lv.features.shape_laf[:, :, 2], lv.features.laf[:, :, 2])


def test_merged_levels_describe_the_blocks_own_keypoints_once(levels):
    """Merged detection: each block keeps the keypoints its own crop detected (as with per-block detection),
    the ones both blocks found are one keypoint, and all are described on the whole scaled image."""
    pipeline, blocks, _, shared, per_block = levels
    image, _ = squares()
    merged = build_levels(pipeline, image, blocks, detection="merged")
    assert len(merged) == 1 and merged[0].blocks == [0, 1] and merged[0].origin == (0.0, 0.0)
    lv = merged[0]
    xy = lv.features.xy.numpy()
    for k, own in enumerate(per_block):
        d, _ = nearest(own.features.xy.numpy(), xy[lv.members[k]])
        assert len(lv.members[k]) == len(own.features) and d.max() <= 1.0 + 1e-6
    both = len(per_block[0].features) + len(per_block[1].features)
    assert len(np.intersect1d(*lv.members)) > 0 and len(lv.features) < both
    assert len(lv.features) == len(np.union1d(*lv.members))
    # described on the whole scaled image: the whole-image detection's descriptors where the keypoints
    # coincide (the crops' own detector normalisation moves them by hundredths of a pixel)
    d, j = nearest(xy, shared[0].features.xy.numpy())
    same = d < 0.1
    assert same.mean() > 0.5
    cosine = (lv.features.descriptors[torch.from_numpy(same)] * shared[0].features.descriptors[j[same]]).sum(dim=1)
    assert cosine.min() > 0.99


def test_merge_keypoints_keeps_the_strongest_of_each_group_per_level():
    def part(rows):
        rows = np.array(rows, np.float32)
        return (rows[:, :2], np.repeat(np.eye(2, dtype=np.float32)[None], len(rows), 0), rows[:, 2],
                rows[:, 3].astype(np.int64))

    a = part([[10.0, 10.0, 1.0, 0], [50.0, 50.0, 2.0, 1], [30.0, 30.0, 0.5, 0]])
    b = part([[10.6, 9.2, 3.0, 0], [50.3, 50.0, 4.0, 2], [80.0, 5.0, 1.0, 0]])
    keypoints, members = merge_keypoints([a, b], radius=1.0)
    # groups: {a0, b0} (b0 stronger), a1, a2, b1 (level 2: not a1's group), b2; in decreasing response
    np.testing.assert_allclose(keypoints.xy.numpy(), [[50.3, 50.0], [10.6, 9.2], [50.0, 50.0], [80.0, 5.0],
                                                      [30.0, 30.0]], atol=1e-6)
    assert keypoints.level.tolist() == [2, 0, 1, 0, 0]
    assert [m.tolist() for m in members] == [[1, 2, 4], [0, 1, 3]]
    far = merge_keypoints([a, b], radius=0.5)[0]
    assert len(far) == 6


@pytest.mark.parametrize("options", [{"descriptor": "tfeat"}, WEIGHT_FREE], ids=["networks", "weight-free"])
def test_sets_described_in_pieces_equal_sets_described_whole(pair, options):
    """Merged and "scale" levels (the tiles' regions) and fixed-orientation descriptors spread over 3 workers in
    pieces of the networks' batch (256 keypoints): the features of one process, bit for bit."""
    images = [cv2.resize(load_image(path), (320, 240), interpolation=cv2.INTER_AREA) for path in pair]
    pipeline = make_base_pipeline(BaseConfig(**options))
    blocks = [b for b in make_blocks(240, 320) if b.scale_index < 2]
    requests = [LevelRequest(image, blocks, detection="merged") for image in images]
    requests.append(LevelRequest(images[1], make_tiles(240, 320), regions_only=True, detection="scale"))
    runs = []
    for workers in (1, 3):
        levels = [lv for found in build_levels_many(pipeline, requests, workers) for lv in found]
        wanted = [(lv, {b: np.arange(0, len(lv.features), 1 + b % 3) for b in (0, 5, 11)}) for lv in levels]
        fixed = FixedDescriptors(pipeline, 16, workers)
        fixed.compute(wanted)
        runs.append([(lv.features, *(fixed.features(lv, index, b).descriptors for b, index in bins.items()))
                     for lv, bins in wanted])
    total = sum(len(lv.features) for lv, _ in wanted)
    assert max(len(lv.features) for lv, _ in wanted) > piece_size(total, pipeline.describe_batch(), 3)  # split
    for (one, *fixed_one), (three, *fixed_three) in zip(*runs, strict=True):
        for name in ("laf", "descriptors", "response", "shape_laf"):
            assert torch.equal(getattr(one, name), getattr(three, name)), name
        assert all(torch.equal(a, b) for a, b in zip(fixed_one, fixed_three, strict=True))


def test_forked_detections_equal_one_process(levels):
    """Shared and per-block requests of two images (blocks and tiles' regions) detected by 1 or 2 workers:
    the same levels, in request order, scales and blocks in order."""
    pipeline, blocks, _, _, _ = levels
    image, _ = squares()
    requests = [LevelRequest(image, blocks), LevelRequest(image[::-1].copy(), blocks, detection="block"),
                LevelRequest(image, blocks, regions_only=True), LevelRequest(image, blocks, detection="merged")]
    one, two = (build_levels_many(pipeline, requests, workers) for workers in (1, 2))
    assert [[lv.blocks for lv in r] for r in two] == [[[0, 1]], [[0], [1]], [[0, 1]], [[0, 1]]]
    assert two[2][0].features.descriptors.shape[1] == 0 and two[0][0].features.descriptors.shape[1] > 0
    flat = ([lv for r in levels_of for lv in r] for levels_of in (one, two))
    for a, b in zip(*flat, strict=True):
        assert a.origin == b.origin and all(np.array_equal(x, y) for x, y in zip(a.members, b.members, strict=True))
        for name in ("laf", "descriptors", "response", "shape_laf"):
            assert torch.equal(getattr(a.features, name), getattr(b.features, name)), name


def test_merged_detection_of_a_cuda_pipeline_runs_on_the_cpu_in_the_workers(levels):
    """With workers, a CUDA pipeline's block crops are detected on the CPU in forked processes: the keypoints of
    a CPU pipeline. The stand-in's detector fails unless asked for the CPU, so it shows where each crop ran."""
    pipeline, blocks, _, _, _ = levels
    image, _ = squares()
    requests = [LevelRequest(image, blocks, detection="merged")]
    detections = [_Detection(0, [0, 1], resize_lanczos(image, blocks[0].factor), None, None)]
    cuda_like = copy.copy(pipeline)
    cuda_like.device = torch.device("cuda")

    def cpu_only(crop, device=None):
        assert device == torch.device("cpu"), "a crop was detected on the pipeline's device"
        return pipeline.detect_keypoints(crop, device)

    cuda_like.detect_keypoints = cpu_only
    with torch_threads(1):  # as build_levels_many runs it (forked workers run single-threaded torch)
        (want, want_members), = _detected_keypoints(pipeline, detections, requests, 1)
        (got, got_members), = _detected_keypoints(cuda_like, detections, requests, 2)
    assert len(want) > 20 and torch.equal(want.xy, got.xy) and torch.equal(want.response, got.response)
    assert all(np.array_equal(a, b) for a, b in zip(want_members, got_members, strict=True))


def test_detection_choices_are_validated():
    assert make_config("slime").slime.detection is None  # the base's: merged for Hz+
    assert make_config("slime-rootsift", detection="block").slime.detection == "block"
    with pytest.raises(ConfigError, match="invalid detection 'tiles'"):
        make_config("slime", detection="tiles")
    with pytest.raises(ConfigError, match="tile_detection 'merged' needs the hz\\+ base"):
        make_config("slime-keynet", tile_detection="merged")
    with pytest.raises(ValueError, match="detection must be one of"):
        LevelRequest(np.zeros((8, 8, 3)), [], detection="tile")
