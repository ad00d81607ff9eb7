"""Metrics on synthetic cases with hand-computed answers."""

import itertools
import math

import cv2
import numpy as np
import pytest

from slime_match.errors import ConfigError
from slime_match.eval import metrics as M
from slime_match.eval.datasets import load_dataset


def _rot(axis, deg):
    return cv2.Rodrigues(np.asarray(axis, np.float64) / np.linalg.norm(axis) * math.radians(deg))[0]


H_GT = np.array([[1.1, 0.05, 20.0], [-0.03, 0.95, -10.0], [1e-4, -5e-5, 1.0]])


def test_homography_precision_exact_with_known_outliers():
    rng = np.random.default_rng(0)
    x0 = rng.uniform(50, 450, (100, 2))
    x1 = M.project(H_GT, x0)[0] + rng.normal(0, 1.0, (100, 2))
    out = rng.choice(100, 23, replace=False)
    x1[out] += rng.choice([-1, 1], (23, 2)) * rng.uniform(30, 100, (23, 2))
    ok = M.correct_matches_homography(x0, x1, H_GT)
    assert ok.sum() == 77 and not ok[out].any()
    assert M.correct_matches_homography(np.zeros((0, 2)), np.zeros((0, 2)), H_GT).shape == (0,)


def test_homography_threshold_boundary_and_masks():
    x0 = np.array([[100.0, 100.0], [200.0, 100.0], [300.0, 300.0]])
    x1 = x0 + [[14.9, 0.0], [15.1, 0.0], [0.0, 0.0]]
    assert M.correct_matches_homography(x0, x1, np.eye(3)).tolist() == [True, False, True]
    mask1 = np.zeros((400, 400), bool)
    mask1[290:310, 290:310] = True  # excluded area around the third match in image 1
    assert M.correct_matches_homography(x0, x1, np.eye(3), mask1=mask1).tolist() == [True, False, False]


def test_fundamental_epipolar_and_local_consistency():
    F = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0.0]])  # rectified: y1 == y0
    gx, gy = np.meshgrid(np.arange(0, 400, 40.0), np.arange(0, 400, 40.0))
    g0 = np.stack([gx.ravel(), gy.ravel()], 1)
    g1 = g0 * [1.2, 1.0] + [-30.0, 0.0]  # horizontal flow varying affinely
    corrs = np.concatenate([g0, g1], 1)
    x0 = np.array([[105.0, 205.0], [105.0, 205.0], [105.0, 205.0], [1000.0, 205.0]])
    exact = x0[0] * [1.2, 1.0] + [-30.0, 0.0]
    x1 = np.array([exact, exact + [40.0, 0.0], exact + [0.0, 20.0], [900.0, 205.0]])
    assert M.correct_matches_fundamental(x0, x1, F).tolist() == [True, True, False, True]
    # with GT: the second is on its epipolar line but off the local flow; the fourth has no GT nearby
    assert M.correct_matches_fundamental(x0, x1, F, gt_corrs=corrs).tolist() == [True, False, False, True]


def test_fundamental_local_consistency_under_rotation_and_scale():
    # GT flow = rotation by 60 degrees and scale 1.5 about (200, 200): the flow of the nearest GT point alone
    # differs by tens of px, the local affine model predicts exactly
    A = 1.5 * _rot([0, 0, 1], 60)[:2, :2]
    warp = lambda p: (p - 200.0) @ A.T + 200.0
    rng = np.random.default_rng(3)
    g0 = rng.uniform(0, 400, (150, 2))
    x0 = rng.uniform(50, 350, (200, 2))
    x1 = warp(x0)
    assert M._locally_consistent(x0, x1, g0, warp(g0), 15.0, 50.0, 8, 2).all()
    assert not M._locally_consistent(x0, x1 + [25.0, 0.0], g0, warp(g0), 15.0, 50.0, 8, 2).any()


