"""Slime block levels: one detection per scale, per block (the paper's prototype), or per block with the shared
keypoints of overlapping blocks merged and described once."""

import copy
import dataclasses

import cv2
import numpy as np
import pytest
import torch
from conftest import DATA, require

from slime_match.config import make_config
from slime_match.errors import ConfigError
from slime_match.eval.metrics import correct_matches_homography
from slime_match.geometry.ransac import HomographyRansacConfig
from slime_match.io import load_image
from slime_match.matcher import Matcher
from slime_match.pipelines import BaseConfig, make_base_pipeline
from slime_match.slime.block_matching import (
    LevelRequest,
    _detected_keypoints,
    _Detection,
    build_levels,
    build_levels_many,
    describe_fixed_bins,
    fixed_features,
    match_block_pairs,
    match_jobs,
    merge_keypoints,
    piece_size,
    pieces_of,
    ransac_batches,
    translate_features,
)
from slime_match.slime.blocks import make_blocks, make_tiles, points_in_blocks, resize_lanczos
from slime_match.slime.forking import fork_map, torch_threads
from slime_match.types import Features

WEIGHT_FREE = {"shape": "baumberg", "orientation": "gradient", "descriptor": "rootsift"}
SIZE = (240, 320)  # (H, W)


def _squares() -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) grey image of bright 20 px squares on a dark ground, and their (4 S, 2) corners in px."""
    h, w = SIZE
    img = np.full((h, w), 0.2, np.float32)
    corners = []
    for y in range(30, 210, 50):
        for x in range(30, 290, 55):
            img[y:y + 20, x:x + 20] = 0.9
            corners += [(x - 0.5, y - 0.5), (x + 19.5, y - 0.5), (x - 0.5, y + 19.5), (x + 19.5, y + 19.5)]
    img = cv2.GaussianBlur(img, (0, 0), 1.0)
    return np.repeat(img[:, :, None], 3, axis=2), np.array(corners)


@pytest.fixture(scope="module")
def levels():
    image, corners = _squares()
    pipeline = make_base_pipeline(BaseConfig(**WEIGHT_FREE))
    blocks = [b for b in make_blocks(*SIZE) if b.scale_index == 0]  # factor 0.8: 256 x 192, two blocks
    shared = build_levels(pipeline, image, blocks)
    per_block = build_levels(pipeline, image, blocks, detection="block")
    return pipeline, blocks, corners, shared, per_block


def _nearest(points: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = np.linalg.norm(points[:, None] - xy[None], axis=2)
    return d.min(axis=1), d.argmin(axis=1)


def test_per_block_levels_one_per_block_with_core_keypoints(levels):
    _, blocks, _, shared, per_block = levels
    assert len(shared) == 1 and shared[0].blocks == [0, 1]
    assert [lv.blocks for lv in per_block] == [[0], [1]]
    assert blocks[1].box[0] > 0 and blocks[0].box[1] < 0  # both origin signs are exercised
    for lv, block in zip(per_block, blocks):
        assert lv.origin == (float(block.box[0]), float(block.box[1]))
        assert np.array_equal(lv.members[0], np.arange(len(lv.features)))
        inside = points_in_blocks(block.to_original(lv.features.xy.numpy()), [block]).toarray()[0]
        assert len(lv.features) > 20 and inside.all()


def test_square_corners_found_at_the_same_scaled_positions_by_both_modes(levels):
    _, blocks, corners, shared, per_block = levels
    scaled = blocks[0].to_scaled(corners)
    d_shared, i_shared = _nearest(scaled, shared[0].features.xy.numpy())
    xy_block = np.concatenate([lv.features.xy.numpy() for lv in per_block])
    d_block, i_block = _nearest(scaled, xy_block)
    assert d_shared.max() < 2.0 and d_block.max() < 2.0, (d_shared.max(), d_block.max())
    gap = np.linalg.norm(shared[0].features.xy.numpy()[i_shared] - xy_block[i_block], axis=1)
    assert gap.max() < 1.0, gap.max()
    # shape frames move with the centres
    for lv in per_block:
        assert torch.equal(lv.features.shape_laf[:, :, 2], lv.features.laf[:, :, 2])


def test_fixed_orientation_descriptors_use_the_crop_context(levels):
    """Re-described per-block regions equal the shared ones: the crop-local frames sample the same pixels."""
    pipeline, _, _, shared, per_block = levels
    for k, lv in enumerate(per_block):
        own = shared[0].members[k]
        dist, j = _nearest(lv.features.xy.numpy(), shared[0].features.xy.numpy()[own])
        same = np.nonzero(dist < 0.3)[0]
        assert len(same) > 0.8 * len(lv.features)
        describe_fixed_bins(pipeline, [(lv, {3: same}), (shared[0], {3: own[j[same]]})], 16)
        ours = fixed_features(lv, same, 3, 16).descriptors
        ref = fixed_features(shared[0], own[j[same]], 3, 16).descriptors
        cosine = (ours * ref).sum(dim=1)
        assert cosine.median() > 0.99 and (cosine > 0.8).float().mean() > 0.9, cosine.median()
        # without the origin shift the same call samples other pixels: the check above can fail
        wrong = pipeline.describe_fixed(lv.context, lv.features.subset(torch.from_numpy(same)), 3 * 2 * np.pi / 16)
        assert (wrong.descriptors * ref).sum(dim=1).median() < 0.9


def test_fixed_features_of_a_block_without_keypoints_are_empty(levels):
    """A block or tile without keypoints asks for a bin that nothing else needs: describe_fixed_bins has nothing
    to describe, and its fixed features are empty instead of a missing cache entry."""
    pipeline, _, _, shared, _ = levels
    nothing = np.zeros(0, np.int64)
    describe_fixed_bins(pipeline, [(shared[0], {11: nothing})], 16)
    assert 11 not in shared[0].fixed
    empty = fixed_features(shared[0], nothing, 11, 16)
    assert len(empty) == 0 and empty.descriptors.shape[1] == shared[0].features.descriptors.shape[1]


def test_merged_levels_describe_the_blocks_own_keypoints_once(levels):
    """Merged detection: each block keeps the keypoints its own crop detected (as with per-block detection),
    the ones both blocks found are one keypoint, and all are described on the whole scaled image."""
    pipeline, blocks, _, shared, per_block = levels
    image, _ = _squares()
    merged = build_levels(pipeline, image, blocks, detection="merged")
    assert len(merged) == 1 and merged[0].blocks == [0, 1] and merged[0].origin == (0.0, 0.0)
    lv = merged[0]
    xy = lv.features.xy.numpy()
    for k, own in enumerate(per_block):
        d, _ = _nearest(own.features.xy.numpy(), xy[lv.members[k]])
        assert len(lv.members[k]) == len(own.features) and d.max() <= 1.0 + 1e-6
    both = len(per_block[0].features) + len(per_block[1].features)
    assert len(np.intersect1d(*lv.members)) > 0 and len(lv.features) < both
    assert len(lv.features) == len(np.union1d(*lv.members))
    # described on the whole scaled image: the whole-image detection's descriptors where the keypoints
    # coincide (the crops' own detector normalisation moves them by hundredths of a pixel)
    d, j = _nearest(xy, shared[0].features.xy.numpy())
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


def test_fork_map_and_forked_descriptors_equal_one_process(levels):
    assert fork_map(lambda k: k * k, 11, 2) == [k * k for k in range(11)]
    pipeline, _, _, shared, _ = levels
    out = []
    for workers in (1, 2):
        fresh = [dataclasses.replace(lv, fixed={}) for lv in shared]
        wanted = [(lv, {b: np.arange(0, len(lv.features), 1 + b) for b in (0, 3, 5)}) for lv in fresh]
        describe_fixed_bins(pipeline, wanted, 16, workers)
        out.append([fixed_features(lv, index, b, 16).descriptors for lv, bins in wanted for b, index in bins.items()])
    assert all(torch.equal(a, b) for a, b in zip(*out, strict=True))


def test_pieces_cover_the_set_at_multiples_of_the_batch():
    assert piece_size(10_000, 256, 1) == 10_000 and piece_size(10_000, None, 8) == 10_000
    assert piece_size(0, 256, 1) == 1 and piece_size(100, 256, 16) == 256
    assert piece_size(10_000, 256, 2) == 256 * 5  # about a quarter of an even share: 10,000 / 8 = 1250
    for count, size in ((0, 256), (1, 256), (256, 256), (257, 256), (10_000, 1280)):
        pieces = pieces_of(count, size)
        assert [i for piece in pieces for i in range(count)[piece]] == list(range(count))
        assert all(piece.start % size == 0 and piece.stop - piece.start <= size for piece in pieces)
    assert pieces_of(0, 256) == [slice(0, 0)]


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
        describe_fixed_bins(pipeline, wanted, 16, workers)
        runs.append([(lv.features, *(fixed_features(lv, index, b, 16).descriptors for b, index in bins.items()))
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
    image, _ = _squares()
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


def test_match_jobs_of_a_cuda_pipeline_equal_one_process(levels):
    """On CUDA, ``match_jobs`` copies the jobs' features to the CPU before forking: the same matches and
    positions as one process, or forked on the CPU. The CPU pipeline stands in for a CUDA one: its ``device``
    is all that ``match_jobs`` reads to choose."""
    pipeline, blocks, _, shared, per_block = levels
    own = [shared[0].features.subset(torch.from_numpy(m)) for m in shared[0].members]
    jobs = [(own[i], per_block[j].features, blocks[i], blocks[j], None) for i in range(2) for j in range(2)]
    jobs += [(own[0], per_block[0].features, blocks[0], blocks[0], lambda y0, y1: y0[:, 0] < 120), None]
    cuda_like = copy.copy(pipeline)
    cuda_like.device = torch.device("cuda")
    runs = [match_jobs(p, len(jobs), jobs.__getitem__, w) for p, w in ((pipeline, 1), (pipeline, 2), (cuda_like, 2))]
    assert len(runs[0][0][0]) > 15 and len(runs[0][5][0]) == 0
    assert len(runs[0][4][0]) > 0 and not np.array_equal(runs[0][4][0].idx0, runs[0][0][0].idx0)  # filtered
    for other in runs[1:]:
        for (m, xy0, xy1), (n, yy0, yy1) in zip(runs[0], other, strict=True):
            assert np.array_equal(m.idx0, n.idx0) and np.array_equal(m.idx1, n.idx1)
            assert np.array_equal(m.scores, n.scores) and np.array_equal(xy0, yy0) and np.array_equal(xy1, yy1)


def test_merged_detection_of_a_cuda_pipeline_runs_on_the_cpu_in_the_workers(levels):
    """With workers, a CUDA pipeline's block crops are detected on the CPU in forked processes: the keypoints of
    a CPU pipeline. The stand-in's detector fails unless asked for the CPU, so it shows where each crop ran."""
    pipeline, blocks, _, _, _ = levels
    image, _ = _squares()
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


