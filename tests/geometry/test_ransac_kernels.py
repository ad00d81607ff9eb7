"""The RANSACs' compiled loops (``geometry.ransac_kernels``) against numpy references on synthetic data."""

import itertools

import numpy as np

from slime_match.geometry.homography import homography_dlt_batch, project, two_sided_error_batch
from slime_match.geometry.ransac_kernels import (
    far_samples,
    floyd_subsets,
    inlier_counts,
    inlier_mask,
    minimal_homographies,
)

H_TRUE = np.array([[1.1, 0.05, 20.0], [-0.03, 0.95, -10.0], [1e-4, 2e-4, 1.0]])


def _floyd_numpy(u, n):
    k = len(u)
    out = np.empty((len(n), k), dtype=np.int64)
    for i in range(k):
        j = n - k + i
        t = np.minimum(np.floor(u[i] * (j + 1)).astype(np.int64), j)
        taken = (out[:, :i] == t[:, None]).any(axis=1)
        out[:, i] = np.where(taken, j, t)
    return out


def test_floyd_subsets_matches_numpy():
    rng = np.random.default_rng(0)
    for k in (1, 2, 4, 8):
        n = rng.integers(k, 3 * k, 5000)
        u = rng.random((k, len(n)))
        u[:, :3] = np.nextafter(1.0, 0.0)  # the largest uniform: t = j
        out = floyd_subsets(u, n)
        assert np.array_equal(out, _floyd_numpy(u, n))
        assert (np.sort(out, axis=1)[:, 1:] != np.sort(out, axis=1)[:, :-1]).all()
        assert ((out >= 0) & (out < n[:, None])).all()


def test_far_samples_matches_brute_force():
    rng = np.random.default_rng(1)
    rows = rng.uniform(0, 60, (30, 4))
    index = np.array(list(itertools.combinations(range(10), 4)))
    start = rng.integers(0, 20, len(index))
    pts = rows[start[:, None] + index]
    i, j = np.triu_indices(4, 1)
    d = pts[:, i] - pts[:, j]
    gap = np.sqrt(np.minimum(d[..., 0] ** 2 + d[..., 1] ** 2, d[..., 2] ** 2 + d[..., 3] ** 2))
    out = far_samples(rows, start, index, 15.0)
    assert np.array_equal(out, gap.min(axis=1) > 15.0)
    assert 0 < out.sum() < len(out)


def _samples(rng, count):
    x0 = rng.uniform(0, 640, (count, 4, 2))
    x1 = project(H_TRUE, x0.reshape(-1, 2))[0].reshape(count, 4, 2)
    x1[count // 2:] = rng.uniform(0, 640, (count - count // 2, 4, 2))  # arbitrary 4-point maps
    x0[:50, :, 1] = 0.5 * x0[:50, :, 0] + 3.0  # collinear in image 0: degenerate
    x0[50:60, 1] = x0[50:60, 0]  # a duplicated point: degenerate
    rows = np.concatenate([x0, x1], axis=-1).reshape(-1, 4)
    return x0, x1, rows, 4 * np.arange(count, dtype=np.int64), np.tile(np.arange(4), (count, 1))


def test_minimal_homographies_exact_and_as_the_numpy_dlt():
    rng = np.random.default_rng(2)
    x0, x1, rows, start, index = _samples(rng, 2000)
    h, ok = minimal_homographies(rows, start, index, 0.05)
    ref, sigma2 = homography_dlt_batch(x0, x1)
    clear = np.abs(sigma2 - 0.05) > 1e-6
    assert np.array_equal(ok[clear], sigma2[clear] >= 0.05)
    assert not ok[:60].any() and ok.sum() > 1000
    assert (h[~ok] == 0).all()
    sign = np.sign(np.einsum("mij,mij->m", h, ref))[:, None, None]
    assert np.abs(h - sign * ref)[ok].max() < 1e-9
    exact = ok.copy()
    exact[1000:] = False  # samples of H_TRUE: H up to scale
    assert np.abs(h[exact] / h[exact, 2:, 2:] - H_TRUE / H_TRUE[2, 2]).max() < 1e-8
    assert np.allclose(np.linalg.norm(h[ok], axis=(1, 2)), 1.0)
    assert minimal_homographies(rows, start, index, 0.0)[1].all()  # no degeneracy test


def test_inlier_kernels_match_the_two_sided_error():
    rng = np.random.default_rng(3)
    *_, rows, start, index = _samples(rng, 400)
    h, ok = minimal_homographies(rows, start, index, 0.05)
    h = h[ok]
    side = rng.choice([-1.0, 1.0], len(h))
    pts = rng.uniform(-200, 840, (300, 2))
    pts = np.c_[pts, project(H_TRUE, pts)[0] + rng.normal(0, 10, pts.shape)]
    err, w = two_sided_error_batch(h, pts[:, :2], pts[:, 2:])
    ref = (err < 15.0) & (w * side[:, None] > 0)
    n = rng.integers(0, len(pts) + 1, len(h))
    first = rng.integers(0, len(pts) - n + 1)
    counts = inlier_counts(h, side, pts, first, n, 15.0)
    assert np.array_equal(counts, [r[s:s + k].sum() for r, s, k in zip(ref, first, n, strict=True)])
    for m in range(0, len(h), 7):
        assert np.array_equal(inlier_mask(h[m], side[m], pts, 15.0), ref[m])
    assert ref.sum() > 1000
