"""Orientation histograms: bins centred on multiples of 2 pi / bins, cyclic, the fullest bin's centre."""

import math

import numpy as np
import pytest

from slime_match.slime.orientations import (
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
