"""Slime orchestration: coordinate frames, flow guide, final merge, and end-to-end runs with exact GT."""

import math
import os
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from conftest import DATA, require

from slime_match.config import make_config
from slime_match.errors import ConfigError, ImageError
from slime_match.eval.datasets import rotate_image
from slime_match.eval.metrics import correct_matches_homography, coverage, valid_area_homography
from slime_match.geometry.homography import project
from slime_match.io import load_image
from slime_match.matcher import Matcher
from slime_match.slime.block_matching import BlockPairMatches, device_workers, orientation_bin
from slime_match.slime.blocks import make_blocks, make_tiles
from slime_match.slime.clusters import greedy_clusters
from slime_match.slime.forking import torch_threads
from slime_match.slime.pipeline import (
    MANY_BLOCK_PAIRS,
    _workers,
    block_planes_to_original,
    empty_result_reason,
    layout_warning,
    tile_count_warning,
)
from slime_match.slime.refine import FlowGuide, PlaneGuide, cluster_representatives, global_dtm, tile_test
from slime_match.slime.tiles import TileConfig

WEIGHT_FREE = {"shape": "baumberg", "orientation": "gradient", "descriptor": "rootsift"}


def test_orientation_bin_centres_and_wrap():
    width = 2 * math.pi / 16
    assert orientation_bin(0.0, 16) == 0
    assert orientation_bin(0.49 * width, 16) == 0 and orientation_bin(0.51 * width, 16) == 1
    assert orientation_bin(-width, 16) == 15 and orientation_bin(2 * math.pi, 16) == 0
    assert orientation_bin(math.pi, 16) == 8


def test_block_planes_map_exactly_to_original_frame():
    blocks0, blocks1 = make_blocks(480, 640), make_blocks(600, 800)
    w0 = next(i for i, b in enumerate(blocks0) if b.scale_index == 2)
    w1 = next(i for i, b in enumerate(blocks1) if b.scale_index == 0)
    h_true = np.array([[0.9, 0.1, 20.0], [-0.05, 1.1, -10.0], [1e-4, 2e-5, 1.0]])
    rng = np.random.default_rng(0)
    x_orig = rng.uniform(50, 400, (30, 2))
    y_orig, _ = project(h_true, x_orig)
    b0, b1 = blocks0[w0], blocks1[w1]
    x_s, y_s = b0.to_scaled(x_orig), b1.to_scaled(y_orig)
    # The block-frame homography that RANSAC would estimate: scaled 0 -> scaled 1.
    from slime_match.geometry.homography import homography_dlt

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


def test_flow_guide_equals_brute_force():
    rng = np.random.default_rng(1)
    g0, g1 = rng.uniform(0, 300, (200, 2)), rng.uniform(0, 300, (200, 2))
    pick = rng.integers(0, 200, 500)
    y0 = g0[pick] + rng.normal(0, 8, (500, 2))
    y1 = g1[pick] + rng.normal(0, 8, (500, 2))
    y1[:250] = rng.uniform(0, 300, (250, 2))
    guide = FlowGuide(g0, g1, 15.0)
    d0 = np.linalg.norm(y0[:, None] - g0[None], axis=2)
    d1 = np.linalg.norm(y1[:, None] - g1[None], axis=2)
    expected = (np.maximum(d0, d1) < 15.0).any(axis=1)
    assert expected.sum() > 50
    assert np.array_equal(guide(y0, y1, neighbours=200), expected)
    assert FlowGuide(np.zeros((0, 2)), np.zeros((0, 2)), 15.0)(y0, y1).sum() == 0


def test_plane_guide_keeps_what_fits_one_of_the_given_planes():
    """Candidates within t of a plane (two-sided), on its side, pass for that plane only; the other plane of the
    pair, or a plane not given, does not let them through."""
    shift = np.array([[1.0, 0.0, 40.0], [0.0, 1.0, -20.0], [0.0, 0.0, 1.0]])
    zoom = np.array([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]])
    flipped = -shift  # the same mapping with w < 0 on every point: the other side of that plane
    guide = PlaneGuide(np.stack([shift, zoom, flipped]), np.array([1.0, 1.0, 1.0]), 15.0)
    y0 = np.array([[100.0, 100.0], [100.0, 100.0], [100.0, 100.0], [50.0, 60.0]])
    y1 = np.array([[150.0, 80.0], [155.0, 80.0], [201.0, 207.0], [90.0, 40.0]])  # errors under shift: 10, 15, .., 0
    assert guide(y0, y1, np.array([0])).tolist() == [True, False, False, True]
    assert guide(y0, y1, np.array([1])).tolist() == [False, False, True, False]  # zoom: (200, 200) vs (201, 207)
    assert guide(y0, y1, np.array([0, 1])).tolist() == [True, False, True, True]
    assert guide(y0, y1, np.array([2])).tolist() == [False] * 4
    assert guide(y0, y1, np.array([], np.int64)).tolist() == [False] * 4
    assert guide(y0[:0], y1[:0], np.array([0])).shape == (0,)


