"""Block planes (Secs. 3.2-3.3): block pairs matched and re-matched under fixed orientations, the planes
mapped exactly to original pixels and gathered in one match table."""

import dataclasses

import cv2
import numpy as np
import pytest
import torch

from slime_match.geometry.homography import homography_dlt, project
from slime_match.geometry.ransac import HomographyRansacConfig
from slime_match.pipelines import BaseConfig, make_base_pipeline
from slime_match.slime.block_planes import (
    BlockPairMatches,
    _BlockSide,
    _from_level_pairs,
    block_planes,
    block_planes_to_original,
    level_pair_key,
    match_block_pairs,
)
from slime_match.slime.blocks import make_blocks
from slime_match.slime.fixed_descriptors import FixedDescriptors
from slime_match.slime.levels import build_levels
from slime_match.slime.match_table import deduplicate

from .helpers import SIZE, WEIGHT_FREE, squares


def test_block_planes_map_exactly_to_original_frame():
    blocks0, blocks1 = make_blocks(480, 640), make_blocks(600, 800)
    w0 = next(i for i, b in enumerate(blocks0) if b.scale_index == 2)
    w1 = next(i for i, b in enumerate(blocks1) if b.scale_index == 0)
    h_true = np.array([[0.9, 0.1, 20.0], [-0.05, 1.1, -10.0], [1e-4, 2e-5, 1.0]])
    rng = np.random.default_rng(0)
    x_orig = rng.uniform(50, 400, (30, 2))
    y_orig, _ = project(h_true, x_orig)
    b0, b1 = blocks0[w0], blocks1[w1]
    x_s, y_s = b0.level_frame.from_original(x_orig), b1.level_frame.from_original(y_orig)
    # The block-frame homography that RANSAC would estimate: scaled 0 -> scaled 1.
    h_scaled, _ = homography_dlt(x_s, y_s)
    bpm = BlockPairMatches(np.array([[w0, w1]]), h_scaled[None], np.array([0.3]), np.zeros(30, np.int64), x_s, y_s,
                           np.full(30, 2.0 * b0.factor), np.full(30, 3.0 * b1.factor), np.arange(30.0))
    table, h, side = block_planes_to_original(bpm, blocks0, blocks1)
    assert np.allclose(table.xy0, x_orig, atol=1e-6) and np.allclose(table.xy1, y_orig, atol=1e-6)
    mapped, _ = project(h[0], x_orig)
    assert np.allclose(mapped, y_orig, atol=1e-5)
    assert side.tolist() == [1.0]
    assert np.allclose(table.angle1, 0.3) and np.allclose(table.angle0, 0.0)
    assert np.allclose(table.scale0, 2.0, rtol=1e-2) and np.allclose(table.scale1, 3.0, rtol=1e-2)


def _moved_squares():
    image, _ = squares()
    moved = cv2.warpAffine(image, np.float32([[1, 0, 6], [0, 1, 4]]), SIZE[::-1], borderMode=cv2.BORDER_REFLECT)
    return image, moved


def test_upright_base_reuses_the_first_run_for_the_orientation_refined_one(monkeypatch):
    """On an upright base, the fixed frames and descriptors at angle 0 are the features' own, bit for bit, so
    Sec. 3.3's re-run of a theta* = 0 pair repeats the first run: its matches are reused (no descriptors, no
    re-match), and the planes equal those of the re-run done in full."""
    image, moved = _moved_squares()
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