def test_ransac_batches_do_not_depend_on_the_workers():
    """Batches of RANSAC_BATCH problems, each its own seeded batched RANSAC: any number of workers gives the
    same planes, and they find the true homography of every problem with enough inliers."""
    g = np.random.default_rng(2)
    h = np.array([[1.1, 0.05, 10.0], [-0.02, 0.95, -5.0], [1e-4, 0.0, 1.0]])
    problems = []
    for k in range(120):
        x0 = g.uniform(0, 256, (30 + k % 40, 2))
        y = np.c_[x0, np.ones(len(x0))] @ h.T
        x1 = y[:, :2] / y[:, 2:]
        angle = g.uniform(0, 2 * np.pi, len(x0) // 3)
        x1[: len(x0) // 3] += 40 * np.c_[np.cos(angle), np.sin(angle)]  # a third are outliers, 40 px off
        problems.append((x0, x1))
    config = HomographyRansacConfig(threshold=3.0)
    one, two = ransac_batches(problems, config, 0, 1), ransac_batches(problems, config, 0, 2)
    assert len(one) == len(problems)
    for a, b, (x0, _) in zip(one, two, problems, strict=True):
        np.testing.assert_array_equal(a.model, b.model)
        np.testing.assert_array_equal(a.inliers, b.inliers)
        assert a.inliers[len(x0) // 3:].all() and not a.inliers[: len(x0) // 3].any()


def test_translate_features_moves_centres_only():
    laf = torch.tensor([[[2.0, 0.5, 10.0], [0.0, 3.0, 20.0]]])
    f = Features(laf, torch.ones(1, 4), torch.ones(1), laf.clone())
    moved = translate_features(f, (-32.0, 5.0))
    assert torch.equal(moved.xy, torch.tensor([[-22.0, 25.0]]))
    assert torch.equal(moved.shape_laf[:, :, 2], torch.tensor([[-22.0, 25.0]]))
    assert torch.equal(moved.laf[:, :, :2], laf[:, :, :2]) and torch.equal(f.laf, laf)


@pytest.mark.slow
def test_per_block_slime_end_to_end_on_a_real_pair():
    """graf 1 -> 3 at 400 x 300 with per-block detection (about a minute on 2 idle cores)."""
    folder = require(DATA / "oxford_graf")
    a, b = load_image(folder / "img1.png"), load_image(folder / "img3.png")
    s = np.diag([0.5, 0.5, 1.0])
    s[:2, 2] = -0.25  # pixel-centre convention of a 2x downscale
    a, b = (cv2.resize(im, (im.shape[1] // 2, im.shape[0] // 2), interpolation=cv2.INTER_AREA) for im in (a, b))
    h = s @ np.loadtxt(folder / "H1to3p") @ np.linalg.inv(s)
    result = Matcher(make_config("slime", detection="block", **WEIGHT_FREE))(a, b)
    ok = correct_matches_homography(result.keypoints0, result.keypoints1, h)
    assert ok.sum() > 100 and ok.mean() >= 0.9, (int(ok.sum()), ok.mean())
    assert result.summary["config"]["slime"]["detection"] == "block"


def test_detection_choices_are_validated():
    assert make_config("slime").slime.detection is None  # the base's: merged for Hz+
    assert make_config("slime-rootsift", detection="block").slime.detection == "block"
    with pytest.raises(ConfigError, match="invalid detection 'tiles'"):
        make_config("slime", detection="tiles")
    with pytest.raises(ConfigError, match="tile_detection 'merged' needs the hz\\+ base"):
        make_config("slime-keynet", tile_detection="merged")
    with pytest.raises(ValueError, match="detection must be one of"):
        LevelRequest(np.zeros((8, 8, 3)), [], detection="tile")


def test_upright_base_reuses_the_first_run_for_the_orientation_refined_one(monkeypatch):
    """On an upright base, the fixed frames and descriptors at angle 0 are the features' own, bit for bit, so
    Sec. 3.3's re-run of a theta* = 0 pair repeats the first run: its matches are reused (no descriptors, no
    re-match), and the planes equal those of the re-run done in full."""
    image, _ = _squares()
    moved = cv2.warpAffine(image, np.float32([[1, 0, 6], [0, 1, 4]]), SIZE[::-1], borderMode=cv2.BORDER_REFLECT)
    upright = make_base_pipeline(BaseConfig(**{**WEIGHT_FREE, "orientation": "upright"}))
    assert upright.own_frames_upright() and not make_base_pipeline(BaseConfig(**WEIGHT_FREE)).own_frames_upright()
    context = upright.prepare(image)
    own = upright.detect(context)
    fixed = upright.describe_fixed(context, own.subset(torch.arange(3, len(own))), 0.0)
    assert torch.equal(fixed.laf, own.laf[3:]) and torch.equal(fixed.descriptors, own.descriptors[3:])

    blocks = [b for b in make_blocks(*SIZE) if b.scale_index == 0]

    def planes():
        levels0, levels1 = build_levels(upright, image, blocks), build_levels(upright, moved, blocks)
        return match_block_pairs(upright, levels0, levels1, blocks, blocks, HomographyRansacConfig(threshold=15.0))

    reused, counts = planes()
    monkeypatch.setattr(upright, "own_frames_upright", lambda: False)
    full, full_counts = planes()
    assert counts["block_planes"] > 0 and counts["block_pairs_rerun"] == 0
    assert full_counts["block_pairs_rerun"] == full_counts["block_planes_first"] == counts["block_planes_first"]
    for field in dataclasses.fields(full):
        np.testing.assert_array_equal(getattr(reused, field.name), getattr(full, field.name))
