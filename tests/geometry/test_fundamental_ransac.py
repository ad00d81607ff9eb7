"""Synthetic checks of the fundamental matrix RANSAC: known F among 50% outliers, two scene planes, one plane."""

import numpy as np
import pytest

from slime_match.geometry.fundamental_ransac import ransac_fundamental

from .helpers import check_fundamental, stereo_problem


@pytest.mark.parametrize("planes", [False, True])
def test_ransac_fundamental_recovers_f(planes):
    rng = np.random.default_rng(3)
    if planes:  # two scene planes: 8-point samples within one plane are degenerate
        a = stereo_problem(rng, 400, depth=(5.0, 5.0))
        b = stereo_problem(rng, 400, depth=(7.0, 7.0))
        x0, x1, gt = (np.r_[u, v] for u, v in zip(a, b, strict=True))
    else:
        x0, x1, gt = stereo_problem(rng, 1000)
    res = ransac_fundamental(x0, x1)
    check_fundamental(res, x0, x1, gt)
    assert res.info["source"] in ("8-point", "plane+parallax")


def test_ransac_fundamental_planar_without_parallax_returns_homography():
    rng = np.random.default_rng(4)
    x0, x1, _ = stereo_problem(rng, 300, ratio=0.0, depth=(5.0, 5.0))
    res = ransac_fundamental(x0, x1)
    assert res.kind == "homography" and res.info["source"] == "homography"
    assert res.inliers.mean() > 0.95