def test_block_planes_gathers_the_refined_planes_in_original_pixels(levels):
    """``block_planes`` is ``match_block_pairs``, ``block_planes_to_original`` and ``deduplicate`` in a row:
    the same planes, raw and deduplicated tables, their counts, and their ``--save-stages`` arrays."""
    pipeline, blocks, _, _, _ = levels
    image, moved = _moved_squares()
    levels0, levels1 = build_levels(pipeline, image, blocks), build_levels(pipeline, moved, blocks)
    ransac = HomographyRansacConfig(threshold=15.0)
    planes = block_planes(pipeline, levels0, levels1, blocks, blocks, ransac)
    matches, counts = match_block_pairs(pipeline, levels0, levels1, blocks, blocks, ransac)
    raw, h, side = block_planes_to_original(matches, blocks, blocks)
    table, _ = deduplicate(raw)
    assert counts["block_planes"] > 0 and len(raw) > len(table) > 0  # overlapping blocks: duplicate matches
    for field in dataclasses.fields(matches):
        np.testing.assert_array_equal(getattr(planes.level_matches, field.name), getattr(matches, field.name))
    for field in dataclasses.fields(raw):
        np.testing.assert_array_equal(getattr(planes.raw, field.name), getattr(raw, field.name))
        np.testing.assert_array_equal(getattr(planes.table, field.name), getattr(table, field.name))
    np.testing.assert_array_equal(planes.H, h)
    np.testing.assert_array_equal(planes.side, side)
    assert planes.counts == {**counts, "block_matches": len(raw), "block_matches_unique": len(table)}
    arrays = planes.arrays()
    assert set(arrays) == {"planes_pairs", "planes_H", "planes_theta", "block_matches_xy0",
                           "block_matches_xy1", "block_matches_plane", "table_xy0", "table_xy1",
                           "table_weight"}
    np.testing.assert_array_equal(arrays["planes_pairs"], matches.pairs)
    np.testing.assert_array_equal(arrays["block_matches_plane"], raw.source)
    np.testing.assert_array_equal(arrays["table_weight"], table.weight)
    assert arrays["table_weight"].sum() == len(raw)


