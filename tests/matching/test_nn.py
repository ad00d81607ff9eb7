"""NN ratio, mutual NN and FGINN on constructed cases and against brute force."""

import numpy as np
import pytest
import torch

from slime_match.errors import ConfigError
from slime_match.matching import nn_kernels
from slime_match.matching.nn import (
    _smallest,
    _smallest_cols,
    knn,
    match_fginn,
    match_mutual_nn,
    match_mutual_nn_ratio,
    match_nn_ratio,
    nearest_far,
)


def dists(d0, d1):
    return torch.cdist(d0.double(), d1.double()).numpy()


def as_dict(m):
    return {(int(i), int(j)): s for i, j, s in zip(m.idx0, m.idx1, m.scores)}


def random_case(seed=0, n=70, m=60, dim=8):
    g = torch.Generator().manual_seed(seed)
    d1 = torch.randn(m, dim, generator=g)
    d0 = torch.cat([d1[:40] + 0.2 * torch.randn(40, dim, generator=g), torch.randn(n - 40, dim, generator=g)])
    xy1 = torch.rand(m, 2, generator=g) * 100
    xy1[1:20:2] = xy1[0:19:2] + 3  # near-duplicate keypoints in image 1, similar descriptors
    d1[1:20:2] = d1[0:19:2] + 0.05 * torch.randn(10, dim, generator=g)
    return d0, d1, torch.rand(n, 2, generator=g) * 100, xy1


