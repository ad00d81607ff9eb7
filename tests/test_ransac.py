"""Synthetic RANSAC checks: known H / F among 50% outliers, degenerate inputs, determinism, backends."""

import itertools
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from slime_match.errors import ConfigError
from slime_match.geometry.backends import estimate_geometry
from slime_match.geometry.fundamental import epipolar_distance
from slime_match.geometry.homography import project, two_sided_error
from slime_match.geometry.ransac import (
    FundamentalRansacConfig,
    HomographyRansacConfig,
    _has_far_quadruple,
    ransac_fundamental,
    ransac_homography,
    ransac_homography_many,
)
from slime_match.geometry.ransac_kernels import far_samples

H_TRUE = np.array([[1.1, 0.05, 20.0], [-0.03, 0.95, -10.0], [1e-4, 2e-4, 1.0]])
K_CAM = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
R_CAM = Rotation.from_rotvec([0.05, 0.2, 0.02]).as_matrix()
T_CAM = np.array([1.0, 0.1, 0.2])


def _f_true():
    kinv = np.linalg.inv(K_CAM)
    t = T_CAM
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    f = kinv.T @ tx @ R_CAM @ kinv
    return f / np.linalg.norm(f)


def _with_outliers(rng, x0, x1, ratio=0.5, noise=0.5):
    x1 = x1 + rng.normal(0, noise, x1.shape)
    out = rng.random(len(x0)) < ratio
    x1[out] = rng.uniform(0, 640, (out.sum(), 2))
    return x0, x1, ~out


def _homography_problem(rng, n, h=H_TRUE, ratio=0.5):
    x0 = rng.uniform(0, 640, (n, 2))
    return _with_outliers(rng, x0, project(h, x0)[0], ratio)


def _stereo_problem(rng, n, ratio=0.5, depth=(4.0, 8.0)):
    pts = np.c_[rng.uniform(-2, 2, (n, 2)), rng.uniform(*depth, n)]
    p0 = pts @ K_CAM.T
    p1 = (pts @ R_CAM.T + T_CAM) @ K_CAM.T
    return _with_outliers(rng, p0[:, :2] / p0[:, 2:], p1[:, :2] / p1[:, 2:], ratio, noise=0.3)


def _check_homography(res, x0, gt, h=H_TRUE, max_false=0.02):
    assert res.kind == "homography" and res.model is not None
    grid = np.stack(np.meshgrid(np.linspace(0, 640, 5), np.linspace(0, 640, 5)), -1).reshape(-1, 2)
    assert np.abs(project(res.model, grid)[0] - project(h, grid)[0]).max() < 2.0
    assert (res.inliers & gt).sum() >= 0.95 * gt.sum()
    assert (res.inliers & ~gt).sum() <= max_false * (~gt).sum()


def _check_fundamental(res, x0, x1, gt):
    assert res.kind == "fundamental" and res.model is not None
    assert epipolar_distance(res.model, x0[gt], x1[gt]).mean() < 1.0
    assert epipolar_distance(_f_true(), x0[res.inliers], x1[res.inliers]).mean() < 2.0
    assert (res.inliers & gt).sum() >= 0.95 * gt.sum()
    assert (res.inliers & ~gt).sum() <= 0.05 * (~gt).sum()


def test_ransac_homography_recovers_h():
    rng = np.random.default_rng(0)
    x0, x1, gt = _homography_problem(rng, 1000)
    res = ransac_homography(x0, x1)
    _check_homography(res, x0, gt)
    assert res.info["iterations"] >= 100
    w = project(res.model, x0[res.inliers])[1]
    assert (w > 0).all()  # inliers are on the positive side of the returned model
    assert (two_sided_error(res.model, x0[res.inliers], x1[res.inliers]) < 15.0).all()


def test_ransac_homography_rejects_points_behind_the_plane():
    h = np.array([[1.0, 0, 0], [0, 1, 0], [0.004, 0, 1]])  # vanishing line x = -250
    rng = np.random.default_rng(1)
    x0 = rng.uniform(0, 400, (200, 2))
    x1 = project(h, x0)[0]
    behind = np.array([[-450.0, 100.0], [-600.0, 300.0]])  # mapped through infinity, w < 0
    x0b, x1b = np.r_[x0, behind], np.r_[x1, project(h, behind)[0]]
    res = ransac_homography(x0b, x1b)
    assert res.inliers[:200].all() and not res.inliers[200:].any()


def test_ransac_homography_many_matches_single_runs():
    rng = np.random.default_rng(2)
    hs = [H_TRUE, np.array([[0.9, -0.2, 50.0], [0.15, 1.05, 5.0], [-2e-4, 1e-4, 1.0]])]
    problems, truths = [], []
    for i in range(12):
        x0, x1, gt = _homography_problem(rng, [20, 60, 200, 500][i % 4], hs[i % 2], ratio=0.3)
        problems.append((x0, x1))
        truths.append((x0, gt, hs[i % 2]))
    problems.append((np.zeros((2, 2)), np.zeros((2, 2))))  # too small: empty result, no crash
    results = ransac_homography_many(problems)
    assert len(results) == 13
    for res, (x0, gt, h) in zip(results[:12], truths, strict=True):
        _check_homography(res, x0, gt, h, max_false=0.1)
    assert results[12].model is None and results[12].inliers.shape == (2,)
    single = ransac_homography_many([problems[3]], seed=5)[0]
    assert np.array_equal(single.inliers, ransac_homography(*problems[3], seed=5).inliers)