def test_planes_found_with_the_images_exchanged_turn_round_to_image_0_to_image_1(levels):
    """A simulated view of image 1 takes image 0's part in Secs. 3.2-3.3; ``swapped`` turns its planes round:
    homographies inverted, keypoints, orientations and scales exchanged, the same rows. Exchanged back, the
    planes are the ones found."""
    pipeline, blocks, _, _, _ = levels
    image, moved = _moved_squares()  # moved = image shifted by (6, 4) px
    levels0, levels1 = build_levels(pipeline, image, blocks), build_levels(pipeline, moved, blocks)
    found = block_planes(pipeline, levels1, levels0, blocks, blocks, HomographyRansacConfig(threshold=15.0))
    planes = found.swapped()
    assert len(planes.H) == len(found.H) > 0
    np.testing.assert_array_equal(planes.level_matches.pairs, found.level_matches.pairs[:, ::-1])
    np.testing.assert_array_equal(planes.raw.xy0, found.raw.xy1)
    np.testing.assert_array_equal(planes.table.angle1, found.table.angle0)
    np.testing.assert_array_equal(planes.raw.scale0, found.raw.scale1)
    np.testing.assert_allclose(planes.H @ found.H, np.broadcast_to(np.eye(3), found.H.shape), atol=1e-8)
    for plane in range(len(planes.H)):  # each homography maps its plane's image-0 keypoints to image 1's
        rows = planes.raw.source == plane
        mapped, _ = project(planes.H[plane], planes.raw.xy0[rows])
        assert np.median(np.linalg.norm(mapped - planes.raw.xy1[rows], axis=1)) < 15.0  # the RANSAC's t_perp
    np.testing.assert_allclose(np.cos(planes.table.rho), np.cos(found.table.rho))  # the turn, the other way
    np.testing.assert_allclose(np.sin(planes.table.rho), -np.sin(found.table.rho), atol=1e-12)
    assert np.all(planes.side == 1.0)
    back = planes.swapped()
    np.testing.assert_allclose(back.H, found.H, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(back.level_matches.xy0, found.level_matches.xy0)
    np.testing.assert_allclose(np.cos(back.level_matches.theta), np.cos(found.level_matches.theta), atol=1e-12)
    np.testing.assert_array_equal(back.table.xy1, found.table.xy1)


def test_a_shared_fixed_descriptors_describes_image_1_once(levels, monkeypatch):
    """The plain blocks and the simulated views pair image 0's levels with the same image-1 levels: with one
    ``FixedDescriptors`` for both calls, the second describes none of image 1's features again and finds the
    same planes as with a fresh one."""
    pipeline, blocks, _, _, _ = levels
    image, moved = _moved_squares()
    levels1 = build_levels(pipeline, moved, blocks)
    ransac = HomographyRansacConfig(threshold=15.0)
    shared = FixedDescriptors(pipeline, 16)
    first = block_planes(pipeline, build_levels(pipeline, image, blocks), levels1, blocks, blocks, ransac,
                         fixed=shared)
    described = []  # the contexts (images) of every fixed-orientation description
    describe = pipeline.describe_fixed
    monkeypatch.setattr(pipeline, "describe_fixed",
                        lambda context, *rest: described.append(context) or describe(context, *rest))
    levels0 = build_levels(pipeline, image, blocks)  # new level objects: as a view's are
    again = block_planes(pipeline, levels0, levels1, blocks, blocks, ransac, fixed=shared)
    second = list(described)
    fresh = block_planes(pipeline, levels0, levels1, blocks, blocks, ransac)
    assert len(first.H) > 0 and first.counts["block_pairs_rerun"] > 0
    image1 = {id(level.context) for level in levels1}
    assert second and not image1 & {id(context) for context in second}  # image 0's only
    assert image1 & {id(context) for context in described[len(second):]}  # a fresh one describes image 1 too
    for field in dataclasses.fields(fresh.level_matches):
        np.testing.assert_array_equal(getattr(again.level_matches, field.name),
                                      getattr(fresh.level_matches, field.name))


def test_a_plane_counts_distinct_keypoints():
    """Four matches of one keypoint of image 0 to four of image 1 are one keypoint there, not four."""
    from slime_match.slime.block_planes import distinct_keypoints
    from slime_match.types import Matches

    matches = Matches(np.array([0, 0, 0, 0, 1]), np.array([0, 1, 2, 3, 4]), np.zeros(5))
    assert distinct_keypoints(matches) == 2
    assert distinct_keypoints(Matches.empty()) == 0


def test_levels_matching_shares_each_level_pairs_matches_out_to_its_block_pairs(levels, monkeypatch):
    """``matching="levels"``: the base pipeline matches the two whole levels once, and each block pair gets,
    in order, exactly those matches whose two ends lie in its blocks' cores, indexed into the blocks' own
    features; planes come out of them as from per-pair matching."""
    pipeline, blocks, _, _, _ = levels
    image, moved = _moved_squares()
    levels0, levels1 = build_levels(pipeline, image, blocks), build_levels(pipeline, moved, blocks)
    (level0,), (level1,) = levels0, levels1
    whole = pipeline.match(level0.features, level1.features, level0.size, level1.size)
    fixed = FixedDescriptors(pipeline, 16)
    side0, side1 = _BlockSide(levels0, blocks, fixed), _BlockSide(levels1, blocks, fixed)
    pairs = [(w0, w1) for w0 in range(len(blocks)) for w1 in range(len(blocks))]
    shared = _from_level_pairs(pipeline, side0, side1, pairs, workers=1)
    assert sum(len(m) for m, _, _ in shared) > 0
    for (w0, w1), (m, xy0, xy1) in zip(pairs, shared):
        inside = np.isin(whole.idx0, level0.members[w0]) & np.isin(whole.idx1, level1.members[w1])
        np.testing.assert_array_equal(m.scores, whole.scores[inside])
        np.testing.assert_array_equal(xy0, level0.features.xy.numpy()[whole.idx0[inside]])
        np.testing.assert_array_equal(xy1, level1.features.xy.numpy()[whole.idx1[inside]])
        np.testing.assert_array_equal(side0.own(w0).xy.numpy()[m.idx0], xy0)
        np.testing.assert_array_equal(side1.own(w1).xy.numpy()[m.idx1], xy1)
    ransac = HomographyRansacConfig(threshold=15.0)
    _, counts = match_block_pairs(pipeline, levels0, levels1, blocks, blocks, ransac, matching="levels")
    assert counts["block_pairs"] == len(pairs) and counts["block_planes"] > 0
    # a level pair matched before (a view's probe) is not matched again: its matches are the ones given
    given = whole.subset(np.arange(len(whole)) % 2 == 0)
    monkeypatch.setattr(pipeline, "match", lambda *args, **kwargs: pytest.fail("the level pair was matched again"))
    again = _from_level_pairs(pipeline, side0, side1, pairs, 1, {level_pair_key(level0, level1): given})
    for (w0, w1), (m, xy0, _) in zip(pairs, again):
        inside = np.isin(given.idx0, level0.members[w0]) & np.isin(given.idx1, level1.members[w1])
        np.testing.assert_array_equal(xy0, level0.features.xy.numpy()[given.idx0[inside]])
