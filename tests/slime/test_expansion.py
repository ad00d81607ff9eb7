"""Plane expansion and match pruning (Sec. 3.4) on synthetic planes with exact answers."""

import math

import numpy as np
import pytest
import scipy.sparse as sp

from slime_match.errors import ConfigError
from slime_match.geometry.homography import two_sided_error
from slime_match.slime.expansion import Expansion, PlaneConfig, expand_planes

from .helpers import make_table


def _project(h, x):
    p = np.hstack([x, np.ones((len(x), 1))]) @ h.T
    return p[:, :2] / p[:, 2:]






def _scene():
    """Two planes with known H, patches consistent with their plane or deliberately inconsistent."""
    rng = np.random.default_rng(1)
    c, s = math.cos(0.4), math.sin(0.4)
    h_a = np.array([[1.1 * c, -1.1 * s, 40.0], [1.1 * s, 1.1 * c, -20.0], [1e-5, 2e-5, 1.0]])
    h_b = np.array([[0.7, 0.05, 300.0], [-0.02, 0.75, 100.0], [0.0, 0.0, 1.0]])
    n = 40
    xa = rng.uniform(0, 400, (n, 2))
    xb = rng.uniform(0, 400, (n, 2))
    x0 = np.vstack([xa, xb])
    x1 = np.vstack([_project(h_a, xa), _project(h_b, xb)]) + rng.uniform(-3, 3, (2 * n, 2))
    rho = np.concatenate([np.full(n, 0.4), np.full(n, 0.0)])  # plane A rotates by 0.4 rad, B by ~0
    psi = np.concatenate([np.full(n, 1.1), np.full(n, 0.72)])
    a0 = rng.uniform(-np.pi, np.pi, 2 * n)
    s0 = rng.uniform(2, 10, 2 * n)
    kind = np.zeros(2 * n, int)  # 0 consistent, 1 bad orientation, 2 bad scale
    kind[[3, 7, 45, 50]] = 1
    kind[[5, 11, 60]] = 2
    rho = np.where(kind == 1, rho + np.pi, rho)  # patches upside down
    psi = np.where(kind == 2, psi * 5.0, psi)
    # outliers: random positions
    xo0, xo1 = rng.uniform(0, 400, (30, 2)), rng.uniform(0, 700, (30, 2))
    t = make_table(
        np.vstack([x0, xo0]),
        np.vstack([x1, xo1]),
        np.concatenate([a0, np.zeros(30)]),
        np.concatenate([a0 + rho, np.zeros(30)]),
        np.concatenate([s0, np.ones(30)]),
        np.concatenate([s0 * psi, np.ones(30)]),
    )
    return t, np.stack([h_a, h_b]), n, np.concatenate([kind, np.zeros(30, int)])


def test_expand_planes_exact_sets():
    t, h, n, kind = _scene()
    p = expand_planes(t, h, np.ones(2)).toarray()
    assert p.shape == (2, len(t))
    for l in range(2):
        err = two_sided_error(h[l], t.xy0, t.xy1)
        plane = np.zeros(len(t), bool)
        plane[l * n : (l + 1) * n] = True
        expected = (err < 15) & (kind == 0)
        # the geometric part must agree exactly with the geometry module's two-sided error
        np.testing.assert_array_equal(p[l], expected)
        assert p[l, plane & (kind == 0)].all() and not p[l, plane & (kind > 0)].any()
    # each plane's own consistent matches are in, the other plane's matches are out
    assert not p[0, n : 2 * n].any() and not p[1, :n].any()


def test_expand_planes_plane_side_and_literal_scale_mode():
    t, h, n, kind = _scene()
    assert expand_planes(t, h, -np.ones(2)).nnz == 0  # every match is on the + side
    # literal paper equation: only the homography's own scale is bounded -> bad-scale patches pass
    p = expand_planes(t, h, np.ones(2), PlaneConfig(relative_scale="homography")).toarray()
    assert p[0, :n][kind[:n] == 2].all()
    assert not p[0, :n][kind[:n] == 1].any()
    # a zoom of 4 violates t_sigma = 3 in "homography" mode whatever the patches say
    z = np.diag([4.0, 4.0, 1.0])
    xy0 = np.array([[10.0, 10.0], [20.0, 30.0]])
    tz = make_table(xy0, 4 * xy0 + 1.5, np.zeros(2), np.zeros(2), np.ones(2), np.full(2, 4.0))
    assert expand_planes(tz, z[None], [1], PlaneConfig(relative_scale="homography")).nnz == 0
    assert expand_planes(tz, z[None], [1]).nnz == 2
    with pytest.raises(ConfigError):
        PlaneConfig(relative_scale="nope")


