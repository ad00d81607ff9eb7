"""Slime end to end: ``Matcher`` runs of ``run_slime`` on real pairs with exact GT (original-pixel frames,
block scale options, empty results), and the layout of Sec. 3.1."""

import cv2
import numpy as np
import pytest
from conftest import DATA, require

from slime_match.config import make_config
from slime_match.errors import ConfigError, ImageError
from slime_match.eval.datasets import rotate_image
from slime_match.eval.metrics import correct_matches_homography, coverage, valid_area_homography
from slime_match.geometry.homography import project
from slime_match.io import load_image
from slime_match.matcher import Matcher
from slime_match.slime.blocks import BlockConfig, make_blocks, make_tiles
from slime_match.slime.pipeline import Layout

from .helpers import WEIGHT_FREE


@pytest.fixture(scope="module")
def graf_small():
    """graf 1 -> 3 at half resolution with its exact GT homography."""
    folder = require(DATA / "oxford_graf")
    a, b = load_image(folder / "img1.png"), load_image(folder / "img3.png")
    h = np.loadtxt(folder / "H1to3p")
    s = np.diag([0.5, 0.5, 1.0])
    s[:2, 2] = -0.25  # pixel-centre convention of a 2x downscale
    small = [cv2.resize(im, (im.shape[1] // 2, im.shape[0] // 2), interpolation=cv2.INTER_AREA) for im in (a, b)]
    return small[0], small[1], s @ h @ np.linalg.inv(s)


def test_slime_weight_free_beats_its_base_on_a_real_pair(graf_small):
    a, b, h = graf_small
    slime = Matcher(make_config("slime", **WEIGHT_FREE))(a, b)
    base = Matcher(make_config("hz+", **WEIGHT_FREE))(a, b)
    ok_slime = correct_matches_homography(slime.keypoints0, slime.keypoints1, h)
    ok_base = correct_matches_homography(base.keypoints0, base.keypoints1, h)
    assert ok_slime.mean() >= 0.9, ok_slime.mean()
    assert ok_slime.sum() > ok_base.sum()
    counts = slime.summary["counts"]
    assert counts["block_planes"] > 0 and counts["ftheta_sets"] > 0 and counts["final"] == len(slime)


def test_plane_tile_test_covers_more_of_a_real_pair():
    """HPatches v_churchill 1 -> 3, weight-free: keeping the tile matches that fit their tile pair's plane
    (``tile_test="plane"``) instead of those near a F^theta match covers more at no cost in precision."""
    folder = require(DATA / "hpatches" / "v_churchill")
    a, b = load_image(folder / "1.ppm"), load_image(folder / "3.ppm")
    h = np.loadtxt(folder / "H_1_3")
    valid = valid_area_homography(h, a.shape[:2], b.shape[:2])
    rows = {}
    for test in ("flow", "plane"):
        result = Matcher(make_config("slime", tile_test=test, **WEIGHT_FREE))(a, b)
        ok = correct_matches_homography(result.keypoints0, result.keypoints1, h)
        rows[test] = (coverage(result.keypoints0[ok], result.keypoints1[ok], a.shape[:2], b.shape[:2], *valid),
                      ok.mean())
        assert result.summary["config"]["slime"]["tile_test"] == test
    assert rows["plane"][0] >= rows["flow"][0] + 0.03, rows
    assert rows["plane"][1] >= rows["flow"][1] - 0.01, rows


def test_slime_on_a_rotated_pair(graf_small):
    a, b, h = graf_small
    b_rot, rot = rotate_image(b, 90)
    result = Matcher(make_config("slime", **WEIGHT_FREE))(a, b_rot)
    ok = correct_matches_homography(result.keypoints0, result.keypoints1, rot @ h)
    assert ok.sum() > 100 and ok.mean() >= 0.8, (int(ok.sum()), ok.mean())


def test_fewer_block_scales(graf_small):
    """The fast setting (block scales 1, 2: 8 blocks per image) matches the pair with fewer block pairs."""
    a, b, h = graf_small
    result = Matcher(make_config("slime", scales=(1, 2), **WEIGHT_FREE))(a, b)
    assert result.summary["counts"]["block_pairs"] == 8 * 8
    assert tuple(result.summary["config"]["slime"]["blocks"]["scales"]) == (1, 2)
    ok = correct_matches_homography(result.keypoints0, result.keypoints1, h)
    assert ok.sum() > 100 and ok.mean() >= 0.9, (int(ok.sum()), ok.mean())


def test_max_side_matches_in_original_pixels():
    """graf 1 -> 3 (800 x 640) matched at max_side 400: matches, stage points and boxes in original pixels."""
    folder = require(DATA / "oxford_graf")
    a, b = load_image(folder / "img1.png"), load_image(folder / "img3.png")
    config = make_config("slime", scales=(1, 2), max_side=400, **WEIGHT_FREE)
    config.slime.keep_stages = True
    result = Matcher(config)(a, b)
    summary = result.summary
    assert summary["image_sizes"]["image0"] == [800, 640] and summary["working_sizes"]["image0"] == [400, 320]
    ok = correct_matches_homography(result.keypoints0, result.keypoints1, np.loadtxt(folder / "H1to3p"))
    assert ok.sum() > 1000 and ok.mean() >= 0.9, (int(ok.sum()), ok.mean())
    assert result.keypoints0.max(axis=0)[0] > 400  # not left in the 400 x 320 working frame
    stages = result.stages
    np.testing.assert_allclose(np.sort(stages["final_xy0"], axis=0), np.sort(result.keypoints0, axis=0))
    assert stages["blocks0"][:, 2].max() == pytest.approx(799.5) and stages["tiles1"][:, 3].max() == pytest.approx(639.5)
    # plane 0's matches follow its homography: RANSAC's bound is 15 px in the half-size working frame, 30 px
    # here; a frame mix-up would be off by a few hundred px (on a GPU plane 0 gave a median of 7.6 px)
    own = stages["block_matches_plane"] == 0
    moved, _ = project(stages["planes_H"][0], stages["block_matches_xy0"][own])
    assert own.sum() >= 4 and np.median(np.linalg.norm(moved - stages["block_matches_xy1"][own], axis=1)) < 15


def test_small_images_are_upsampled_and_matched_in_original_pixels():
    """graf 1 -> 3 shrunk to 240 x 192 (factor 0.3, its GT homography scaled alike): Slime upsamples both images
    to 600 x 480 (min_side 480, factor 2.5) and returns matches in the 240 x 192 frames that follow the GT (at
    240 x 192 itself, min_side 0, its 7 tile match sets cannot pass the epipolar vote: no match)."""
    folder = require(DATA / "oxford_graf")
    s = np.diag([0.3, 0.3, 1.0])
    s[:2, 2] = 0.5 * 0.3 - 0.5  # pixel-centre convention: x_s = (x + 0.5) 0.3 - 0.5
    h = s @ np.loadtxt(folder / "H1to3p") @ np.linalg.inv(s)
    a, b = (cv2.resize(load_image(folder / f), (240, 192), interpolation=cv2.INTER_AREA)
            for f in ("img1.png", "img3.png"))
    result = Matcher(make_config("slime", scales=(1, 2), **WEIGHT_FREE))(a, b)
    assert result.image_sizes == ((240, 192), (240, 192)) and result.working_sizes == ((600, 480), (600, 480))
    assert result.working_factors == ((2.5, 2.5), (2.5, 2.5))
    assert result.summary["working_factors"]["image1"] == [2.5, 2.5]
    assert result.summary["side_limits"] == {"min_side": 480, "max_side": 1200}
    ok = correct_matches_homography(result.keypoints0, result.keypoints1, h, 15 * 0.3)  # 15 px at full size
    assert ok.sum() >= 1000 and ok.mean() >= 0.9, (int(ok.sum()), ok.mean())  # 5258 of 5476 (0.96) on a CPU
    assert result.keypoints0.max(axis=0)[0] <= 239.5 and result.keypoints0.max(axis=0)[0] > 200


def test_max_side_bad_values(graf_small):
    with pytest.raises(ConfigError, match="max_side"):
        make_config("hz+", max_side=16)
    thin = np.zeros((40, 400, 3), np.float32)  # 400 x 40 shrunk to 100 x 10
    with pytest.raises(ImageError, match="raise max_side"):
        Matcher(make_config("hz+", max_side=100, **WEIGHT_FREE))(thin, graf_small[1])


def test_block_scale_presets():
    """slime-fast drops the finest block level, slime-fine adds a fourth; an explicit scales option wins."""
    assert make_config("slime").slime.blocks.scales == (1, 2, 3)
    assert make_config("slime-fast").slime.blocks.scales == (1, 2)
    assert make_config("slime-fine").slime.blocks.scales == (1, 2, 3, 4)
    assert make_config("slime-fine", scales=(2,)).slime.blocks.scales == (2,)
    assert make_config("slime-fine").base.name == "hz+"


def test_consensus_recovers_the_geometry_when_the_paper_vote_keeps_nothing(graf_small):
    """A vote threshold no match can pass (t_xi = 1000) leaves the paper's rule empty; the default rule then
    takes the largest consistent geometry, says so in the summary, and its matches follow the GT."""
    a, b, h = graf_small
    results = {vote: Matcher(make_config("slime", scales=(1, 2), views="off", **{"slime.tiles.t_xi": 1000,
                                                                     "slime.tiles.vote": vote}, **WEIGHT_FREE))(a, b)
               for vote in ("paper", "consensus")}
    assert len(results["paper"]) == 0 and results["paper"].summary["decisions"]["vote"] == "paper"
    found = results["consensus"]
    decisions = found.summary["decisions"]
    assert decisions["vote"] == "consensus" and "largest group of planes sharing one epipolar geometry has" in decisions["vote_reason"], decisions
    ok = correct_matches_homography(found.keypoints0, found.keypoints1, h)
    assert ok.sum() > 100 and ok.mean() >= 0.9, (int(ok.sum()), ok.mean())


def test_empty_slime_result_says_why(graf_small):
    """A 120 x 90 crop matched at its own size (min_side off) has one tile: the epipolar vote cannot pass, and the
    summary says so."""
    a = graf_small[0][100:190, 100:220]
    result = Matcher(make_config("slime", scales=(1,), min_side=0, **WEIGHT_FREE))(a, a)
    assert len(result) == 0 and result.summary["counts"]["block_planes"] > 0
    assert any("cannot keep a match" in w for w in result.summary["warnings"]), result.summary["warnings"]


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


def test_layout_of_an_image_pair():
    """Sec. 3.1's layout: every scale's blocks and the full-resolution tiles of each image, as ``make_blocks``
    and ``make_tiles`` give them."""
    config = BlockConfig(scales=(1, 2))
    layout = Layout.of((480, 640), (600, 800), config)
    assert layout.blocks0 == make_blocks(480, 640, config)
    assert layout.blocks1 == make_blocks(600, 800, config)
    assert layout.tiles0 == make_tiles(480, 640, config)
    assert layout.tiles1 == make_tiles(600, 800, config)
    assert len(layout.blocks0) == 2 + 6 and len(layout.tiles0) == 12


def test_layout_arrays_are_the_cores_in_original_pixels():
    """``--save-stages``' blocks0/1 and tiles0/1: per block [x0, y0, x1, y1, scale index], its core's edges
    (pixel borders, half a pixel off the centres) in original px."""
    layout = Layout.of((480, 640), (600, 800), BlockConfig())
    arrays = layout.arrays()
    assert sorted(arrays) == ["blocks0", "blocks1", "tiles0", "tiles1"]
    for name, blocks in (("blocks0", layout.blocks0), ("blocks1", layout.blocks1), ("tiles0", layout.tiles0),
                         ("tiles1", layout.tiles1)):
        expected = [[b.core[0] / b.fx - 0.5, b.core[1] / b.fy - 0.5, b.core[2] / b.fx - 0.5,
                     b.core[3] / b.fy - 0.5, b.scale_index] for b in blocks]
        np.testing.assert_allclose(arrays[name], expected, rtol=0, atol=1e-9)
    # the tiles are at full resolution: their cores less half a pixel
    np.testing.assert_array_equal(arrays["tiles0"][:2], [[-0.5, -0.5, 191.5, 191.5, 0],
                                                         [148.5, -0.5, 340.5, 191.5, 0]])
    assert arrays["tiles0"][:, 2].max() == 639.5 and arrays["tiles1"][:, 3].max() == 599.5
    # scale 1: 192 px at 0.4x
    np.testing.assert_array_equal(arrays["blocks0"][0], [-0.5, -0.5, 479.5, 479.5, 0])
    assert set(arrays["blocks1"][:, 4].tolist()) == {0.0, 1.0, 2.0}


def test_a_pooled_base_adds_its_own_block_planes(graf_small):
    """Slime on Hz+ with RootSIFT pooled (``pool="rootsift"``): the block planes are exactly those of Slime on
    Hz+ followed by those of Slime on RootSIFT, whose matches lie on the GT homography, and the final matches
    stay right."""
    a, b, h = graf_small
    alone = {name: Matcher(make_config(preset, views="off", **options))(a, b).summary["counts"]
             for name, preset, options in (("hz+", "slime", WEIGHT_FREE), ("rootsift", "slime-rootsift", {}))}
    pooled = Matcher(make_config("slime", pool="rootsift", views="off", keep_stages=True, **WEIGHT_FREE))(a, b)
    counts = pooled.summary["counts"]
    assert counts["pooled_planes"] == alone["rootsift"]["block_planes"] > 0
    assert counts["block_planes"] == alone["hz+"]["block_planes"] + alone["rootsift"]["block_planes"]
    assert pooled.summary["decisions"]["pool"] == (f"rootsift: {counts['pooled_planes']} block planes pooled with "
                                                   f"the base's {alone['hz+']['block_planes']}")
    # the pooled planes' own matches lie on the GT homography (within 15 px)
    xy0, xy1, plane = (pooled.stages[f"block_matches_{key}"] for key in ("xy0", "xy1", "plane"))
    first = counts["block_planes"] - counts["pooled_planes"]
    right = [np.mean(np.linalg.norm(project(h, xy0[plane == p])[0] - xy1[plane == p], axis=1) < 15)
             for p in range(first, counts["block_planes"])]
    assert np.percentile(right, 10) >= 0.9, np.percentile(right, 10)
    ok = correct_matches_homography(pooled.keypoints0, pooled.keypoints1, h)
    assert ok.sum() > 100 and ok.mean() >= 0.9, (int(ok.sum()), ok.mean())
