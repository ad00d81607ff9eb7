"""The exact test for a 4-point sample passing the sample distance test, against every sample."""

import itertools

import numpy as np

from slime_match.geometry.ransac_kernels import far_samples
from slime_match.geometry.ransac_problems import _has_far_quadruple


def test_has_far_quadruple_brute_force():
    rng = np.random.default_rng(7)
    for n in range(4, 12):
        for spread in (20.0, 40.0, 80.0):
            x = rng.uniform(0, spread, (n, 4))
            samples = np.array(list(itertools.combinations(range(n), 4)))
            ref = bool(far_samples(x, np.zeros(len(samples), np.int64), samples, 15.0).any())
            assert _has_far_quadruple(x, 15.0) == ref, (n, spread)
