"""Blob matching: many-to-many candidate matches ranked by a context-aware nearest-neighbour ratio.

Steps (ALGORITHMS.md section 3): blocked L2 distances; shortlist the pairs within the k smallest of both
their row and their column; greedy many-to-many acceptance with at most p_n pairs per keypoint; score
each accepted pair by 2v / (v_r + v_c), where v_r and v_c are the nearest competitors of the row and the
column located farther than ``context_radius`` from the partner keypoint.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
import torch

from .._runtime.options import config_from_dict
from ..errors import ConfigError
from ..types import Matches
from . import nn_kernels
from .nn import knn, nearest_far


@dataclass
class BlobConfig:
    """Blob matching parameters.

    Attributes:
        shortlist_k: a pair survives when it is within the k smallest distances of its row and column.
        max_per_keypoint: p_n, the most accepted pairs per keypoint in each image.
        context_radius: competitors closer than this (pixels) to the partner keypoint are ignored.
        block_size: descriptor rows per distance block (memory ~ 3 * block_size * M floats).
    """

    shortlist_k: int = 10
    max_per_keypoint: int = 3
    context_radius: float = 16.0
    block_size: int = 1024

    def __post_init__(self) -> None:
        for name in ("shortlist_k", "max_per_keypoint", "block_size"):
            if int(getattr(self, name)) < 1:
                raise ConfigError(f"BlobConfig.{name} must be >= 1, got {getattr(self, name)}")
        if self.context_radius < 0:
            raise ConfigError(f"BlobConfig.context_radius must be >= 0 px, got {self.context_radius}")

    @classmethod
    def from_dict(cls, options: dict) -> BlobConfig:
        """Config from a dict; unknown keys raise ConfigError."""
        return config_from_dict(cls, options)


def greedy_many_to_many(rows: np.ndarray, cols: np.ndarray, values: np.ndarray, max_per: int) -> np.ndarray:
    """Greedy many-to-many acceptance: walk the pairs by ascending value (stable) and accept (i, j) while row i
    and column j each hold fewer than ``max_per`` accepted pairs.

    Args:
        rows, cols: (P,) int pair indices (no duplicate pairs); values: (P,) sort keys.
        max_per: p_n.

    Returns:
        (P,) bool accepted mask.
    """
    return nn_kernels.greedy_accept(rows, cols, np.argsort(values, kind="stable"), max_per)


def _shortlist(row_dist: torch.Tensor, row_idx: torch.Tensor,
               col_idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The row top-k pairs (i, j = row_idx[i, r]) whose row i is also in column j's top-k (exact index
    membership), in row-major order: i (P,), j (P,) and their distances row_dist[i, r] (P,).

    Args:
        row_dist, row_idx: (N, kr) each row's nearest columns; col_idx: (M, kc) each column's nearest rows.
    """
    if row_idx.device.type == "cpu":
        found = nn_kernels.shortlist(row_dist.numpy(), row_idx.numpy(), col_idx.numpy())
        return tuple(torch.from_numpy(a) for a in found)
    n, kr = row_idx.shape
    r_i = torch.arange(n, device=row_idx.device).repeat_interleave(kr)
    r_j = row_idx.flatten()
    in_both = (col_idx[r_j] == r_i[:, None]).any(1)
    return r_i[in_both], r_j[in_both], row_dist.flatten()[in_both]


def blob_match(desc0: torch.Tensor, desc1: torch.Tensor, xy0: torch.Tensor, xy1: torch.Tensor,
               config: BlobConfig | dict | None = None) -> Matches:
    """Blob matching of two descriptor sets.

    Args:
        desc0: (N, D), desc1: (M, D) descriptors (CPU or CUDA, same device).
        xy0: (N, 2), xy1: (M, 2) keypoint positions in pixels.
        config: BlobConfig, a dict of its fields, or None for the defaults.

    Returns:
        Many-to-many Matches sorted by ascending context-ratio score 2v / (v_r + v_c).
    """
    cfg = BlobConfig.from_dict(config) if isinstance(config, dict) else (config or BlobConfig())
    n, m = desc0.shape[0], desc1.shape[0]
    if n == 0 or m == 0:
        return Matches.empty()
    dev = desc0.device
    xy0 = torch.as_tensor(xy0, device=dev).float()
    xy1 = torch.as_tensor(xy1, device=dev).float()
    row_dist, row_idx, col_dist, col_idx = knn(desc0, desc1, cfg.shortlist_k, cfg.shortlist_k, cfg.block_size)

    i, j, v = _shortlist(row_dist, row_idx, col_idx)
    ok = greedy_many_to_many(i.cpu().numpy(), j.cpu().numpy(), v.cpu().numpy(), cfg.max_per_keypoint)
    ok_t = torch.from_numpy(ok).to(dev)
    i, j, v = i[ok_t], j[ok_t], v[ok_t]

    v_r = nearest_far(desc0, desc1, xy1, xy1[j], cfg.context_radius, row_dist, row_idx, cfg.block_size, rows=i)
    v_c = nearest_far(desc1, desc0, xy0, xy0[i], cfg.context_radius, col_dist, col_idx, cfg.block_size, rows=j)
    v_r = torch.where(torch.isinf(v_r), v, v_r)
    v_c = torch.where(torch.isinf(v_c), v, v_c)
    denom = v_r + v_c
    tied = torch.where(v > 0, torch.full_like(v, float("inf")), torch.ones_like(v))  # 0 / 0 is ambiguous
    score = torch.where(denom > 0, 2 * v / denom.clamp_min(torch.finfo(v.dtype).tiny), tied)
    s = score.double().cpu().numpy()
    order = np.argsort(s, kind="stable")
    return Matches(i.cpu().numpy()[order], j.cpu().numpy()[order], s[order])


@cache
def warm_up() -> None:
    """Load Blob matching's compiled loops (``nn_kernels``) in this process, once: from numba's on-disk cache,
    or compiled on first use (a few seconds). Call it before forking workers that run Blob matching, or each
    of them pays it."""
    g = torch.Generator().manual_seed(0)
    desc = torch.rand(40, 8, generator=g)
    blob_match(desc, torch.rand(40, 8, generator=g), torch.rand(40, 2, generator=g) * 64,
               torch.rand(40, 2, generator=g) * 64)
