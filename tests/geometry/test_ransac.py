"""Synthetic checks of the homography RANSAC (known H among 50% outliers, many problems at once) and of the
options both RANSACs share: degenerate inputs, determinism, config errors."""

import numpy as np
import pytest

from slime_match.errors import ConfigError
from slime_match.geometry.backends import estimate_geometry
from slime_match.geometry.fundamental_ransac import ransac_fundamental
from slime_match.geometry.homography import project, two_sided_error
from slime_match.geometry.ransac import (
    FundamentalRansacConfig,
    HomographyRansacConfig,
    ransac_homography,
    ransac_homography_many,
)

from .helpers import H_TRUE, check_homography, homography_problem, stereo_problem


def test_ransac_homography_recovers_h():
    rng = np.random.default_rng(0)
    x0, x1, gt = homography_problem(rng, 1000)
    res = ransac_homography(x0, x1)
    check_homography(res, x0, gt)
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
        x0, x1, gt = homography_problem(rng, [20, 60, 200, 500][i % 4], hs[i % 2], ratio=0.3)
        problems.append((x0, x1))
        truths.append((x0, gt, hs[i % 2]))
    problems.append((np.zeros((2, 2)), np.zeros((2, 2))))  # too small: empty result, no crash
    results = ransac_homography_many(problems)
    assert len(results) == 13
    for res, (x0, gt, h) in zip(results[:12], truths, strict=True):
        check_homography(res, x0, gt, h, max_false=0.1)
    assert results[12].model is None and results[12].inliers.shape == (2,)
    single = ransac_homography_many([problems[3]], seed=5)[0]
    assert np.array_equal(single.inliers, ransac_homography(*problems[3], seed=5).inliers)


def test_ransac_homography_many_clustered_problem_draws_to_the_cap():
    """A problem whose samples all fail the distance test: no model, max_iterations reported, others solved."""
    rng = np.random.default_rng(3)
    x0, x1, gt = homography_problem(rng, 200, ratio=0.3)
    cluster = rng.uniform(0, 10, (12, 2))
    results = ransac_homography_many([(cluster, cluster + 5), (x0, x1)])
    assert results[0].model is None and results[0].info["iterations"] == HomographyRansacConfig().max_iterations
    check_homography(results[1], x0, gt, max_false=0.1)


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
    x0, x1, _ = stereo_problem(rng, 300)
    a, b = ransac_fundamental(x0, x1, seed=11), ransac_fundamental(x0, x1, seed=11)
    assert np.array_equal(a.model, b.model) and np.array_equal(a.inliers, b.inliers)
    x0, x1, _ = homography_problem(rng, 300)
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
