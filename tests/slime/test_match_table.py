"""The match table: one row per block-pair match in original px, exact duplicates merged into weighted
rows."""


import numpy as np
import pytest

from slime_match.slime.match_table import deduplicate

from .helpers import make_table


def test_deduplicate_merges_exact_duplicates():
    xy0 = np.array([[1.0, 2.0], [1.0, 2.0], [5.0, 5.0], [1.0, 2.0 + 1e-9]])
    xy1 = np.array([[3.0, 4.0], [3.0, 4.0], [6.0, 6.0], [3.0, 4.0]])
    t = make_table(xy0, xy1, np.zeros(4), np.zeros(4), np.ones(4), np.ones(4))
    t.score = np.array([0.5, 0.2, 0.3, 0.9])
    d, inv = deduplicate(t)
    assert len(d) == 2
    assert inv[0] == inv[1] == inv[3] != inv[2]
    assert d.weight[inv[0]] == 3 and d.weight[inv[2]] == 1
    assert d.score[inv[0]] == pytest.approx(0.2)
    np.testing.assert_allclose(d.xy0[inv], t.xy0, atol=1e-6)
