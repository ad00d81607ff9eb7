"""The consensus fallback of the epipolar vote on a scene where most tile sets are wrong."""

import math

import numpy as np

from slime_match.geometry.fundamental import epipolar_distance
from slime_match.slime.consensus import epipolar_consensus
from slime_match.slime.epipolar_vote import epipolar_consistency

from .helpers import make_sets, make_table


def many_wrong_planes(correct=4, wrong=40, n=30, seed=0):
    """Matches of a 640 x 480 stereo pair: ``correct`` planes of n matches each (0.5 px noise) and ``wrong``
    sets of n matches each following a random similarity (rotated by 30-90 degrees); returns x0, x1, F, and
    the rows of each set."""
    rng = np.random.default_rng(seed)
    k = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    a = 0.2
    r = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    t = np.array([-1.0, 0.1, 0.05])
    xs0, xs1 = [], []
    for p in range(correct):
        normal = np.array([math.sin(0.4 * p - 0.6), 0.1 * p, math.cos(0.4 * p - 0.6)])
        uv = rng.uniform([20 + 150 * p, 20], [170 + 150 * p, 460], (n, 2))
        ray = np.linalg.inv(k) @ np.vstack([uv.T, np.ones(n)])
        x3 = (ray * ((4.0 + p) / (normal @ ray))).T
        p0, p1 = (k @ x3.T).T, (k @ (r @ x3.T + t[:, None])).T
        xs0.append(p0[:, :2] / p0[:, 2:] + rng.normal(0, 0.5, (n, 2)))
        xs1.append(p1[:, :2] / p1[:, 2:] + rng.normal(0, 0.5, (n, 2)))
    for _ in range(wrong):
        x0 = rng.uniform([20, 20], [620, 460], (n, 2))
        angle = rng.choice([-1, 1]) * rng.uniform(0.5, 1.5)  # rad
        c0, c1 = rng.uniform([100, 100], [540, 380], (2, 2))
        rot = rng.uniform(0.7, 1.4) * np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
        h = np.eye(3)
        h[:2, :2], h[:2, 2] = rot, c1 - rot @ c0
        x1 = np.hstack([x0, np.ones((n, 1))]) @ h.T
        xs0.append(x0)
        xs1.append(x1[:, :2] / x1[:, 2:])
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    f = np.linalg.inv(k).T @ tx @ r @ np.linalg.inv(k)
    rows = [np.arange(i * n, (i + 1) * n) for i in range(correct + wrong)]
    return np.vstack(xs0), np.vstack(xs1), f / np.linalg.norm(f), rows


def test_consensus_finds_the_geometry_the_vote_misses():
    x0, x1, f, rows = many_wrong_planes()
    table = make_table(x0, x1)
    d = len(rows)
    sets = make_sets(rows, len(table), tile0=np.arange(d) % 6, tile1=np.arange(d) % 5)
    assert not epipolar_consistency(table, sets).any()  # 4 correct sets of 44: the paper's vote keeps nothing
    found = epipolar_consensus(table, sets)
    correct = np.zeros(len(table), bool)
    correct[:120] = True
    assert found.planes == 4 and found.sets[:4].all() and not found.sets[4:].any()
    assert found.keep[:120].mean() > 0.95 and not found.keep[120:].any()
    assert np.median(epipolar_distance(found.F, x0[:120], x1[:120])) < 2.0
    assert abs(np.sum(found.F * f)) > 0.99  # both of unit norm: the true F up to sign
    # accepted only with enough distinct homographies: the correct sets as one plane cannot confirm an F
    one_plane = make_sets(rows, len(table), tile0=np.arange(d) % 6, tile1=np.arange(d) % 5,
                          plane=np.r_[np.zeros(4, int), np.arange(1, d - 3)])
    assert not epipolar_consensus(table, one_plane, min_planes=4).keep.any()
    assert not epipolar_consensus(table, sets, min_planes=5).keep.any()


def test_consensus_of_fewer_than_two_sets_is_empty():
    x0, x1, _, rows = many_wrong_planes(correct=1, wrong=0)
    table = make_table(x0, x1)
    found = epipolar_consensus(table, make_sets(rows, len(table), tile0=[0], tile1=[0]))
    assert found.F is None and not found.keep.any() and found.planes == 0