def test_tile_tests_choose_flow_or_plane():
    """"flow" ignores the planes, "plane" ignores the flows."""
    flow = FlowGuide(np.array([[0.0, 0.0]]), np.array([[500.0, 500.0]]), 15.0)
    plane = PlaneGuide(np.eye(3)[None], np.ones(1), 15.0)
    y0 = np.array([[5.0, 0.0], [300.0, 300.0], [700.0, 0.0]])
    y1 = np.array([[505.0, 500.0], [305.0, 300.0], [0.0, 700.0]])
    planes = np.array([0])
    assert tile_test("flow", flow, plane)(y0, y1, planes).tolist() == [True, False, False]
    assert tile_test("plane", flow, plane)(y0, y1, planes).tolist() == [False, True, False]
    with pytest.raises(ValueError, match="tile test 'either'"):
        tile_test("either", flow, plane)
    with pytest.raises(ConfigError, match="invalid tile_test 'nearest'"):
        make_config("slime", tile_test="nearest")
    with pytest.raises(ConfigError, match="Slime option"):
        make_config("hz+", tile_test="plane")


def test_global_dtm_merges_exact_duplicates():
    rng = np.random.default_rng(2)
    x0 = rng.uniform(0, 200, (300, 2))
    x1 = x0 + [10.0, 5.0]
    xy0, xy1 = np.vstack([x0, x0[:100]]), np.vstack([x1, x1[:100]])
    scores = rng.uniform(0, 1, 400)
    k0, k1, s = global_dtm(xy0, xy1, scores, (220, 220), (220, 220))
    rows = np.hstack([k0, k1])
    assert len(np.unique(rows, axis=0)) == len(rows) and len(rows) > 250
    assert np.all(np.diff(s) >= 0)


def test_cluster_representatives_and_shared_verdicts():
    """Matches within 4 px of a better one at both ends join its cluster, represented by its best-scored
    match; in global_dtm the members of a cluster share its verdict (kept or dropped together)."""
    xy0 = np.array([[10.2, 10.1], [11.9, 10.4], [10.5, 11.5], [30.0, 30.0], [10.2, 10.1]])
    xy1 = np.array([[20.0, 20.0], [20.5, 21.0], [25.0, 20.0], [40.0, 40.0], [20.1, 20.2]])
    scores = np.array([0.5, 0.2, 0.1, 0.3, 0.4])
    rep, cluster = cluster_representatives(xy0, xy1, scores)
    assert cluster[0] == cluster[1] == cluster[4] and len({cluster[0], cluster[2], cluster[3]}) == 3
    assert sorted(rep.tolist()) == [1, 2, 3]  # the best-scored member of each cluster
    rng = np.random.default_rng(4)
    x0 = rng.uniform(5, 195, (200, 2))
    x1 = x0 + [10.0, 5.0]
    near0, near1 = x0[:80] + rng.uniform(-0.4, 0.4, (80, 2)), x1[:80] + rng.uniform(-0.4, 0.4, (80, 2))
    k0, k1, _ = global_dtm(np.vstack([x0, near0]), np.vstack([x1, near1]), rng.uniform(0, 1, 280), (220, 220),
                           (220, 220))
    kept = {tuple(r) for r in np.round(np.hstack([k0, k1]), 6)}
    both = np.round(np.hstack([np.vstack([x0, near0]), np.vstack([x1, near1])]), 6)
    _, member = cluster_representatives(np.vstack([x0, near0]), np.vstack([x1, near1]), np.zeros(280))
    for c in np.unique(member):
        verdicts = {tuple(r) in kept for r in both[member == c]}
        assert len(verdicts) == 1
    assert len(k0) > 250


