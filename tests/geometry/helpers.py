"""Helpers shared by the RANSAC tests: a known homography and stereo rig, problems with outliers, checks."""

import numpy as np
from scipy.spatial.transform import Rotation

from slime_match.geometry.fundamental import epipolar_distance
from slime_match.geometry.homography import project

H_TRUE = np.array([[1.1, 0.05, 20.0], [-0.03, 0.95, -10.0], [1e-4, 2e-4, 1.0]])
K_CAM = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
R_CAM = Rotation.from_rotvec([0.05, 0.2, 0.02]).as_matrix()
T_CAM = np.array([1.0, 0.1, 0.2])


def f_true():
    kinv = np.linalg.inv(K_CAM)
    t = T_CAM
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    f = kinv.T @ tx @ R_CAM @ kinv
    return f / np.linalg.norm(f)


def with_outliers(rng, x0, x1, ratio=0.5, noise=0.5):
    x1 = x1 + rng.normal(0, noise, x1.shape)
    out = rng.random(len(x0)) < ratio
    x1[out] = rng.uniform(0, 640, (out.sum(), 2))
    return x0, x1, ~out


def homography_problem(rng, n, h=H_TRUE, ratio=0.5):
    x0 = rng.uniform(0, 640, (n, 2))
    return with_outliers(rng, x0, project(h, x0)[0], ratio)


def stereo_problem(rng, n, ratio=0.5, depth=(4.0, 8.0)):
    pts = np.c_[rng.uniform(-2, 2, (n, 2)), rng.uniform(*depth, n)]
    p0 = pts @ K_CAM.T
    p1 = (pts @ R_CAM.T + T_CAM) @ K_CAM.T
    return with_outliers(rng, p0[:, :2] / p0[:, 2:], p1[:, :2] / p1[:, 2:], ratio, noise=0.3)


def check_homography(res, x0, gt, h=H_TRUE, max_false=0.02):
    assert res.kind == "homography" and res.model is not None
    grid = np.stack(np.meshgrid(np.linspace(0, 640, 5), np.linspace(0, 640, 5)), -1).reshape(-1, 2)
    assert np.abs(project(res.model, grid)[0] - project(h, grid)[0]).max() < 2.0
    assert (res.inliers & gt).sum() >= 0.95 * gt.sum()
    assert (res.inliers & ~gt).sum() <= max_false * (~gt).sum()


def check_fundamental(res, x0, x1, gt):
    assert res.kind == "fundamental" and res.model is not None
    assert epipolar_distance(res.model, x0[gt], x1[gt]).mean() < 1.0
    assert epipolar_distance(f_true(), x0[res.inliers], x1[res.inliers]).mean() < 2.0
    assert (res.inliers & gt).sum() >= 0.95 * gt.sum()
    assert (res.inliers & ~gt).sum() <= 0.05 * (~gt).sum()
