"""Pose metrics (LoFTR protocol): angular errors, essential-matrix and F-based pose, AUC."""

import math

import numpy as np
import pytest

from slime_match.eval.metrics.pose import (
    estimate_pose_essential,
    pose_auc,
    pose_errors_sweep,
    pose_from_fundamental,
    relative_pose_error,
)

from .helpers import rot


def test_relative_pose_error_known_rotations():
    R_gt, t_gt = rot([0, 1, 0], 30), np.array([1.0, 0, 0])
    r, te = relative_pose_error(R_gt, t_gt, rot([0, 1, 0], 25), np.array([-1.0, 0, 0]))
    assert r == pytest.approx(5.0) and te == pytest.approx(0.0, abs=1e-6)  # sign of t is ignored
    _, te = relative_pose_error(R_gt, t_gt, R_gt, np.array([1.0, 1.0, 0]))
    assert te == pytest.approx(45.0)
    assert relative_pose_error(R_gt, t_gt, None, None) == (math.inf, math.inf)


def _synthetic_two_view(rng, n=200, noise=0.0):
    K0 = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    K1 = np.array([[450.0, 0, 300], [0, 460, 250], [0, 0, 1]])
    R, t = rot([0.2, 1, 0.1], 12), np.array([0.8, 0.1, 0.2])
    X = np.concatenate([rng.uniform(-2, 2, (n, 2)), rng.uniform(4, 8, (n, 1))], 1)
    x0 = X @ K0.T
    x1 = (X @ R.T + t) @ K1.T
    x0, x1 = x0[:, :2] / x0[:, 2:], x1[:, :2] / x1[:, 2:]
    return K0, K1, R, t, x0 + rng.normal(0, noise, x0.shape), x1 + rng.normal(0, noise, x1.shape)


def test_pose_estimation_recovers_synthetic_pose():
    rng = np.random.default_rng(1)
    K0, K1, R, t, x0, x1 = _synthetic_two_view(rng, noise=0.1)
    x1[:40] = rng.uniform(0, 600, (40, 2))  # 20% outliers
    Re, te, inl = estimate_pose_essential(x0, x1, K0, K1, threshold=1.0)
    r_err, t_err = relative_pose_error(R, t, Re, te)
    assert r_err < 1.0 and t_err < 3.0 and inl[40:].mean() > 0.9 and inl[:40].mean() < 0.2
    sweep = pose_errors_sweep(x0, x1, K0, K1, R, t, thresholds=(0.5, 2.0))
    assert set(sweep) == {0.5, 2.0} and max(sweep.values()) < 3.0
    assert estimate_pose_essential(x0[:4], x1[:4], K0, K1) is None


def test_pose_estimation_answers_none_when_opencv_asserts(monkeypatch):
    """Some OpenCV releases' five-point solver asserts on a degenerate sample: no pose, not a stopped bench."""
    import cv2

    def asserting(*args, **kwargs):
        raise cv2.error("solvePoly: (-215:Assertion failed)")

    rng = np.random.default_rng(1)
    K0, K1, _, _, x0, x1 = _synthetic_two_view(rng)
    monkeypatch.setattr(cv2, "findEssentialMat", asserting)
    assert estimate_pose_essential(x0, x1, K0, K1, threshold=1.0) is None


def test_pose_from_fundamental():
    rng = np.random.default_rng(2)
    K0, K1, R, t, x0, x1 = _synthetic_two_view(rng)
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    F = np.linalg.inv(K1).T @ tx @ R @ np.linalg.inv(K0)
    Re, te, inl = pose_from_fundamental(F, K0, K1, x0, x1)
    r_err, t_err = relative_pose_error(R, t, Re, te)
    assert r_err < 1e-4 and t_err < 1e-4 and inl.all()


def test_pose_auc_known_lists():
    assert pose_auc([5.0], (10,))[10] == pytest.approx(0.75)  # (0.5*5*1 + 5*1) / 10
    assert pose_auc([0.0, 0.0]) == {5.0: 1.0, 10.0: 1.0, 20.0: 1.0}
    assert pose_auc([math.inf, np.nan, 30.0]) == {5.0: 0.0, 10.0: 0.0, 20.0: 0.0}
    # errors 2 and 30 at threshold 5: ramp to 0.5 at 2 (area 0.5), then flat 0.5 for 3 px (1.5)
    assert pose_auc([30.0, 2.0], (5,))[5] == pytest.approx(2.0 / 5)
