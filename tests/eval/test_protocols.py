"""Standard protocols of the hard sets (EVD homography, WxBS fundamental) on synthetic data with exact answers."""

import math

import numpy as np
import pytest

from slime_match.eval.metrics import protocols as P
from slime_match.geometry.homography import project

from .helpers import H_GT, rot, two_view_points

SHAPE = (120, 160)


def _translation(dx: float, dy: float) -> np.ndarray:
    return np.array([[1.0, 0, dx], [0, 1, dy], [0, 0, 1]])


def _exact_matches(H: np.ndarray, n: int = 200, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    x0 = np.random.default_rng(seed).uniform([0, 0], [SHAPE[1], SHAPE[0]], (n, 2))
    return x0, project(H, x0)[0]


def test_identical_homography_scores_one():
    assert P.homography_transfer_error(H_GT, H_GT, SHAPE, SHAPE) == pytest.approx(0.0, abs=1e-9)
    x0, x1 = _exact_matches(H_GT)
    result = P.evd_protocol(x0, x1, H_GT, SHAPE, SHAPE, threshold=3.0, max_iters=1000)
    assert result["error"] < 1e-3 and result["maa"] == 1.0


def test_known_translation_error_and_maa():
    # GT: shift by (10, 5); estimate: shift by (13.5, 5): every point of both directions is 3.5 px off
    H_gt, H_est = _translation(10, 5), _translation(13.5, 5)
    assert P.homography_transfer_error(H_est, H_gt, SHAPE, SHAPE) == pytest.approx(3.5)
    x0, x1 = _exact_matches(H_est)
    result = P.evd_protocol(x0, x1, H_gt, SHAPE, SHAPE, threshold=3.0, max_iters=1000)
    assert result["error"] == pytest.approx(3.5, abs=1e-3)
    assert result["maa"] == pytest.approx(12 / 15)  # 3.5 < t for t = 4..15


def test_transfer_error_pools_both_directions_over_the_common_area():
    # GT identity, estimate scale 2 about the origin: |H x - x| = |x| forward, |y / 2 - y| = |y| / 2 back
    H_est = np.diag([2.0, 2.0, 1.0])
    rows, cols = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    norm = np.hypot(cols, rows)
    assert P.homography_transfer_error(H_est, np.eye(3), SHAPE, SHAPE) == pytest.approx(0.75 * norm.mean())
    # GT shift by half the width: only the left half of image 0 (and right half of image 1) is common;
    # estimate scale 2 then the same shift: forward |x| over the left half, backward |y - 80| / 2 over the right
    half = SHAPE[1] // 2
    H_gt = _translation(half, 0)
    forward = norm[:, :half]
    backward = np.hypot(cols[:, half:] - half, rows[:, half:]) / 2
    expected = np.concatenate([forward.ravel(), backward.ravel()]).mean()
    assert P.homography_transfer_error(H_gt @ H_est, H_gt, SHAPE, SHAPE) == pytest.approx(expected)
    assert P.homography_transfer_error(H_est, _translation(500, 0), SHAPE, SHAPE) == math.inf  # no common area
    # homographies are defined up to scale, sign included
    assert P.homography_transfer_error(-H_gt @ H_est, -3 * H_gt, SHAPE, SHAPE) == pytest.approx(expected)


def test_evd_failures_score_zero():
    x0, x1 = _exact_matches(H_GT, n=3)
    assert P.magsac_homography(x0, x1, 3.0, 1000) is None
    assert P.evd_protocol(x0, x1, H_GT, SHAPE, SHAPE, 3.0, 1000) == {
        "maa": 0.0, "maa_mean": 0.0, "maa_min": 0.0, "maa_max": 0.0, "error": math.inf}
    assert P.homography_transfer_error(None, H_GT, SHAPE, SHAPE) == math.inf


# a rectified pair (camera 1 = camera 0 shifted along x): epipolar lines are the image rows
F_RECTIFIED = np.array([[0.0, 0, 0], [0, 0, -1], [0, 1, 0]])


def _rectified_matches(n: int = 300, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Exact matches of a rectified pair: random pixels, random disparities, same rows."""
    rng = np.random.default_rng(seed)
    x0 = rng.uniform([40, 0], [640, 480], (n, 2))
    return x0, x0 - np.c_[rng.uniform(1, 40, n), np.zeros(n)]


def test_symmetric_epipolar_distance_on_a_rectified_pair():
    x0, x1 = _rectified_matches(5)
    offsets = np.array([0.0, 0.5, 1.5, 2.5, 30.0])
    d = P.symmetric_epipolar_distance(F_RECTIFIED, x0, x1 + np.c_[np.zeros(5), offsets])
    assert d == pytest.approx(offsets)
    assert P.symmetric_epipolar_distance(-7.0 * F_RECTIFIED, x0, x1) == pytest.approx(0.0, abs=1e-12)
    # image 1 scaled by 2: an offset of d px there is d / 2 px in image 0; the larger one counts
    F_scaled = np.diag([0.5, 0.5, 1.0]) @ F_RECTIFIED
    d = P.symmetric_epipolar_distance(F_scaled, x0, 2 * x1 + np.c_[np.zeros(5), offsets])
    assert d == pytest.approx(offsets)


def test_wxbs_recall_one_on_exact_correspondences_of_known_cameras():
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    R, t = rot([0.1, 1, 0.05], 15), np.array([1.0, 0.2, 0.1])
    x0, x1 = two_view_points(K, K, R, t, np.random.default_rng(1), n=300)
    corrs = np.hstack(two_view_points(K, K, R, t, np.random.default_rng(2), n=40))
    result = P.wxbs_protocol(x0, x1, corrs, threshold=1.0, max_iters=1000)
    assert result["recall"] == [1.0] * 20 and result["maa"] == 1.0


def test_wxbs_recall_curve_of_perturbed_correspondences():
    x0, x1 = _rectified_matches()
    g0, g1 = _rectified_matches(5, seed=3)
    offsets = np.array([0.5, 1.5, 2.5, 10.5, 30.0])  # symmetric distances of the GT correspondences
    corrs = np.c_[g0, g1 + np.c_[np.zeros(5), offsets]]
    result = P.wxbs_protocol(x0, x1, corrs, threshold=1.0, max_iters=1000)
    expected = [1 / 5, 2 / 5] + [3 / 5] * 8 + [4 / 5] * 10  # t = 1, 2, 3..10, 11..20
    assert result["recall"] == pytest.approx(expected)
    assert result["maa"] == pytest.approx(np.mean(expected))


def test_wxbs_too_few_matches_scores_zero():
    x0, x1 = _rectified_matches(7)
    corrs = np.c_[x0, x1]
    assert P.magsac_fundamental(x0, x1, 1.0, 1000) is None
    assert P.wxbs_protocol(x0, x1, corrs, 1.0, 1000, orders=3) == {
        "maa": 0.0, "maa_mean": 0.0, "maa_min": 0.0, "maa_max": 0.0, "recall": [0.0] * 20}


# eleven matches that a Slime run returned on a WxBS pair, on which OpenCV's MAGSAC++ for F raises an assertion
# (``!model.empty()`` in ``setModelParameters``) instead of finding no model
USAC_ASSERTS = np.array([
    [327.276, 302.565, 159.122, 465.709], [247.620, 287.557, 113.342, 459.763], [267.569, 298.483, 121.381, 460.125],
    [270.332, 279.034, 123.552, 452.611], [250.637, 322.251, 116.020, 475.835], [256.543, 274.773, 116.754, 450.184],
    [349.394, 284.045, 169.589, 456.198], [328.073, 304.128, 150.696, 473.019], [281.532, 242.954, 128.874, 436.379],
    [214.771, 270.687, 101.372, 451.369], [328.886, 303.568, 157.564, 471.723]])


def test_a_set_opencv_asserts_on_scores_zero_instead_of_stopping_the_bench():
    x0, x1 = USAC_ASSERTS[:, :2], USAC_ASSERTS[:, 2:]
    assert P.magsac_fundamental(x0, x1, 3.0, 10000) is None
    assert P.wxbs_protocol(x0, x1, USAC_ASSERTS, 3.0, 10000)["maa"] == 0.0


def test_match_orders_start_with_the_given_order_and_repeat():
    orders = P.match_orders(6, 4)
    assert len(orders) == 4 and orders[0].tolist() == list(range(6))
    assert all(sorted(o.tolist()) == list(range(6)) for o in orders[1:])
    assert all((a == b).all() for a, b in zip(orders, P.match_orders(6, 4)))  # the same permutations every call


def _noisy_homography_matches(n_in: int = 60, n_out: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Inliers of H_GT with 6 px noise and uniform outliers: a set on which the estimate depends on the order."""
    rng = np.random.default_rng(3)
    x0, x1 = _exact_matches(H_GT, n_in + n_out, seed=3)
    x1 = x1 + rng.normal(0, 6.0, x1.shape)
    x1[n_in:] = rng.uniform([0, 0], [SHAPE[1], SHAPE[0]], (n_out, 2))
    return x0, x1


def test_protocols_over_orders_are_the_mean_of_each_order_run_alone():
    x0, x1 = _noisy_homography_matches()
    runs = [P.evd_protocol(x0[o], x1[o], H_GT, SHAPE, SHAPE, 3.0, 50)["maa"] for o in P.match_orders(len(x0), 5)]
    result = P.evd_protocol(x0, x1, H_GT, SHAPE, SHAPE, 3.0, 50, orders=5)
    assert result["maa"] == pytest.approx(runs[0])
    assert result["maa_mean"] == pytest.approx(np.mean(runs))
    assert (result["maa_min"], result["maa_max"]) == pytest.approx((min(runs), max(runs))) and min(runs) < max(runs)

    y0, y1 = _rectified_matches(40)
    corrs = np.c_[y0, y1]
    y1 = y1 + np.random.default_rng(4).normal(0, 1.0, y1.shape)
    runs = [P.wxbs_protocol(y0[o], y1[o], corrs, 1.0, 50)["maa"] for o in P.match_orders(len(y0), 4)]
    result = P.wxbs_protocol(y0, y1, corrs, 1.0, 50, orders=4)
    assert result["maa"] == pytest.approx(runs[0]) and result["maa_mean"] == pytest.approx(np.mean(runs))
