"""Slime's job runner: how the detections, descriptions, block and tile pairs and RANSACs are spread over
forked worker processes (:func:`~slime_match._runtime.forking.fork_map`), and what stays in this process.

Forked processes cannot use CUDA: on CUDA the networks run in the main process (``device_workers``), while
the block and tile pairs (Blob matching, DTM, RANSAC) run on the CPU in the workers (``match_jobs``). Work is
split so that the results do not depend on the number of workers: descriptions in pieces of a multiple of the
pipeline's batch (``piece_size``), RANSACs in fixed batches seeded by their index (``ransac_batches``).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch

from .._runtime.forking import fork_map
from ..geometry.ransac import HomographyRansacConfig, ransac_homography_many
from ..pipelines import BasePipeline, CandidateFilter
from ..types import Features, Matches
from .blocks import Block

__all__ = [
    "JobMatches",
    "MatchJob",
    "device_workers",
    "features_from_numpy",
    "features_to_numpy",
    "joined",
    "match_jobs",
    "pair_workers",
    "piece_size",
    "pieces_of",
    "ransac_batches",
    "uses_cuda",
]


def uses_cuda(pipeline: BasePipeline) -> bool:
    """Whether the pipeline computes on a CUDA device (forked processes cannot use CUDA)."""
    device = getattr(pipeline, "device", None)
    return device is not None and device.type == "cuda"


def device_workers(pipeline: BasePipeline, workers: int) -> int:
    """Workers for calls that run the pipeline's networks or read its tensors: one on CUDA, else ``workers``."""
    return 1 if uses_cuda(pipeline) else workers


def pair_workers(count: int, workers: int) -> int:
    """Forking pays only from about four block pairs a worker."""
    return workers if count >= 4 * workers else 1


def piece_size(total: int, batch: int | None, workers: int) -> int:
    """Keypoints per call when ``total`` keypoints are described by ``workers`` processes: about a quarter of
    an even share (so that the processes finish together), a multiple of the pipeline's ``describe_batch``
    (so that the features do not depend on ``workers``); all of them (no pieces) in one process or when the
    pipeline must describe a set whole (``batch`` None)."""
    if workers <= 1 or batch is None:
        return max(total, 1)
    return batch * max(1, math.ceil(total / (4 * workers * batch)))


def pieces_of(count: int, size: int) -> list[slice]:
    """``range(count)`` in consecutive slices of ``size`` (the last one shorter; one empty slice for 0)."""
    return [slice(start, min(start + size, count)) for start in range(0, count, size)] or [slice(0, 0)]


def joined(parts: list[tuple[np.ndarray | None, ...]]) -> tuple[np.ndarray | None, ...]:
    """The arrays of ``features_to_numpy`` of consecutive pieces of one set, as those of the whole set."""
    return tuple(None if column[0] is None else np.concatenate(column) for column in zip(*parts))


def features_to_numpy(features: Features) -> tuple[np.ndarray | None, ...]:
    """The arrays of features (CPU numpy), to send from a forked worker: torch would pickle shared memory."""
    return tuple(None if t is None else t.detach().cpu().numpy() for t in
                 (features.laf, features.descriptors, features.response, features.shape_laf))


def features_from_numpy(arrays: tuple[np.ndarray | None, ...], device: torch.device) -> Features:
    """Features on ``device`` from the arrays of ``features_to_numpy``."""
    return Features(*(None if a is None else torch.from_numpy(a).to(device) for a in arrays))


MatchJob = tuple[Features, Features, Block, Block, CandidateFilter | None]
JobMatches = tuple[Matches, np.ndarray, np.ndarray]


def match_jobs(pipeline: BasePipeline, count: int, job: Callable[[int], MatchJob | None], workers: int = 1
               ) -> list[JobMatches]:
    """The base pipeline on ``count`` block (or tile) pairs, in ``workers`` forked processes (``fork_map``).

    ``job(k)`` gives pair k's features (in their level's pixels), its two blocks and a candidate filter (on
    block-frame positions), or None for no match. On CUDA the jobs' features are first copied to the CPU in
    this process, as forked processes cannot use CUDA, and matched there: one pair's Blob matching is too
    small a problem for a GPU (3.8 ms a pair on an H100, in one process, in the profile of a Slime call).

    Returns:
        Per pair: the matches, and the matched positions (K, 2) float64 in the features' level pixels.
    """
    if not uses_cuda(pipeline):
        return fork_map(lambda k: _match_job(pipeline, job(k)), count, workers)
    copies: dict[int, tuple[Features, Features]] = {}  # id -> (features, CPU copy): pairs share block features

    def on_cpu(features: Features) -> Features:
        if id(features) not in copies:
            copies[id(features)] = features, features.to("cpu")
        return copies[id(features)][1]

    jobs = [None if j is None else (on_cpu(j[0]), on_cpu(j[1]), *j[2:]) for j in map(job, range(count))]
    return fork_map(lambda k: _match_job(pipeline, jobs[k]), count, workers)


def _match_job(pipeline: BasePipeline, job: MatchJob | None) -> JobMatches:
    """The base pipeline on one pair (features shifted into each block's own frame): its matches and matched
    positions in the features' own pixels."""
    if job is None or len(job[0]) < 4 or len(job[1]) < 4:
        return Matches.empty(), np.zeros((0, 2)), np.zeros((0, 2))
    f0, f1, b0, b1, candidate_filter = job
    m = pipeline.match(f0.moved((-b0.box[0], -b0.box[1])), f1.moved((-b1.box[0], -b1.box[1])), b0.shape, b1.shape,
                       candidate_filter=candidate_filter)
    xy0, xy1 = (f.xy.detach().cpu().numpy().astype(np.float64) for f in (f0, f1))
    return m, xy0[m.idx0], xy1[m.idx1]


RANSAC_BATCH = 50  # block pairs per batched RANSAC: a fixed split, so results do not depend on the workers


def ransac_batches(problems: list[tuple[np.ndarray, np.ndarray]], config: HomographyRansacConfig, seed: int,
                   workers: int = 1) -> list:
    """``ransac_homography_many`` on consecutive batches of ``RANSAC_BATCH`` problems (batch b seeded with
    (seed, b)), spread over ``workers`` forked processes; the same results for any number of workers."""
    starts = range(0, len(problems), RANSAC_BATCH)
    parts = fork_map(lambda b: ransac_homography_many(problems[starts[b]:starts[b] + RANSAC_BATCH], config,
                                                      seed=[seed, b]), len(starts), workers)
    return [result for part in parts for result in part]
