"""Accuracy errors (homography, fundamental / epipolar line area), mAA and failure counts."""

import itertools
import math

import numpy as np
import pytest

from slime_match.eval.metrics.accuracy import (
    epipolar_line_area,
    failure_counts,
    fundamental_accuracy_error,
    homography_accuracy_error,
    mean_average_accuracy,
)
from slime_match.eval.metrics.coverage import valid_area_homography
from slime_match.geometry.homography import project

from .helpers import H_GT, rot


def test_homography_accuracy_shift_and_maa_boundaries():
    valid = np.ones((120, 160), bool)
    # H_est = (shift by 2 px in image 1) o H_gt: E12 is exactly 2, E21 = mean |H_gt^-1 (x - s) - H_gt^-1 x|
    H_est = np.array([[1, 0, 2.0], [0, 1, 0], [0, 0, 1]]) @ H_GT
    v0, v1 = valid_area_homography(H_GT, valid.shape, valid.shape)
    pts = np.stack(np.nonzero(v1)[::-1], 1).astype(float)
    Hi = np.linalg.inv(H_GT)
    e21 = np.linalg.norm(project(Hi, pts - [2.0, 0])[0] - project(Hi, pts)[0], axis=1).mean()
    assert homography_accuracy_error(H_est, H_GT, v0, v1) == pytest.approx(max(2.0, e21))
    Hs = np.eye(3)
    Hs[0, 2] = 2.0
    err = homography_accuracy_error(Hs, np.eye(3), valid, valid)
    assert err == pytest.approx(2.0)
    assert homography_accuracy_error(None, np.eye(3), valid, valid) == math.inf
    # Eq. acc_formula: error e passes thresholds t = floor(e)+1 .. 15 (strict <)
    assert mean_average_accuracy(np.array([err])) == pytest.approx(13 / 15)
    assert mean_average_accuracy(np.array([1.0])) == pytest.approx(14 / 15)
    assert mean_average_accuracy(np.array([0.999])) == pytest.approx(1.0)
    assert mean_average_accuracy(np.array([15.0, math.inf, np.nan])) == 0.0
    assert mean_average_accuracy(np.array([0.0, 14.5])) == pytest.approx((15 + 1) / 30)


def test_fundamental_accuracy_zero_and_growing():
    K = np.array([[300.0, 0, 160], [0, 300, 120], [0, 0, 1]])
    R, t = rot([0.1, 1, 0.05], 10), np.array([1.0, 0.1, 0.05])
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    F = np.linalg.inv(K).T @ tx @ R @ np.linalg.inv(K)
    valid = np.ones((240, 320), bool)
    assert fundamental_accuracy_error(F, F, valid, valid) == pytest.approx(0.0, abs=1e-9)
    assert fundamental_accuracy_error(-3.0 * F, F, valid, valid) == pytest.approx(0.0, abs=1e-9)
    errs = []
    for deg in (0.2, 0.5, 1.0, 2.0):
        Rp = rot([0.3, 0.2, 1.0], deg) @ R
        Fp = np.linalg.inv(K).T @ tx @ Rp @ np.linalg.inv(K)
        errs.append(fundamental_accuracy_error(Fp, F, valid, valid))
    assert all(0 < a < b for a, b in itertools.pairwise(errs))
    assert fundamental_accuracy_error(None, F, valid, valid) == math.inf


def test_epipolar_line_area_parallel_and_crossing():
    # horizontal lines y = 10 and y = 13 across a 100 x 50 (w x h) image: 3 x 100 px^2
    la, lb = np.array([[0.0, 1.0, -10.0]]), np.array([[0.0, -2.0, 26.0]])
    assert epipolar_line_area(la, lb, (50, 100))[0] == pytest.approx(300.0)
    # vertical lines x = 20 and x = 25 in the same image: 5 x 50 (integrated along rows)
    la, lb = np.array([[1.0, 0.0, -20.0]]), np.array([[1.0, 0.0, -25.0]])
    assert epipolar_line_area(la, lb, (50, 100))[0] == pytest.approx(250.0)
    # lines crossing at the image centre with slopes +-0.1: two triangles 50 px long, 10 px high at the edge
    c = np.array([49.5, 24.5])
    la = np.array([[0.1, -1.0, c[1] - 0.1 * c[0]]])
    lb = np.array([[-0.1, -1.0, c[1] + 0.1 * c[0]]])
    assert epipolar_line_area(la, lb, (50, 100))[0] == pytest.approx(500.0)
    assert epipolar_line_area(la, lb, (50, 100), col_step=4)[0] == pytest.approx(500.0, rel=0.01)


def test_failure_counts():
    assert failure_counts(np.array([0, 10, 5, 0, 3]), np.array([0, 0, 5, 0, 1])) == {
        "no_matches": 2,
        "only_wrong": 1,
    }
