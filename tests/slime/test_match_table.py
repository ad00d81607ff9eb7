"""The match table: one row per block-pair match in original px, exact duplicates merged into weighted
rows."""

import math

import numpy as np
import pytest

from slime_match.slime.match_table import MatchTable, deduplicate

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


def test_deduplicate_sums_weights_and_keeps_the_first_rows_attributes():
    t = MatchTable([[0, 0], [4, 4], [0, 0]], [[1, 1], [5, 5], [1, 1]], [0.1, 0.2, 0.3], [0.4, 0.5, 0.6],
                   [1, 2, 3], [4, 5, 6], [2, 1, 0.5], [7, 8, 9], [0.9, 0.8, 0.7])
    d, inv = deduplicate(t)
    assert inv.tolist() == [0, 1, 0] and len(d) == 2
    assert d.weight.tolist() == [2.5, 1.0] and d.score.tolist() == [0.7, 0.8]
    assert d.angle0.tolist() == [0.1, 0.2] and d.scale1.tolist() == [4.0, 5.0] and d.source.tolist() == [7, 8]
    empty, inv = deduplicate(t.subset(np.zeros(3, bool)))
    assert len(empty) == 0 and inv.shape == (0,) and inv.dtype == np.int64


def test_match_table_rows_subsets_and_relative_orientations():
    t = make_table(np.arange(8.0).reshape(4, 2), np.ones((4, 2)), angle0=[0.0, 3.0, -3.0, 1.0],
                   angle1=[0.5, -3.0, 3.0, 1.0])
    assert len(t) == 4 and t.xy0.dtype == np.float64 and t.source.dtype == np.int64
    np.testing.assert_allclose(t.rho, [0.5, 2 * math.pi - 6.0, 6.0 - 2 * math.pi, 0.0], atol=1e-12)
    picked = t.subset(np.array([3, 1]))
    assert picked.xy0.tolist() == [[6.0, 7.0], [2.0, 3.0]] and picked.angle0.tolist() == [1.0, 3.0]
    assert len(t.subset(np.array([True, False, True, False]))) == 2
    with pytest.raises(ValueError, match="same length"):
        MatchTable(np.zeros((3, 2)), np.zeros((3, 2)), np.zeros(3), np.zeros(3), np.ones(3), np.ones(2),
                   np.ones(3), np.zeros(3), np.zeros(3))
