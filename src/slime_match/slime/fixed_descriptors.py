"""Descriptors under fixed orientations (Secs. 3.3 and 3.8): each level's features described at the angle
of an orientation bin, once per (level, bin) and only for the features that a block or tile pair needs.

A :class:`FixedDescriptors` belongs to one stage of one pair (the block re-run of Sec. 3.3, the tiles of
Sec. 3.8): the levels it describes are never changed, so cached levels can serve any later pair.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from .._runtime.forking import fork_map
from ..features.laf import set_laf_angle
from ..pipelines import BasePipeline
from ..types import Features
from .jobs import device_workers, piece_size, pieces_of
from .levels import ScaleLevel

__all__ = ["FixedDescriptors"]


class FixedDescriptors:
    """The fixed-orientation descriptors of some levels' features, computed on demand.

    Args:
        pipeline: the base pipeline that describes them (``describe_fixed``).
        bins: orientation bins; bin b is the angle b 2 pi / bins.
        workers: forked processes sharing the calls, each (level, bin) in pieces (``piece_size``: the same
            descriptors as in one process); one process on CUDA.
    """

    def __init__(self, pipeline: BasePipeline, bins: int, workers: int = 1) -> None:
        self.pipeline, self.bins, self.workers = pipeline, bins, workers
        self._levels: dict[int, ScaleLevel] = {}  # id -> level: the keys below stay valid while held here
        self._sets: dict[tuple[int, int], tuple[np.ndarray, torch.Tensor]] = {}  # (id, bin) -> (computed, desc.)

    def _get(self, level: ScaleLevel, bin_index: int) -> tuple[np.ndarray, torch.Tensor | None]:
        """(N,) mask of the features described so far under bin ``bin_index``, and their (N, D) descriptors."""
        return self._sets.get((id(level), bin_index), (np.zeros(len(level.features), bool), None))

    def use_own(self, levels: list[ScaleLevel]) -> None:
        """Take the levels' own descriptors as those of bin 0 (angle 0): on an upright base they are."""
        for level in levels:
            self._levels[id(level)] = level
            self._sets.setdefault((id(level), 0), (np.ones(len(level.features), bool), level.features.descriptors))

    def compute(self, requests: list[tuple[ScaleLevel, dict[int, np.ndarray]]]) -> None:
        """Describe what ``features`` will be asked for.

        Args:
            requests: (level, orientation bin -> indices of the level's features needed under that bin's
                angle), each level at most once. Each (level, bin) is described in batched calls (one, or
                pieces spread over the workers), and only for features not described before.
        """
        pipeline, bins = self.pipeline, self.bins
        wanted_sets = []
        for level, wanted in requests:
            self._levels[id(level)] = level
            for bin_index, index in wanted.items():
                computed, _ = self._get(level, bin_index)
                missing = np.unique(index)
                missing = missing[~computed[missing]]
                if len(missing):
                    wanted_sets.append((level, bin_index, missing))
        workers = device_workers(pipeline, self.workers)
        forked = workers > 1
        size = piece_size(sum(len(missing) for *_, missing in wanted_sets), pipeline.describe_batch(), workers)
        tasks = [(level, bin_index, missing[piece]) for level, bin_index, missing in wanted_sets
                 for piece in pieces_of(len(missing), size)]
        tasks.sort(key=lambda task: -len(task[2]))  # the largest first: even loads over the workers

        def describe(k: int) -> np.ndarray | torch.Tensor:
            level, bin_index, missing = tasks[k]
            regions = level.features.subset(torch.from_numpy(missing))
            if level.origin != (0.0, 0.0):
                regions = regions.moved((-level.origin[0], -level.origin[1]))
            fresh = pipeline.describe_fixed(level.context, regions, bin_index * 2 * math.pi / bins).descriptors
            return fresh.detach().cpu().numpy() if forked else fresh.detach()  # no device round trip in-process

        for (level, bin_index, missing), fresh in zip(tasks, fork_map(describe, len(tasks), workers)):
            n, device = len(level.features), level.features.laf.device
            computed, descriptors = self._get(level, bin_index)
            if descriptors is None:
                descriptors = torch.zeros(n, fresh.shape[1], device=device)
            descriptors[torch.from_numpy(missing).to(device)] = torch.as_tensor(fresh, device=device)
            computed = computed.copy()
            computed[missing] = True
            self._sets[id(level), bin_index] = (computed, descriptors)

    def features(self, level: ScaleLevel, index: np.ndarray, bin_index: int) -> Features:
        """Features ``index`` of a level under the fixed orientation of ``bin_index`` (see ``compute``).

        An empty ``index`` (a block or tile without keypoints, for which nothing was described) gives no
        features.
        """
        if len(index) == 0:
            return level.features.subset(torch.zeros(0, dtype=torch.long, device=level.features.laf.device))
        computed, descriptors = self._get(level, bin_index)
        if not computed[index].all():
            raise RuntimeError("fixed-orientation descriptors requested before FixedDescriptors.compute")
        select = torch.from_numpy(index).to(descriptors.device)
        laf = set_laf_angle(level.features.shape_laf[select], bin_index * 2 * math.pi / self.bins)
        return Features(laf, descriptors[select], level.features.response[select])