def _expand_reference(t, h, side, config):
    """Sec. 3.4 pair by pair, as the expand_planes docstring states it (slow, plain Python)."""
    steps = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)]

    def apply(m, x):
        q = m @ np.array([x[0], x[1], 1.0])
        return q[:2] / q[2], q[2]

    def local(m, x, rho, psi):
        qx, _ = apply(m, x)
        rot = scale = False
        for dx, dy in steps:
            d = apply(m, (x[0] + dx, x[1] + dy))[0] - qx
            diff = rho - (math.atan2(d[1], d[0]) - math.atan2(dy, dx))
            rot |= abs(math.remainder(diff, 2 * math.pi)) < config.t_theta
            scale |= 1 / config.t_sigma <= math.hypot(*d) / psi <= config.t_sigma
        return rot, scale

    out = np.zeros((len(h), len(t)), bool)
    for l, m in enumerate(h):
        for i in range(len(t)):
            x0, x1 = t.xy0[i], t.xy1[i]
            q1, w = apply(m, x0)
            q0, _ = apply(np.linalg.inv(m), x1)
            if max(np.linalg.norm(q1 - x1), np.linalg.norm(q0 - x0)) >= config.t_perp or np.sign(w) != side[l]:
                continue
            psi = t.scale1[i] / t.scale0[i] if config.relative_scale == "patch" else 1.0
            rot0, sc0 = local(m, x0, t.rho[i], psi)
            rot1, sc1 = local(np.linalg.inv(m), x1, -t.rho[i], 1 / psi)
            out[l, i] = (rot0 or rot1) and (sc0 or sc1)
    return out


@pytest.mark.parametrize("mode", ["patch", "homography"])
def test_expand_planes_equals_the_pair_by_pair_rule(mode):
    """Random matches around 8 nearby planes (some seen from the other side): the compiled pass gives the
    memberships of the plain rule (thousands of them: the output buffers grow)."""
    g = np.random.default_rng(4)
    m = 600
    base = np.array([[1.1, 0.1, 20.0], [-0.05, 0.9, 10.0], [2e-4, -1e-4, 1.0]])
    h = np.stack([base + g.normal(0, 1, (3, 3)) * [[0.02, 0.02, 3.0], [0.02, 0.02, 3.0], [1e-5, 1e-5, 0]]
                  for _ in range(8)])
    xy0 = g.uniform(0, 400, (m, 2))
    y = np.c_[xy0, np.ones(m)] @ base.T
    xy1 = y[:, :2] / y[:, 2:] + g.normal(0, 8, (m, 2))
    angle0 = g.uniform(-np.pi, np.pi, m)
    t = make_table(xy0, xy1, angle0, angle0 + g.normal(0, 1.0, m), np.ones(m), np.exp(g.normal(0, 1.0, m)))
    side = np.array([1, 1, 1, -1, 1, 1, 1, 1.0])
    config = PlaneConfig(relative_scale=mode)
    ref = _expand_reference(t, h, side, config)
    assert 1024 < ref.sum() < ref.size - 600 and not ref[3].any()
    for threads in (1, 3):  # 3 threads: the 8 planes in 8 parts of one (np.linspace bounds)
        got = expand_planes(t, h, side, config, threads=threads)
        np.testing.assert_array_equal(got.toarray(), ref)
        assert got.has_canonical_format


def test_expansion_counts_and_arrays():
    """Sec. 3.4's result: the memberships' count, and each (plane, match) membership for ``--save-stages``."""
    memberships = sp.csr_matrix(np.array([[1, 0, 1, 0], [0, 0, 0, 0], [0, 1, 1, 1]], bool))
    expansion = Expansion(memberships)
    assert expansion.counts == {"expanded_memberships": 5}
    arrays = expansion.arrays()
    assert sorted(arrays) == ["expanded_match", "expanded_plane"]
    assert arrays["expanded_plane"].tolist() == [0, 0, 2, 2, 2]
    assert arrays["expanded_match"].tolist() == [0, 2, 1, 2, 3]
    assert arrays["expanded_plane"].dtype == np.int64 and arrays["expanded_match"].dtype == np.int64
    nothing = Expansion(expand_planes(make_table(np.zeros((0, 2)), np.zeros((0, 2))), np.eye(3)[None], [1]))
    assert nothing.memberships.shape == (1, 0) and nothing.counts == {"expanded_memberships": 0}
    assert all(len(a) == 0 for a in nothing.arrays().values())
