"""Orientation histograms: bins centred on multiples of 2 pi / bins, cyclic, the fullest bin's centre."""

import math

import numpy as np
import pytest

from slime_match.slime.orientations import (
    group_relative_orientation,
    orientation_bin,
    relative_orientation,
    wrap_angle,
)


def test_orientation_bin_centres_and_wrap():
    width = 2 * math.pi / 16
    assert orientation_bin(0.0, 16) == 0
    assert orientation_bin(0.49 * width, 16) == 0 and orientation_bin(0.51 * width, 16) == 1
    assert orientation_bin(-width, 16) == 15 and orientation_bin(2 * math.pi, 16) == 0
    assert orientation_bin(math.pi, 16) == 8


def test_relative_orientation_histogram():
    rng = np.random.default_rng(0)
    a0 = rng.uniform(-np.pi, np.pi, 200)
    rho = np.concatenate([np.full(120, math.radians(92.0)), rng.uniform(-np.pi, np.pi, 80)])
    assert relative_orientation(a0, a0 + rho) == pytest.approx(math.pi / 2)
    # cyclic: values around +-180 deg fall in the same bin
    r = relative_orientation(np.zeros(4), np.array([3.1, -3.1, 3.12, 0.5]))
    assert abs(wrap_angle(r - math.pi)) < 1e-12
    # upright pairs: 0 is a bin centre
    assert relative_orientation(np.zeros(5), np.full(5, 0.1)) == 0.0
    # weights decide
    assert relative_orientation(np.zeros(3), np.array([0.0, 1.0, 1.0]), weights=np.array([5, 1, 1])) == 0.0
    assert math.isnan(relative_orientation(np.zeros(0), np.zeros(0)))


def test_wrap_angle_is_half_open_at_minus_pi():
    got = wrap_angle(np.array([-math.pi, math.pi, 3 * math.pi, 0.5 + 2 * math.pi, -0.5, 0.0]))
    np.testing.assert_allclose(got, [math.pi, math.pi, math.pi, 0.5, -0.5, 0.0], atol=1e-12)
    assert np.all(got > -math.pi) and np.all(got <= math.pi)


def test_group_relative_orientation_per_group():
    """Each group's fullest bin (the lowest on ties, weights counted), NaN for an empty group; one group is
    ``relative_orientation``."""
    width = 2 * math.pi / 16
    rho = np.array([0.1, 0.05, 2 * width + 0.2, 3.1, -3.1, 5 * width, 6 * width, 6 * width - 0.1, 3 * width])
    group = np.array([0, 0, 0, 1, 1, 3, 3, 3, 4])
    weights = np.array([1, 1, 1, 1, 1, 1, 1, 1, 0.0])  # group 4's only entry weighs nothing
    got = group_relative_orientation(rho, group, 5, 16, weights)
    np.testing.assert_allclose(got[[0, 1, 3]], [0.0, math.pi, 6 * width], atol=1e-12)
    assert np.isnan(got[2]) and np.isnan(got[4])
    tie = group_relative_orientation(np.array([2 * width, width]), np.zeros(2, np.int64), 1)
    assert tie[0] == pytest.approx(width)  # a tie goes to the lowest bin
    for k in (0, 1, 3):
        members = group == k
        assert relative_orientation(np.zeros(members.sum()), rho[members], weights=weights[members]) == got[k]