def test_fundamental_local_consistency_on_real_stereo():
    (p,) = load_dataset("motorcycle")
    d = p.disparity
    rng = np.random.default_rng(0)
    rows, cols = np.nonzero(np.isfinite(d))
    pick = rng.choice(len(rows), 1300, replace=False)
    x0 = np.stack([cols[pick], rows[pick]], 1).astype(float)
    x1 = x0 - np.stack([d[rows[pick], cols[pick]], np.zeros(len(pick))], 1)
    corrs = np.concatenate([x0[:300], x1[:300]], 1)  # sparse "hand-taken" GT, as dense as the paper's
    x0, x1 = x0[300:], x1[300:]
    slid = x1 + [30.0, 0.0]  # wrong matches that still lie on their epipolar lines
    assert M.correct_matches_fundamental(x0, slid, p.F).all()
    assert M.correct_matches_fundamental(x0, x1, p.F, gt_corrs=corrs).mean() > 0.9
    assert M.correct_matches_fundamental(x0, slid, p.F, gt_corrs=corrs).mean() < 0.12


def test_disparity_correctness():
    disp = np.full((50, 60), 10.0, np.float32)
    disp[:, 30:] = np.inf
    x0 = np.array([[20.0, 10.0], [20.0, 10.0], [40.0, 10.0]])
    x1 = np.array([[10.0, 10.0], [30.0, 10.0], [30.0, 10.0]])
    err = M.disparity_error(x0, x1, disp)
    assert err[0] == 0 and err[1] == 20 and np.isnan(err[2])
    assert M.correct_matches_disparity(x0, x1, disp).tolist() == [True, False, False]


def test_coverage_single_keypoint_is_disk_area():
    valid = np.zeros((300, 400), bool)
    valid[20:280, 30:370] = True
    pt = np.array([[200.0, 150.0]])
    cov = M.coverage(pt, pt, valid.shape, valid.shape, valid, valid, t=15)
    assert cov == pytest.approx(math.pi * 15**2 / valid.sum(), rel=0.01)
    # a keypoint outside the valid area of image 1 covers nothing there -> min is 0
    assert M.coverage(pt, np.array([[5.0, 5.0]]), valid.shape, valid.shape, valid, valid) == 0.0


def test_valid_area_homography():
    H = np.eye(3)
    H[0, 2] = 100.0  # image 0 shifted right by 100 px
    v0, v1 = M.valid_area_homography(H, (100, 200), (100, 200))
    assert v0.sum() == 100 * 100 and v0[:, :100].all() and not v0[:, 100:].any()
    assert v1[:, 100:].all() and not v1[:, :100].any()
    mask1 = np.zeros((100, 200), bool)
    mask1[:, 150:] = True
    v0, v1 = M.valid_area_homography(H, (100, 200), (100, 200), mask1=mask1)
    assert v0.sum() == 100 * 50 and v1.sum() == 100 * 50


def test_valid_area_nonplanar_union():
    v0, v1 = M.valid_area_nonplanar(
        [np.array([[50.0, 50.0]]), np.array([[150.0, 50.0]])],
        [np.zeros((0, 2)), np.zeros((0, 2))],
        (100, 200),
        (100, 200),
        gt_corrs=np.array([[0.0, 0.0, 100.0, 50.0]]),
        t=10,
    )
    assert v0[50, 50] and v0[50, 150] and v0[0, 0] and not v0[50, 100]
    assert v1[50, 100] and v1.sum() == M.dilated_mask(np.array([[100.0, 50.0]]), (100, 200), 10).sum()


