"""The bundled motorcycle stereo pair and its disparity ground truth."""

import numpy as np

from slime_match.eval.datasets import load_dataset
from slime_match.eval.metrics.correctness import correct_matches_disparity
from slime_match.geometry.fundamental import epipolar_distance


def test_motorcycle_disparity_pair():
    (p,) = load_dataset("motorcycle")
    assert p.kind == "disparity" and p.image0.shape == p.disparity.shape + (3,)
    rows, cols = np.nonzero(np.isfinite(p.disparity))
    x0 = np.stack([cols, rows], 1)[::997].astype(float)
    x1 = x0 - np.stack([p.disparity[rows, cols][::997], np.zeros(len(x0))], 1)
    assert correct_matches_disparity(x0, x1, p.disparity, t=0.5).all()
    assert epipolar_distance(p.F, x0, x1).max() < 1e-9