def _greedy_clusters_by_definition(points, scores, radius):
    cluster = np.full(len(points), -1)
    rep = []
    for i in np.argsort(scores, kind="stable"):
        if cluster[i] < 0:
            near = (np.abs(points - points[i]).max(axis=1) <= radius) & (cluster < 0)
            cluster[near] = len(rep)
            rep.append(i)
    return np.array(rep, np.int64), cluster


@pytest.mark.parametrize("dims", [1, 3, 4])
def test_greedy_clusters_match_the_definition(dims):
    """Compiled sweep + cover against the definition: ties in score, exact duplicates, points exactly at the
    radius (integer grid), a column of equal first coordinates."""
    rng = np.random.default_rng(dims)
    points = rng.integers(0, 40, (600, dims)).astype(float)
    points[:50, 0] = 7.0
    points = np.vstack([points, points[:30]])
    scores = rng.integers(0, 5, len(points)).astype(float)
    for radius in (0.0, 1.0, 2.5):
        rep, cluster = greedy_clusters(points, scores, radius)
        want_rep, want_cluster = _greedy_clusters_by_definition(points, scores, radius)
        assert np.array_equal(rep, want_rep) and np.array_equal(cluster, want_cluster)
    rep, cluster = greedy_clusters(np.zeros((0, 2)), np.zeros(0), 1.0)
    assert rep.shape == (0,) and cluster.shape == (0,)


def test_cluster_representatives_are_apart_and_members_near():
    rng = np.random.default_rng(7)
    xy0 = rng.uniform(0, 60, (3000, 2))
    xy1 = xy0 * 1.1 + rng.normal(0, 2, (3000, 2))
    scores = rng.uniform(0, 1, 3000)
    rep, cluster = cluster_representatives(xy0, xy1, scores, radius=4.0)
    ends = np.hstack([xy0, xy1])
    gap = np.abs(ends[rep][:, None] - ends[rep][None]).max(axis=2)
    np.fill_diagonal(gap, np.inf)
    assert gap.min() > 4.0  # no representative within the radius of another at both ends
    assert np.abs(ends - ends[rep[cluster]]).max() <= 4.0  # every member near its representative
    assert np.all(cluster[rep] == np.arange(len(rep)))
    assert np.all(scores[rep[cluster]] <= scores)  # the representative is the best-scored member


def test_torch_threads_restores_setting():
    before = torch.get_num_threads()
    with torch_threads(1):
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == before


@pytest.fixture(scope="module")
def graf_small():
    """graf 1 -> 3 at half resolution with its exact GT homography."""
    import cv2

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


def _counts(**values: int) -> dict[str, int]:
    return {"block_planes": 5, "superset_H": 40, "epipolar_kept": 100, "ftheta_matches": 90, "tile_matches": 7,
            **values}


def test_empty_result_reason_names_the_stage():
    tiles = TileConfig()
    assert "no block pair gave a plane" in empty_result_reason(_counts(block_planes=0), tiles)
    # |H| (|H| - 1) ordered pairs of sets can never exceed 9 |H| votes when |H| <= 10
    impossible = empty_result_reason(_counts(superset_H=10, epipolar_kept=0), tiles)
    assert "cannot keep a match with only 10 tile match sets" in impossible and "out of 90" in impossible
    assert "do not share one epipolar geometry" in empty_result_reason(_counts(superset_H=11, epipolar_kept=0), tiles)
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


def test_empty_slime_result_says_why(graf_small):
    """A 120 x 90 crop has one tile: the epipolar vote cannot pass, and the summary says so."""
    a = graf_small[0][100:190, 100:220]
    result = Matcher(make_config("slime", scales=(1,), **WEIGHT_FREE))(a, a)
    assert len(result) == 0 and result.summary["counts"]["block_planes"] > 0
    assert any("cannot keep a match" in w for w in result.summary["warnings"]), result.summary["warnings"]


def test_cuda_pipelines_keep_device_work_in_one_process():
    """CUDA does not survive fork: a CUDA base's device work runs in one process, only its CPU halves fork."""
    cuda, cpu = SimpleNamespace(device=torch.device("cuda")), SimpleNamespace(device=torch.device("cpu"))
    assert device_workers(cuda, 4) == 1 and device_workers(cpu, 4) == 4
    assert _workers(3) == 3 and _workers(0) == 1 and _workers(None) == max(1, os.cpu_count() or 1)