"""Blob matching against a brute-force reference on small random data."""

import subprocess
import sys

import numpy as np
import pytest
import torch

from slime_match.errors import ConfigError
from slime_match.matching import nn_kernels
from slime_match.matching.blob import BlobConfig, blob_match, greedy_many_to_many
from slime_match.matching.nn import knn


def reference_blob(d0, d1, xy0, xy1, k=10, p_n=3, radius=16.0):
    """Literal float64 implementation of ALGORITHMS.md section 3 (dense matrix, Python loops)."""
    dist = np.sqrt(((d0[:, None, :] - d1[None, :, :]) ** 2).sum(-1))
    n, m = dist.shape
    row_top = np.argsort(dist, axis=1, kind="stable")[:, :k]
    col_top = np.argsort(dist, axis=0, kind="stable")[:k, :]
    in_row = np.zeros((n, m), bool)
    in_col = np.zeros((n, m), bool)
    np.put_along_axis(in_row, row_top, True, axis=1)
    np.put_along_axis(in_col, col_top, True, axis=0)
    pairs = sorted(zip(*np.nonzero(in_row & in_col)), key=lambda ij: dist[ij])
    row_count, col_count, out = np.zeros(n, int), np.zeros(m, int), {}
    for i, j in pairs:
        if row_count[i] < p_n and col_count[j] < p_n:
            row_count[i] += 1
            col_count[j] += 1
            v = dist[i, j]
            far1 = np.linalg.norm(xy1 - xy1[j], axis=1) > radius
            far0 = np.linalg.norm(xy0 - xy0[i], axis=1) > radius
            v_r = dist[i, far1].min() if far1.any() else v
            v_c = dist[far0, j].min() if far0.any() else v
            out[(int(i), int(j))] = 2 * v / (v_r + v_c)
    return out


def make_data(n=80, m=90, dim=16, seed=0):
    """Descriptors with near-duplicate keypoints (same place, similar descriptor) and true partners."""
    g = np.random.default_rng(seed)
    d0 = g.normal(size=(n, dim))
    xy0 = g.uniform(0, 200, size=(n, 2))
    d0[1::4] = d0[0::4][: len(d0[1::4])] + 0.1 * g.normal(size=(len(d0[1::4]), dim))  # duplicates
    xy0[1::4] = xy0[0::4][: len(xy0[1::4])] + g.uniform(-2, 2, size=(len(xy0[1::4]), 2))
    d1 = np.concatenate([d0[:60] + 0.3 * g.normal(size=(60, dim)), g.normal(size=(m - 60, dim))])
    xy1 = np.concatenate([xy0[:60] * 0.9 + 10, g.uniform(0, 200, size=(m - 60, 2))])
    return d0, d1, xy0, xy1


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("block_size", [7, 1024])
def test_blob_matches_brute_force(seed, block_size):
    d0, d1, xy0, xy1 = make_data(seed=seed)
    ref = reference_blob(d0, d1, xy0, xy1)
    t = [torch.from_numpy(a).float() for a in (d0, d1, xy0, xy1)]
    res = blob_match(*t, BlobConfig(block_size=block_size))
    got = {(int(i), int(j)): s for i, j, s in zip(res.idx0, res.idx1, res.scores)}
    assert set(got) == set(ref)
    np.testing.assert_allclose([got[key] for key in ref], list(ref.values()), rtol=1e-4, atol=1e-5)
    assert np.all(np.diff(res.scores) >= 0)


def test_p_n_limit_and_shortlist_k():
    d0, d1, xy0, xy1 = make_data(seed=3)
    t = [torch.from_numpy(a).float() for a in (d0, d1, xy0, xy1)]
    for p_n in (1, 2, 3):
        res = blob_match(*t, BlobConfig(max_per_keypoint=p_n, shortlist_k=5))
        assert np.bincount(res.idx0).max() <= p_n and np.bincount(res.idx1).max() <= p_n
        ref = reference_blob(d0, d1, xy0, xy1, k=5, p_n=p_n)
        assert set(zip(res.idx0.tolist(), res.idx1.tolist())) == set(ref)
    # Identical descriptor groups: every pair is a tie-free candidate, p_n caps each keypoint.
    base = torch.eye(4).repeat_interleave(5, 0)
    res = blob_match(base + 0.01 * torch.arange(20)[:, None], base, torch.zeros(20, 2), torch.zeros(20, 2),
                     BlobConfig(max_per_keypoint=2))
    assert np.bincount(res.idx0, minlength=20).max() == 2 and np.bincount(res.idx1).max() <= 2


def test_greedy_many_to_many_order():
    rows = np.array([0, 0, 0, 1, 1])
    cols = np.array([0, 1, 2, 0, 1])
    vals = np.array([1.0, 2.0, 3.0, 0.5, 4.0])
    # p_n = 1: (1,0) first, then (0,0) blocked by column 0, (0,1) accepted, (0,2) blocked by row 0, (1,1) blocked.
    assert greedy_many_to_many(rows, cols, vals, 1).tolist() == [False, True, False, True, False]
    assert greedy_many_to_many(rows, cols, vals, 2).tolist() == [True, True, False, True, True]
    assert greedy_many_to_many(rows[:0], cols[:0], vals[:0], 2).tolist() == []


