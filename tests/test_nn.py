"""NN ratio, mutual NN and FGINN on constructed cases and against brute force."""

import numpy as np
import pytest
import torch

from slime_match.errors import ConfigError
from slime_match.matching.nn import _smallest, knn, match_fginn, match_mutual_nn, match_nn_ratio


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