def test_homography_accuracy_shift_and_maa_boundaries():
    valid = np.ones((120, 160), bool)
    # H_est = (shift by 2 px in image 1) o H_gt: E12 is exactly 2, E21 = mean |H_gt^-1 (x - s) - H_gt^-1 x|
    H_est = np.array([[1, 0, 2.0], [0, 1, 0], [0, 0, 1]]) @ H_GT
    v0, v1 = M.valid_area_homography(H_GT, valid.shape, valid.shape)
    pts = np.stack(np.nonzero(v1)[::-1], 1).astype(float)
    Hi = np.linalg.inv(H_GT)
    e21 = np.linalg.norm(M.project(Hi, pts - [2.0, 0])[0] - M.project(Hi, pts)[0], axis=1).mean()
    assert M.homography_accuracy_error(H_est, H_GT, v0, v1) == pytest.approx(max(2.0, e21))
    Hs = np.eye(3)
    Hs[0, 2] = 2.0
    err = M.homography_accuracy_error(Hs, np.eye(3), valid, valid)
    assert err == pytest.approx(2.0)
    assert M.homography_accuracy_error(None, np.eye(3), valid, valid) == math.inf
    # Eq. acc_formula: error e passes thresholds t = floor(e)+1 .. 15 (strict <)
    assert M.mean_average_accuracy(np.array([err])) == pytest.approx(13 / 15)
    assert M.mean_average_accuracy(np.array([1.0])) == pytest.approx(14 / 15)
    assert M.mean_average_accuracy(np.array([0.999])) == pytest.approx(1.0)
    assert M.mean_average_accuracy(np.array([15.0, math.inf, np.nan])) == 0.0
    assert M.mean_average_accuracy(np.array([0.0, 14.5])) == pytest.approx((15 + 1) / 30)


def test_fundamental_accuracy_zero_and_growing():
    K = np.array([[300.0, 0, 160], [0, 300, 120], [0, 0, 1]])
    R, t = _rot([0.1, 1, 0.05], 10), np.array([1.0, 0.1, 0.05])
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    F = np.linalg.inv(K).T @ tx @ R @ np.linalg.inv(K)
    valid = np.ones((240, 320), bool)
    assert M.fundamental_accuracy_error(F, F, valid, valid) == pytest.approx(0.0, abs=1e-9)
    assert M.fundamental_accuracy_error(-3.0 * F, F, valid, valid) == pytest.approx(0.0, abs=1e-9)
    errs = []
    for deg in (0.2, 0.5, 1.0, 2.0):
        Rp = _rot([0.3, 0.2, 1.0], deg) @ R
        Fp = np.linalg.inv(K).T @ tx @ Rp @ np.linalg.inv(K)
        errs.append(M.fundamental_accuracy_error(Fp, F, valid, valid))
    assert all(0 < a < b for a, b in itertools.pairwise(errs))
    assert M.fundamental_accuracy_error(None, F, valid, valid) == math.inf


def test_epipolar_line_area_parallel_and_crossing():
    # horizontal lines y = 10 and y = 13 across a 100 x 50 (w x h) image: 3 x 100 px^2
    la, lb = np.array([[0.0, 1.0, -10.0]]), np.array([[0.0, -2.0, 26.0]])
    assert M.epipolar_line_area(la, lb, (50, 100))[0] == pytest.approx(300.0)
    # vertical lines x = 20 and x = 25 in the same image: 5 x 50 (integrated along rows)
    la, lb = np.array([[1.0, 0.0, -20.0]]), np.array([[1.0, 0.0, -25.0]])
    assert M.epipolar_line_area(la, lb, (50, 100))[0] == pytest.approx(250.0)
    # lines crossing at the image centre with slopes +-0.1: two triangles 50 px long, 10 px high at the edge
    c = np.array([49.5, 24.5])
    la = np.array([[0.1, -1.0, c[1] - 0.1 * c[0]]])
    lb = np.array([[-0.1, -1.0, c[1] + 0.1 * c[0]]])
    assert M.epipolar_line_area(la, lb, (50, 100))[0] == pytest.approx(500.0)
    assert M.epipolar_line_area(la, lb, (50, 100), col_step=4)[0] == pytest.approx(500.0, rel=0.01)