@pytest.mark.parametrize("p_n", [1, 3])
def test_greedy_many_to_many_reference(p_n):
    """Random distinct pairs with tied values against a Python loop over a stable argsort."""
    g = np.random.default_rng(p_n)
    pairs = np.unique(g.integers(0, 60, (3000, 2)), axis=0)
    pairs = pairs[g.permutation(len(pairs))]
    values = g.integers(0, 50, len(pairs)).astype(np.float32)
    row_count, col_count, ref = np.zeros(60, int), np.zeros(60, int), np.zeros(len(pairs), bool)
    for k in np.argsort(values, kind="stable"):
        i, j = pairs[k]
        if row_count[i] < p_n and col_count[j] < p_n:
            row_count[i] += 1
            col_count[j] += 1
            ref[k] = True
    np.testing.assert_array_equal(greedy_many_to_many(pairs[:, 0], pairs[:, 1], values, p_n), ref)


def test_shortlist_kernel_equals_index_membership():
    """The compiled shortlist against the torch expression that CUDA runs."""
    d0, d1, _, _ = make_data(seed=5)
    row_dist, row_idx, _, col_idx = knn(torch.from_numpy(d0).float(), torch.from_numpy(d1).float(), 10, 4)
    r_i = torch.arange(len(d0)).repeat_interleave(10)
    in_both = (col_idx[row_idx.flatten()] == r_i[:, None]).any(1)
    i, j, v = nn_kernels.shortlist(row_dist.numpy(), row_idx.numpy(), col_idx.numpy())
    assert in_both.sum() > 50
    np.testing.assert_array_equal(i, r_i[in_both].numpy())
    np.testing.assert_array_equal(j, row_idx.flatten()[in_both].numpy())
    np.testing.assert_array_equal(v, row_dist.flatten()[in_both].numpy())


def test_context_ratio_ignores_same_place_competitors():
    # Keypoint 0 of image 0 has two near-identical candidates in image 1: one duplicate detection 3 px
    # away from its partner (ignored) and one 100 px away (a real competitor).
    d0 = torch.tensor([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    d1 = torch.tensor([[1.0, 0.0, 0.0], [0.99, 0.14, 0.0], [0.0, 0.0, 1.0]])
    xy0 = torch.tensor([[10.0, 10.0], [100.0, 100.0]])
    same_place = torch.tensor([[50.0, 50.0], [53.0, 50.0], [150.0, 150.0]])
    res = blob_match(d0, d1, xy0, same_place)
    score = {(int(i), int(j)): s for i, j, s in zip(res.idx0, res.idx1, res.scores)}
    v01, v_c = float(torch.dist(d0[0], d1[1])), float(torch.dist(d0[1], d1[1]))
    assert score[(0, 0)] == pytest.approx(0.0, abs=1e-6)
    # Row competitor of (0, 1): d1[0] is 3 px from keypoint 1 (ignored), so v_r = |d0[0] - d1[2]| = sqrt 2.
    assert score[(0, 1)] == pytest.approx(2 * v01 / (np.sqrt(2.0) + v_c), rel=1e-4)
    far_place = same_place.clone()
    far_place[1] = torch.tensor([120.0, 50.0])
    res = blob_match(d0, d1, xy0, far_place)
    score_far = {(int(i), int(j)): s for i, j, s in zip(res.idx0, res.idx1, res.scores)}
    # 70 px apart, d1[0] becomes a competitor at distance 0: v_r = 0.
    assert score_far[(0, 1)] == pytest.approx(2 * v01 / (0.0 + v_c), rel=1e-4)
    assert score_far[(0, 1)] > score[(0, 1)]


def test_empty_and_device_and_config():
    e = torch.zeros(0, 8)
    assert len(blob_match(e, torch.rand(5, 8), torch.zeros(0, 2), torch.rand(5, 2))) == 0
    res = blob_match(torch.rand(1, 8), torch.rand(1, 8), torch.zeros(1, 2), torch.zeros(1, 2))
    assert len(res) == 1 and res.scores[0] == pytest.approx(1.0)  # no competitor: v_r = v_c = v
    with pytest.raises(ConfigError):
        blob_match(torch.rand(3, 8), torch.rand(3, 8), torch.rand(3, 2), torch.rand(3, 2), {"bogus": 1})
    with pytest.raises(ConfigError):
        BlobConfig(max_per_keypoint=0)


def test_every_device_matches_as_the_cpu(device):
    d0, d1, xy0, xy1 = make_data(seed=4)
    t = [torch.from_numpy(a).float() for a in (d0, d1, xy0, xy1)]
    cpu = blob_match(*t)
    other = blob_match(*[a.to(device) for a in t])
    assert set(zip(cpu.idx0.tolist(), cpu.idx1.tolist())) == set(zip(other.idx0.tolist(), other.idx1.tolist()))


_WARM_CHECK = """
import torch
from numba.core.registry import CPUDispatcher
from slime_match.matching import blob, nn_kernels
kernels = {n: k for n, k in vars(nn_kernels).items() if isinstance(k, CPUDispatcher)}
blob.warm_up()
loaded = {n: len(k.signatures) for n, k in kernels.items()}
g = torch.Generator().manual_seed(1)
d0, d1 = torch.rand(700, 128, generator=g), torch.rand(500, 128, generator=g)
blob.blob_match(d0, d1, torch.rand(700, 2, generator=g) * 300, torch.rand(500, 2, generator=g) * 300)
print(loaded == {n: len(k.signatures) for n, k in kernels.items()}, sum(loaded.values()))
"""


def test_warm_up_loads_what_blob_matching_calls():
    """After ``warm_up`` a real Blob matching call compiles nothing more (forked workers inherit them)."""
    out = subprocess.run([sys.executable, "-c", _WARM_CHECK], capture_output=True, text=True, check=True)
    same, loaded = out.stdout.split()
    assert same == "True" and int(loaded) >= 5  # rows, columns, shortlist, greedy, first far
