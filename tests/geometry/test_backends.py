"""The robust estimators behind one interface: Slime's RANSAC, MAGSAC++ and PoseLib on known models."""

import sys

import numpy as np
import pytest

from slime_match.errors import ConfigError
from slime_match.geometry.backends import estimate_geometry

from .helpers import check_fundamental, check_homography, homography_problem, stereo_problem


@pytest.mark.parametrize("backend", ["slime", "magsac", "poselib"])
def test_backends_recover_known_models(backend):
    rng = np.random.default_rng(7)
    x0, x1, gt = homography_problem(rng, 400)
    res = estimate_geometry(x0, x1, "homography", backend, threshold=3.0)
    check_homography(res, x0, gt)
    x0, x1, gt = stereo_problem(rng, 600)
    res = estimate_geometry(x0, x1, "fundamental", backend, threshold=2.0)
    check_fundamental(res, x0, x1, gt)
    res = estimate_geometry(x0[:7], x1[:7], "fundamental", backend)
    assert res.model is None and res.inliers.shape == (7,) and not res.inliers.any()


def test_poselib_backend_without_poselib_is_a_clear_error(monkeypatch):
    """PoseLib is optional (the "poselib" extra): without it the package imports and the other backends run."""
    monkeypatch.setitem(sys.modules, "poselib", None)  # import poselib -> ImportError
    rng = np.random.default_rng(3)
    x0, x1, gt = homography_problem(rng, 200)
    check_homography(estimate_geometry(x0, x1, "homography", "slime", threshold=3.0), x0, gt)
    with pytest.raises(ConfigError, match="slime-match\\[poselib\\]"):
        estimate_geometry(x0, x1, "homography", "poselib", threshold=3.0)


def test_magsac_gives_no_model_where_opencv_asserts():
    """14 matches of a real pair (a base's matches with repeated keypoints) on which OpenCV's USAC raises an
    assertion error for a fundamental matrix instead of returning none: no model, no inlier."""
    x0 = np.array([[471.958, 4.104], [472.519, 4.557], [471.958, 4.104], [462.787, 63.789], [127.380, 261.052],
                   [471.102, 3.538], [472.247, 4.238], [102.754, 310.106], [141.092, 214.769], [127.380, 261.052],
                   [141.092, 214.769], [127.701, 261.234], [122.861, 205.808], [141.873, 215.191]])
    x1 = np.array([[3.611, 116.633], [5.834, 116.159], [4.709, 115.904], [121.753, 146.875], [279.935, 204.826],
                   [3.611, 116.633], [4.709, 115.904], [480.488, 287.750], [279.935, 204.826], [277.905, 206.681],
                   [277.905, 206.681], [279.935, 204.826], [279.449, 211.678], [277.905, 206.681]])
    res = estimate_geometry(x0, x1, "fundamental", "magsac", threshold=3.0)
    assert res.model is None and res.inliers.shape == (14,) and not res.inliers.any()