def test_failure_counts():
    assert M.failure_counts(np.array([0, 10, 5, 0, 3]), np.array([0, 0, 5, 0, 1])) == {
        "no_matches": 2,
        "only_wrong": 1,
    }


def test_relative_pose_error_known_rotations():
    R_gt, t_gt = _rot([0, 1, 0], 30), np.array([1.0, 0, 0])
    r, te = M.relative_pose_error(R_gt, t_gt, _rot([0, 1, 0], 25), np.array([-1.0, 0, 0]))
    assert r == pytest.approx(5.0) and te == pytest.approx(0.0, abs=1e-6)  # sign of t is ignored
    _, te = M.relative_pose_error(R_gt, t_gt, R_gt, np.array([1.0, 1.0, 0]))
    assert te == pytest.approx(45.0)
    assert M.relative_pose_error(R_gt, t_gt, None, None) == (math.inf, math.inf)


def _synthetic_two_view(rng, n=200, noise=0.0):
    K0 = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    K1 = np.array([[450.0, 0, 300], [0, 460, 250], [0, 0, 1]])
    R, t = _rot([0.2, 1, 0.1], 12), np.array([0.8, 0.1, 0.2])
    X = np.concatenate([rng.uniform(-2, 2, (n, 2)), rng.uniform(4, 8, (n, 1))], 1)
    x0 = X @ K0.T
    x1 = (X @ R.T + t) @ K1.T
    x0, x1 = x0[:, :2] / x0[:, 2:], x1[:, :2] / x1[:, 2:]
    return K0, K1, R, t, x0 + rng.normal(0, noise, x0.shape), x1 + rng.normal(0, noise, x1.shape)


def test_pose_estimation_recovers_synthetic_pose():
    rng = np.random.default_rng(1)
    K0, K1, R, t, x0, x1 = _synthetic_two_view(rng, noise=0.1)
    x1[:40] = rng.uniform(0, 600, (40, 2))  # 20% outliers
    Re, te, inl = M.estimate_pose_essential(x0, x1, K0, K1, threshold=1.0)
    r_err, t_err = M.relative_pose_error(R, t, Re, te)
    assert r_err < 1.0 and t_err < 3.0 and inl[40:].mean() > 0.9 and inl[:40].mean() < 0.2
    sweep = M.pose_errors_sweep(x0, x1, K0, K1, R, t, thresholds=(0.5, 2.0))
    assert set(sweep) == {0.5, 2.0} and max(sweep.values()) < 3.0
    assert M.estimate_pose_essential(x0[:4], x1[:4], K0, K1) is None


def test_pose_from_fundamental():
    rng = np.random.default_rng(2)
    K0, K1, R, t, x0, x1 = _synthetic_two_view(rng)
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    F = np.linalg.inv(K1).T @ tx @ R @ np.linalg.inv(K0)
    Re, te, inl = M.pose_from_fundamental(F, K0, K1, x0, x1)
    r_err, t_err = M.relative_pose_error(R, t, Re, te)
    assert r_err < 1e-4 and t_err < 1e-4 and inl.all()


def test_pose_auc_known_lists():
    assert M.pose_auc([5.0], (10,))[10] == pytest.approx(0.75)  # (0.5*5*1 + 5*1) / 10
    assert M.pose_auc([0.0, 0.0]) == {5.0: 1.0, 10.0: 1.0, 20.0: 1.0}
    assert M.pose_auc([math.inf, np.nan, 30.0]) == {5.0: 0.0, 10.0: 0.0, 20.0: 0.0}
    # errors 2 and 30 at threshold 5: ramp to 0.5 at 2 (area 0.5), then flat 0.5 for 3 px (1.5)
    assert M.pose_auc([30.0, 2.0], (5,))[5] == pytest.approx(2.0 / 5)


def test_config_rejects_unknown_options():
    assert M.MetricConfig.from_options(t_perp=10).t_perp == 10
    with pytest.raises(ConfigError):
        M.MetricConfig.from_options(t_prep=10)
