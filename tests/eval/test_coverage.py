"""Coverage and valid areas on synthetic cases with hand-computed answers."""

import math

import numpy as np
import pytest

from slime_match.eval.metrics.coverage import (
    coverage,
    dilated_mask,
    valid_area_homography,
    valid_area_nonplanar,
)


def test_coverage_single_keypoint_is_disk_area():
    valid = np.zeros((300, 400), bool)
    valid[20:280, 30:370] = True
    pt = np.array([[200.0, 150.0]])
    cov = coverage(pt, pt, valid.shape, valid.shape, valid, valid, t=15)
    assert cov == pytest.approx(math.pi * 15**2 / valid.sum(), rel=0.01)
    # a keypoint outside the valid area of image 1 covers nothing there -> min is 0
    assert coverage(pt, np.array([[5.0, 5.0]]), valid.shape, valid.shape, valid, valid) == 0.0


def test_valid_area_homography():
    H = np.eye(3)
    H[0, 2] = 100.0  # image 0 shifted right by 100 px
    v0, v1 = valid_area_homography(H, (100, 200), (100, 200))
    assert v0.sum() == 100 * 100 and v0[:, :100].all() and not v0[:, 100:].any()
    assert v1[:, 100:].all() and not v1[:, :100].any()
    mask1 = np.zeros((100, 200), bool)
    mask1[:, 150:] = True
    v0, v1 = valid_area_homography(H, (100, 200), (100, 200), mask1=mask1)
    assert v0.sum() == 100 * 50 and v1.sum() == 100 * 50


def test_valid_area_nonplanar_union():
    v0, v1 = valid_area_nonplanar(
        [np.array([[50.0, 50.0]]), np.array([[150.0, 50.0]])],
        [np.zeros((0, 2)), np.zeros((0, 2))],
        (100, 200),
        (100, 200),
        gt_corrs=np.array([[0.0, 0.0, 100.0, 50.0]]),
        t=10,
    )
    assert v0[50, 50] and v0[50, 150] and v0[0, 0] and not v0[50, 100]
    assert v1[50, 100] and v1.sum() == dilated_mask(np.array([[100.0, 50.0]]), (100, 200), 10).sum()