def test_knn_rows_and_columns_blocked():
    d0, d1, _, _ = random_case()
    dm = dists(d0, d1)
    rd, ri, cd, ci = knn(d0, d1, 4, 3, block_size=9)
    np.testing.assert_array_equal(ri.numpy(), np.argsort(dm, 1)[:, :4])
    np.testing.assert_allclose(rd.numpy(), np.sort(dm, 1)[:, :4], rtol=1e-4, atol=1e-5)
    np.testing.assert_array_equal(ci.numpy(), np.argsort(dm, 0)[:3].T)
    np.testing.assert_allclose(cd.numpy(), np.sort(dm, 0)[:3].T, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("shape", [(30, 40), (50, 300), (7, 1000)])
def test_smallest_sorted_with_ties_to_the_lowest_index(shape):
    g = torch.Generator().manual_seed(shape[1])
    for d in (torch.rand(shape, generator=g), torch.randint(0, 6, shape, generator=g).float()):  # many ties
        for k in (1, 10, shape[1]):
            vals, idx = _smallest(d, k)
            order = np.argsort(d.numpy(), axis=1, kind="stable")[:, :k]
            np.testing.assert_array_equal(idx.numpy(), order)
            np.testing.assert_array_equal(vals.numpy(), np.take_along_axis(d.numpy(), order, 1))
    d[3, :] = float("nan")  # no bound: the torch.topk fallback
    assert _smallest(d, 5)[0].shape == (shape[0], 5)


def stable_smallest(a, k):
    """Reference: the first k of a stable ascending argsort of each row (NaN last)."""
    order = np.argsort(a, axis=1, kind="stable")[:, :k]
    return np.take_along_axis(a, order, 1), order


def assert_same(got, ref):
    """Equal values (bitwise, NaN included) and indices."""
    np.testing.assert_array_equal(got[0].view(np.int32), ref[0].view(np.int32))
    np.testing.assert_array_equal(got[1], ref[1])


@pytest.mark.parametrize("shape", [(1, 1), (5, 3), (40, 25), (60, 300), (300, 70)])
def test_kernels_match_stable_argsort(shape):
    """Rows and columns (without transposing) on random and tied inputs, for k from 1 to the whole line."""
    g = np.random.default_rng(shape[0] * shape[1])
    for d in (g.random(shape, np.float32), g.integers(0, 4, shape).astype(np.float32),  # many ties
              np.zeros(shape, np.float32), -g.random(shape, np.float32)):
        for k in {1, 2, 10, shape[1]}:
            *got, ok = nn_kernels.smallest_rows(d, min(k, shape[1]))
            assert ok
            assert_same(got, stable_smallest(d, min(k, shape[1])))
        for k in {1, 2, 10, shape[0]}:
            *got, ok = nn_kernels.smallest_cols(d, min(k, shape[0]))
            assert ok
            assert_same(got, stable_smallest(np.ascontiguousarray(d.T), min(k, shape[0])))
    vals, idx, ok = nn_kernels.smallest_rows(np.zeros(shape, np.float32), 0)
    assert ok and vals.shape == idx.shape == (shape[0], 0)


def test_kernels_nan_and_inf():
    """NaN sorts last; with fewer than k NaN-free groups of the entries equal mod 8k (the former search's
    bound is NaN) the kernels hand over to torch.topk."""
    g = np.random.default_rng(1)
    d = g.integers(0, 5, (30, 200)).astype(np.float32)
    d[g.random(d.shape) < 0.05] = np.inf
    d[2, [3, 50, 51, 120, 199]] = np.nan  # a few
    d[5, (np.arange(200) % 16 < 3)] = np.nan  # k = 2: one NaN-free group of 4 (no bound here), 13 of 16
    small = d[:, :12].copy()  # 8k >= M: everything ranked, NaN included
    for a, ks in ((d, (1, 2, 10, 20)), (small, (1, 5, 12))):
        for k in ks:
            *got, ok = nn_kernels.smallest_rows(a, k)
            assert ok
            assert_same(got, stable_smallest(a, k))
            *got, ok = nn_kernels.smallest_cols(np.ascontiguousarray(a.T), k)
            assert ok
            assert_same(got, stable_smallest(a, k))
            np.testing.assert_array_equal(_smallest(torch.from_numpy(a), k)[1].numpy(), stable_smallest(a, k)[1])
    d[7] = np.nan
    d[7, [7, 150]] = 1.0  # no NaN-free group of 80 (k = 10): torch.topk answers for the whole matrix
    assert not nn_kernels.smallest_rows(d, 10)[2] and not nn_kernels.smallest_cols(d.T.copy(), 10)[2]
    fallback = torch.topk(torch.from_numpy(d), 10, dim=1, largest=False, sorted=True)
    for got in (_smallest(torch.from_numpy(d), 10), _smallest_cols(torch.from_numpy(d.T.copy()), 10)):
        torch.testing.assert_close(got[0], fallback[0], equal_nan=True, rtol=0, atol=0)
        assert torch.equal(got[1], fallback[1])


@pytest.mark.parametrize("block_size", [1024, 50, 7])
def test_knn_ties_to_the_lowest_index(block_size):
    """Integer descriptors: exact float32 distances with many ties, rows and columns, one or many row blocks
    (the column lists of the blocks merged)."""
    g = np.random.default_rng(block_size)
    d0, d1 = g.integers(0, 3, (120, 4)), g.integers(0, 3, (90, 4))
    sq = ((d0[:, None, :] - d1[None, :, :]) ** 2).sum(-1)
    rd, ri, cd, ci = knn(torch.from_numpy(d0).float(), torch.from_numpy(d1).float(), 10, 12, block_size)
    ref_rows, ref_cols = stable_smallest(sq, 10), stable_smallest(np.ascontiguousarray(sq.T), 12)
    np.testing.assert_array_equal(ri.numpy(), ref_rows[1])
    np.testing.assert_array_equal(ci.numpy(), ref_cols[1])
    np.testing.assert_array_equal(rd.numpy(), np.sqrt(ref_rows[0]).astype(np.float32))
    np.testing.assert_array_equal(cd.numpy(), np.sqrt(ref_cols[0]).astype(np.float32))


def test_nearest_far_rows_equal_gathered_copies():
    d0, d1, _, xy1 = random_case(4)
    dist, idx, _, _ = knn(d0, d1, 3)
    rows = torch.tensor([5, 0, 5, 69, 12, 33])
    anchor = xy1[idx[rows, 0]]
    gathered = nearest_far(d0[rows], d1, xy1, anchor, 10.0, dist[rows], idx[rows], block_size=4)
    assert torch.equal(nearest_far(d0, d1, xy1, anchor, 10.0, dist, idx, block_size=4, rows=rows), gathered)
    dm = dists(d0, d1)
    for q, i in enumerate(rows.tolist()):
        far = np.linalg.norm(xy1.numpy() - anchor[q].numpy(), axis=1) > 10.0
        assert gathered[q].item() == pytest.approx(dm[i, far].min(), rel=1e-4)


def test_ratio_constructed_and_brute_force():
    d1 = torch.tensor([[1.0, 0.0], [0.0, 1.0], [0.0, 0.9]])
    d0 = torch.tensor([[0.9, 0.0], [0.0, 0.945]])  # row 0 distinctive; row 1 ambiguous (0.045 vs 0.055)
    res = as_dict(match_nn_ratio(d0, d1, 0.8))
    assert set(res) == {(0, 0)}
    assert res[(0, 0)] == pytest.approx(0.1 / np.hypot(0.9, 0.9), rel=1e-5)
    assert set(as_dict(match_nn_ratio(d0, d1, 1.0))) == {(0, 0), (1, 2)}
    d0, d1, _, _ = random_case(1)
    dm = np.sort(dists(d0, d1), 1)
    ref = {i for i in range(len(dm)) if dm[i, 0] / dm[i, 1] < 0.8}
    got = match_nn_ratio(d0, d1, 0.8)
    assert set(got.idx0.tolist()) == ref and np.all(np.diff(got.scores) >= 0)
    assert len(match_nn_ratio(d0, d1[:1])) == len(d0)  # one candidate: no competitor, ratio 0
    with pytest.raises(ConfigError):
        match_nn_ratio(d0, d1, 1.5)


def test_mutual_nn_brute_force():
    d0, d1, _, _ = random_case(2)
    dm = dists(d0, d1)
    ref = {(i, int(dm[i].argmin())) for i in range(len(dm)) if dm[:, dm[i].argmin()].argmin() == i}
    got = as_dict(match_mutual_nn(d0, d1, block_size=16))
    assert set(got) == ref and len(ref) > 10
    for (i, j), s in got.items():
        assert s == pytest.approx(dm[i, j], rel=1e-4, abs=1e-5)
    assert len(match_mutual_nn(torch.zeros(0, 8), d1)) == 0


def test_mutual_nn_ratio_constructed_and_brute_force():
    d1 = torch.tensor([[1.0, 0.0], [0.0, 1.0], [0.0, 0.9]])
    d0 = torch.tensor([[0.9, 0.0], [0.0, 0.945], [0.0, 0.5]])
    # row 0 distinctive; row 1 ambiguous (0.045 vs 0.055); row 2's nearest (column 2) prefers row 1: not mutual
    res = as_dict(match_mutual_nn_ratio(d0, d1, 0.8))
    assert set(res) == {(0, 0)} and res[(0, 0)] == pytest.approx(0.1 / np.hypot(0.9, 0.9), rel=1e-5)
    res = as_dict(match_mutual_nn_ratio(d0, d1, 1.0))
    assert set(res) == {(0, 0), (1, 2)} and res[(1, 2)] == pytest.approx(0.045 / 0.055, rel=1e-4)
    d0, d1, _, _ = random_case(3)
    dm = dists(d0, d1)
    order = np.sort(dm, 1)
    ref = {(i, int(dm[i].argmin())) for i in range(len(dm))
           if dm[:, dm[i].argmin()].argmin() == i and order[i, 0] / order[i, 1] < 0.9}
    got = match_mutual_nn_ratio(d0, d1, 0.9, block_size=16)
    assert set(as_dict(got)) == ref and len(ref) > 10 and np.all(np.diff(got.scores) >= 0)
    assert len(match_mutual_nn_ratio(torch.zeros(0, 8), d1)) == 0
    assert len(match_mutual_nn_ratio(d0[:1], d1[:1])) == 1  # one candidate: no competitor, ratio 0
    for ratio in (0, 1.5):
        with pytest.raises(ConfigError):
            match_mutual_nn_ratio(d0, d1, ratio)


@pytest.mark.parametrize("k", [2, 10])
@pytest.mark.parametrize("mutual", [False, True])
def test_fginn_brute_force(k, mutual):
    d0, d1, xy0, xy1 = random_case(3)
    dm = dists(d0, d1)
    geo = torch.cdist(xy1.double(), xy1.double()).numpy()
    ref = {}
    for i in range(len(dm)):
        j = int(dm[i].argmin())
        far = geo[j] > 10.0
        ratio = dm[i, j] / dm[i, far].min()
        if ratio < 0.8 and (not mutual or dm[:, j].argmin() == i):
            ref[(i, j)] = ratio
    got = as_dict(match_fginn(d0, d1, xy0, xy1, 0.8, 10.0, mutual=mutual, k=k))
    assert set(got) == set(ref)
    np.testing.assert_allclose([got[key] for key in ref], list(ref.values()), rtol=1e-4)


def test_fginn_ignores_same_place_competitor():
    d1 = torch.tensor([[1.0, 0.0, 0.0], [1.0, 0.105, 0.0], [0.0, 0.0, 1.0]])
    d0 = torch.tensor([[1.0, 0.05, 0.0]])  # d1[0] at 0.05, d1[1] at 0.055
    xy0 = torch.zeros(1, 2)
    near = torch.tensor([[0.0, 0.0], [4.0, 3.0], [50.0, 50.0]])  # second NN 5 px away: same place
    assert set(as_dict(match_fginn(d0, d1, xy0, near))) == {(0, 0)}
    assert len(match_nn_ratio(d0, d1)) == 0  # plain ratio rejects it
    far = near.clone()
    far[1] = torch.tensor([30.0, 0.0])
    assert len(match_fginn(d0, d1, xy0, far)) == 0
