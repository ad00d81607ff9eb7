"""Correct matches (planar, non-planar with local consistency, disparity) on synthetic and real cases."""

import numpy as np

from slime_match.eval.datasets import load_dataset
from slime_match.eval.metrics.correctness import (
    _locally_consistent,
    correct_matches_disparity,
    correct_matches_fundamental,
    correct_matches_homography,
    disparity_error,
)
from slime_match.geometry.homography import project

from .helpers import H_GT, rot


def test_homography_precision_exact_with_known_outliers():
    rng = np.random.default_rng(0)
    x0 = rng.uniform(50, 450, (100, 2))
    x1 = project(H_GT, x0)[0] + rng.normal(0, 1.0, (100, 2))
    out = rng.choice(100, 23, replace=False)
    x1[out] += rng.choice([-1, 1], (23, 2)) * rng.uniform(30, 100, (23, 2))
    ok = correct_matches_homography(x0, x1, H_GT)
    assert ok.sum() == 77 and not ok[out].any()
    assert correct_matches_homography(np.zeros((0, 2)), np.zeros((0, 2)), H_GT).shape == (0,)


def test_homography_threshold_boundary_and_masks():
    x0 = np.array([[100.0, 100.0], [200.0, 100.0], [300.0, 300.0]])
    x1 = x0 + [[14.9, 0.0], [15.1, 0.0], [0.0, 0.0]]
    assert correct_matches_homography(x0, x1, np.eye(3)).tolist() == [True, False, True]
    mask1 = np.zeros((400, 400), bool)
    mask1[290:310, 290:310] = True  # excluded area around the third match in image 1
    assert correct_matches_homography(x0, x1, np.eye(3), mask1=mask1).tolist() == [True, False, False]


def test_fundamental_epipolar_and_local_consistency():
    F = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0.0]])  # rectified: y1 == y0
    gx, gy = np.meshgrid(np.arange(0, 400, 40.0), np.arange(0, 400, 40.0))
    g0 = np.stack([gx.ravel(), gy.ravel()], 1)
    g1 = g0 * [1.2, 1.0] + [-30.0, 0.0]  # horizontal flow varying affinely
    corrs = np.concatenate([g0, g1], 1)
    x0 = np.array([[105.0, 205.0], [105.0, 205.0], [105.0, 205.0], [1000.0, 205.0]])
    exact = x0[0] * [1.2, 1.0] + [-30.0, 0.0]
    x1 = np.array([exact, exact + [40.0, 0.0], exact + [0.0, 20.0], [900.0, 205.0]])
    assert correct_matches_fundamental(x0, x1, F).tolist() == [True, True, False, True]
    # with GT: the second is on its epipolar line but off the local flow; the fourth has no GT nearby
    assert correct_matches_fundamental(x0, x1, F, gt_corrs=corrs).tolist() == [True, False, False, True]


def test_fundamental_local_consistency_under_rotation_and_scale():
    # GT flow = rotation by 60 degrees and scale 1.5 about (200, 200): the flow of the nearest GT point alone
    # differs by tens of px, the local affine model predicts exactly
    A = 1.5 * rot([0, 0, 1], 60)[:2, :2]
    warp = lambda p: (p - 200.0) @ A.T + 200.0
    rng = np.random.default_rng(3)
    g0 = rng.uniform(0, 400, (150, 2))
    x0 = rng.uniform(50, 350, (200, 2))
    x1 = warp(x0)
    assert _locally_consistent(x0, x1, g0, warp(g0), 15.0, 50.0, 8, 2).all()
    assert not _locally_consistent(x0, x1 + [25.0, 0.0], g0, warp(g0), 15.0, 50.0, 8, 2).any()


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
    assert correct_matches_fundamental(x0, slid, p.F).all()
    assert correct_matches_fundamental(x0, x1, p.F, gt_corrs=corrs).mean() > 0.9
    assert correct_matches_fundamental(x0, slid, p.F, gt_corrs=corrs).mean() < 0.12


def test_disparity_correctness():
    disp = np.full((50, 60), 10.0, np.float32)
    disp[:, 30:] = np.inf
    x0 = np.array([[20.0, 10.0], [20.0, 10.0], [40.0, 10.0]])
    x1 = np.array([[10.0, 10.0], [30.0, 10.0], [30.0, 10.0]])
    err = disparity_error(x0, x1, disp)
    assert err[0] == 0 and err[1] == 20 and np.isnan(err[2])
    assert correct_matches_disparity(x0, x1, disp).tolist() == [True, False, False]
