"""The epipolar vote (Sec. 3.6) on a synthetic two-plane scene with a known F and a wrong plane."""

import numpy as np

from slime_match.geometry.fundamental import epipolar_distance, epipolar_distance_batch, fundamental_8point
from slime_match.slime import epipolar_vote
from slime_match.slime.epipolar_kernels import epipolar_votes
from slime_match.slime.epipolar_vote import epipolar_consistency, fundamental_from_moments

from .helpers import make_sets, make_table, two_plane_scene


def test_moments_fundamental_matches_eight_point():
    x0, x1, _ = two_plane_scene()
    idx = np.r_[0:30, 200:230]
    h0 = np.hstack([x0[idx], np.ones((60, 1))])
    h1 = np.hstack([x1[idx], np.ones((60, 1))])
    kk = (h1[:, :, None] * h0[:, None, :]).reshape(-1, 9)
    f = fundamental_from_moments((kk.T @ kk)[None])[0]
    assert abs(np.linalg.det(f)) < 1e-12
    f_ref = fundamental_8point(x0[idx], x1[idx])[0]
    f_ref = f_ref / np.linalg.norm(f_ref) * np.sign(np.sum(f_ref * f))
    assert np.abs(f - f_ref).max() < 1e-3  # RMS vs mean-distance normalisation: tiny difference
    assert epipolar_distance(f, x0[idx], x1[idx]).max() < 3.0


def test_epipolar_votes_count_the_fundamental_matrices_within_the_threshold():
    rng = np.random.default_rng(0)
    f = rng.normal(size=(7, 3, 3))
    x0, x1 = rng.uniform(-2, 2, (50, 2)), rng.uniform(-2, 2, (50, 2))
    votes = np.full(50, 3.0)  # added to, not overwritten
    epipolar_votes(f, np.ascontiguousarray(x0.T), np.ascontiguousarray(x1.T), 0.5**2, votes)
    expected = 3 + (epipolar_distance_batch(f, x0, x1) < 0.5).sum(0)
    np.testing.assert_array_equal(votes, expected)
    assert 3 < votes.mean() < 10  # some votes, not all


def test_epipolar_consistency_keeps_the_scene_and_drops_a_wrong_plane(monkeypatch):
    x0, x1, _ = two_plane_scene()
    n = 200
    table = make_table(x0, x1)
    rng = np.random.default_rng(1)
    rows = [rng.choice(np.arange(n) + (n if d >= 12 else 0), 40, replace=False) for d in range(24)]
    rows += [np.arange(2 * n, 2 * n + 40), np.arange(2 * n + 20, 2 * n + 60)]  # overlapping wrong sets
    d = len(rows)
    ts = make_sets(rows, len(table), tile0=np.arange(d) % 5, tile1=np.arange(d) % 7)
    keep = epipolar_consistency(table, ts)
    member = ts.union()
    assert keep[:400][member[:400]].all()
    assert not keep[400:].any()
    assert not keep[~member].any()
    # the vote threshold scales with |H|: with t_xi huge nothing survives
    assert not epipolar_consistency(table, ts, t_xi=100).any()
    # chunking does not change the result
    np.testing.assert_array_equal(epipolar_consistency(table, ts, chunk=5000), keep)
    # nor do threads, here sharing even the smallest chunks
    monkeypatch.setattr(epipolar_vote, "_THREADS_MIN_F", 1)
    monkeypatch.setattr(epipolar_vote, "_THREADS_MIN_TESTS", 1)
    np.testing.assert_array_equal(epipolar_consistency(table, ts, chunk=5000, threads=3), keep)
