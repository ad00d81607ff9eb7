"""The tilt of matches (slime.match_tilt): the stretch of their robust global affine map."""

from __future__ import annotations

import numpy as np
import pytest

from slime_match.slime.match_tilt import AFFINE_TOLERANCE, match_tilt


def _rotation(degrees: float) -> np.ndarray:
    a = np.radians(degrees)
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


@pytest.mark.parametrize(("tilt", "angle"), [(1.0, 0.0), (1.4, 30.0), (3.0, 0.0), (6.0, 70.0)])
def test_the_tilt_of_an_affine_map_is_its_stretch_whatever_the_rotation_and_scale(tilt, angle):
    rng = np.random.default_rng(0)
    xy0 = rng.uniform(0, 600, (200, 2))
    linear = 0.7 * _rotation(25.0) @ np.diag([1.0 / tilt, 1.0]) @ _rotation(angle)
    xy1 = xy0 @ linear.T + [40.0, -15.0]
    outliers = np.arange(200) % 5 == 0  # a fifth of the matches anywhere in image 1
    xy1[outliers] = rng.uniform(0, 600, (outliers.sum(), 2))
    fit = match_tilt(xy0, xy1, (600, 600))
    assert fit.tilt == pytest.approx(tilt, rel=1e-6)
    assert fit.affine[:, :2] == pytest.approx(linear, abs=1e-6)
    far = np.linalg.norm(xy0 @ linear.T + [40.0, -15.0] - xy1, axis=1) > AFFINE_TOLERANCE * np.hypot(600, 600)
    assert np.array_equal(fit.inliers, ~far) and fit.support == int((~far).sum())


def test_fewer_than_three_matches_measure_no_tilt():
    fit = match_tilt(np.zeros((2, 2)), np.zeros((2, 2)), (100, 100))
    assert fit.affine is None and np.isnan(fit.tilt) and fit.support == 0 and fit.inliers.shape == (2,)
