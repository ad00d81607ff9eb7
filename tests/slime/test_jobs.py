"""Slime's job runner: work split into pieces and RANSAC batches that do not depend on the workers, and what
a CUDA pipeline keeps in one process."""

import copy
import os
from types import SimpleNamespace

import numpy as np
import torch

from slime_match.geometry.ransac import HomographyRansacConfig
from slime_match.slime.jobs import (
    device_workers,
    features_from_numpy,
    features_to_numpy,
    joined,
    match_jobs,
    pair_workers,
    piece_size,
    pieces_of,
    ransac_batches,
    uses_cuda,
)
from slime_match.slime.pipeline import _workers
from slime_match.types import Features


def test_pieces_cover_the_set_at_multiples_of_the_batch():
    assert piece_size(10_000, 256, 1) == 10_000 and piece_size(10_000, None, 8) == 10_000
    assert piece_size(0, 256, 1) == 1 and piece_size(100, 256, 16) == 256
    assert piece_size(10_000, 256, 2) == 256 * 5  # about a quarter of an even share: 10,000 / 8 = 1250
    for count, size in ((0, 256), (1, 256), (256, 256), (257, 256), (10_000, 1280)):
        pieces = pieces_of(count, size)
        assert [i for piece in pieces for i in range(count)[piece]] == list(range(count))
        assert all(piece.start % size == 0 and piece.stop - piece.start <= size for piece in pieces)
    assert pieces_of(0, 256) == [slice(0, 0)]


def test_match_jobs_of_a_cuda_pipeline_equal_one_process(levels):
    """On CUDA, ``match_jobs`` copies the jobs' features to the CPU before forking: the same matches and
    positions as one process, or forked on the CPU. The CPU pipeline stands in for a CUDA one: its ``device``
    is all that ``match_jobs`` reads to choose."""
    pipeline, blocks, _, shared, per_block = levels
    own = [shared[0].features.subset(torch.from_numpy(m)) for m in shared[0].members]
    jobs = [(own[i], per_block[j].features, blocks[i], blocks[j], None) for i in range(2) for j in range(2)]
    jobs += [(own[0], per_block[0].features, blocks[0], blocks[0], lambda y0, y1: y0[:, 0] < 120), None]
    cuda_like = copy.copy(pipeline)
    cuda_like.device = torch.device("cuda")
    runs = [match_jobs(p, len(jobs), jobs.__getitem__, w) for p, w in ((pipeline, 1), (pipeline, 2), (cuda_like, 2))]
    assert len(runs[0][0][0]) > 15 and len(runs[0][5][0]) == 0
    assert len(runs[0][4][0]) > 0 and not np.array_equal(runs[0][4][0].idx0, runs[0][0][0].idx0)  # filtered
    for other in runs[1:]:
        for (m, xy0, xy1), (n, yy0, yy1) in zip(runs[0], other, strict=True):
            assert np.array_equal(m.idx0, n.idx0) and np.array_equal(m.idx1, n.idx1)
            assert np.array_equal(m.scores, n.scores) and np.array_equal(xy0, yy0) and np.array_equal(xy1, yy1)


def test_ransac_batches_do_not_depend_on_the_workers():
    """Batches of RANSAC_BATCH problems, each its own seeded batched RANSAC: any number of workers gives the
    same planes, and they find the true homography of every problem with enough inliers."""
    g = np.random.default_rng(2)
    h = np.array([[1.1, 0.05, 10.0], [-0.02, 0.95, -5.0], [1e-4, 0.0, 1.0]])
    problems = []
    for k in range(120):
        x0 = g.uniform(0, 256, (30 + k % 40, 2))
        y = np.c_[x0, np.ones(len(x0))] @ h.T
        x1 = y[:, :2] / y[:, 2:]
        angle = g.uniform(0, 2 * np.pi, len(x0) // 3)
        x1[: len(x0) // 3] += 40 * np.c_[np.cos(angle), np.sin(angle)]  # a third are outliers, 40 px off
        problems.append((x0, x1))
    config = HomographyRansacConfig(threshold=3.0)
    one, two = ransac_batches(problems, config, 0, 1), ransac_batches(problems, config, 0, 2)
    assert len(one) == len(problems)
    for a, b, (x0, _) in zip(one, two, problems, strict=True):
        np.testing.assert_array_equal(a.model, b.model)
        np.testing.assert_array_equal(a.inliers, b.inliers)
        assert a.inliers[len(x0) // 3:].all() and not a.inliers[: len(x0) // 3].any()


def test_cuda_pipelines_keep_device_work_in_one_process():
    """CUDA does not survive fork: a CUDA base's device work runs in one process, only its CPU halves fork."""
    cuda, cpu = SimpleNamespace(device=torch.device("cuda")), SimpleNamespace(device=torch.device("cpu"))
    assert device_workers(cuda, 4) == 1 and device_workers(cpu, 4) == 4
    assert _workers(3) == 3 and _workers(0) == 1 and _workers(None) == max(1, os.cpu_count() or 1)


def test_uses_cuda_and_pair_workers():
    assert uses_cuda(SimpleNamespace(device=torch.device("cuda", 0)))
    assert not uses_cuda(SimpleNamespace(device=torch.device("cpu"))) and not uses_cuda(SimpleNamespace())
    assert not uses_cuda(SimpleNamespace(device=None))
    # forking pays from four pairs a worker
    assert pair_workers(8, 2) == 2 and pair_workers(7, 2) == 1
    assert pair_workers(0, 1) == 1 and pair_workers(400, 16) == 16


def test_features_cross_processes_as_numpy_pieces():
    """Features sent from a worker as numpy arrays, in consecutive pieces, come back whole, bit for bit; a
    features set without shape frames keeps None."""
    g = torch.Generator().manual_seed(0)
    laf, shape_laf = torch.rand(7, 2, 3, generator=g), torch.rand(7, 2, 3, generator=g)
    features = Features(laf, torch.rand(7, 5, generator=g), torch.rand(7, generator=g), shape_laf)
    pieces = [features_to_numpy(features.subset(torch.arange(a, b))) for a, b in ((0, 3), (3, 6), (6, 7))]
    assert all(isinstance(a, np.ndarray) for piece in pieces for a in piece)
    back = features_from_numpy(joined(pieces), torch.device("cpu"))
    for name in ("laf", "descriptors", "response", "shape_laf"):
        assert torch.equal(getattr(back, name), getattr(features, name)), name
    bare = Features(laf, torch.zeros(7, 0), torch.ones(7), None)
    arrays = joined([features_to_numpy(bare)] * 2)
    assert arrays[3] is None and arrays[0].shape == (14, 2, 3) and arrays[1].shape == (14, 0)
    assert features_from_numpy(arrays, torch.device("cpu")).shape_laf is None