def test_has_far_quadruple_brute_force():
    rng = np.random.default_rng(7)
    for n in range(4, 12):
        for spread in (20.0, 40.0, 80.0):
            x = rng.uniform(0, spread, (n, 4))
            samples = np.array(list(itertools.combinations(range(n), 4)))
            ref = bool(far_samples(x, np.zeros(len(samples), np.int64), samples, 15.0).any())
            assert _has_far_quadruple(x, 15.0) == ref, (n, spread)


def test_ransac_homography_many_clustered_problem_draws_to_the_cap():
    """A problem whose samples all fail the distance test: no model, max_iterations reported, others solved."""
    rng = np.random.default_rng(3)
    x0, x1, gt = _homography_problem(rng, 200, ratio=0.3)
    cluster = rng.uniform(0, 10, (12, 2))
    results = ransac_homography_many([(cluster, cluster + 5), (x0, x1)])
    assert results[0].model is None and results[0].info["iterations"] == HomographyRansacConfig().max_iterations
    _check_homography(results[1], x0, gt, max_false=0.1)


@pytest.mark.parametrize("planes", [False, True])
def test_ransac_fundamental_recovers_f(planes):
    rng = np.random.default_rng(3)
    if planes:  # two scene planes: 8-point samples within one plane are degenerate
        a = _stereo_problem(rng, 400, depth=(5.0, 5.0))
        b = _stereo_problem(rng, 400, depth=(7.0, 7.0))
        x0, x1, gt = (np.r_[u, v] for u, v in zip(a, b, strict=True))
    else:
        x0, x1, gt = _stereo_problem(rng, 1000)
    res = ransac_fundamental(x0, x1)
    _check_fundamental(res, x0, x1, gt)
    assert res.info["source"] in ("8-point", "plane+parallax")


def test_ransac_fundamental_planar_without_parallax_returns_homography():
    rng = np.random.default_rng(4)
    x0, x1, _ = _stereo_problem(rng, 300, ratio=0.0, depth=(5.0, 5.0))
    res = ransac_fundamental(x0, x1)
    assert res.kind == "homography" and res.info["source"] == "homography"
    assert res.inliers.mean() > 0.95


@pytest.mark.parametrize("kind", ["homography", "fundamental"])
def test_degenerate_inputs_give_empty_results(kind):
    rng = np.random.default_rng(5)
    fit = ransac_homography if kind == "homography" else ransac_fundamental
    t = np.linspace(0, 500, 60)
    line0 = np.c_[t, 0.5 * t + 10]
    line1 = np.c_[2 * t + 3, -t + 400]
    dup = np.repeat(rng.uniform(0, 640, (1, 2)), 30, axis=0)
    few = 3 if kind == "homography" else 7
    for x0, x1 in [
        (line0, line1),
        (dup, dup + 5.0),
        (line0[:few], line1[:few]),
        (np.zeros((0, 2)), np.zeros((0, 2))),
    ]:
        res = fit(x0, x1, {"max_iterations": 1000})
        assert res.model is None and res.inliers.shape == (len(x0),) and not res.inliers.any()


def test_deterministic_under_seed():
    rng = np.random.default_rng(6)
    x0, x1, _ = _stereo_problem(rng, 300)
    a, b = ransac_fundamental(x0, x1, seed=11), ransac_fundamental(x0, x1, seed=11)
    assert np.array_equal(a.model, b.model) and np.array_equal(a.inliers, b.inliers)
    x0, x1, _ = _homography_problem(rng, 300)
    a, b = ransac_homography(x0, x1, seed=11), ransac_homography(x0, x1, seed=11)
    assert np.array_equal(a.model, b.model) and a.info == b.info


def test_config_errors():
    x = np.zeros((10, 2))
    with pytest.raises(ConfigError):
        ransac_homography(x, x, {"treshold": 3.0})
    with pytest.raises(ConfigError):
        ransac_fundamental(x, x, FundamentalRansacConfig(confidence=1.5))
    with pytest.raises(ConfigError):
        ransac_homography(x, x, HomographyRansacConfig(min_iterations=0))
    with pytest.raises(ConfigError):
        estimate_geometry(x, x, "homography", backend="ransac")
    with pytest.raises(ConfigError):
        estimate_geometry(x, x, "affine")


@pytest.mark.parametrize("backend", ["slime", "magsac", "poselib"])
def test_backends_recover_known_models(backend):
    rng = np.random.default_rng(7)
    x0, x1, gt = _homography_problem(rng, 400)
    res = estimate_geometry(x0, x1, "homography", backend, threshold=3.0)
    _check_homography(res, x0, gt)
    x0, x1, gt = _stereo_problem(rng, 600)
    res = estimate_geometry(x0, x1, "fundamental", backend, threshold=2.0)
    _check_fundamental(res, x0, x1, gt)
    res = estimate_geometry(x0[:7], x1[:7], "fundamental", backend)
    assert res.model is None and res.inliers.shape == (7,) and not res.inliers.any()


def test_poselib_backend_without_poselib_is_a_clear_error(monkeypatch):
    """PoseLib is optional (the "poselib" extra): without it the package imports and the other backends run."""
    monkeypatch.setitem(sys.modules, "poselib", None)  # import poselib -> ImportError
    rng = np.random.default_rng(3)
    x0, x1, gt = _homography_problem(rng, 200)
    _check_homography(estimate_geometry(x0, x1, "homography", "slime", threshold=3.0), x0, gt)
    with pytest.raises(ConfigError, match="slime-match\\[poselib\\]"):
        estimate_geometry(x0, x1, "homography", "poselib", threshold=3.0)
