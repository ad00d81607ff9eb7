"""Slime Sec. 3.8: tile matching refinement and the final global DTM."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial import cKDTree

from ..matching.dtm import DTMConfig, dtm_filter
from ..pipelines import BasePipeline
from .block_matching import ScaleLevel, describe_fixed_bins, fixed_features, orientation_bin, shift_features


@dataclass
class FlowGuide:
    """The flows (x, x') of the block matches of F^theta, to test tile candidates against.

    A tile candidate (y, y') is kept when some guide match has ``max(|x - y|, |x' - y'|) < t``.
    """

    xy0: np.ndarray
    xy1: np.ndarray
    threshold: float

    def __post_init__(self) -> None:
        self._tree = cKDTree(np.hstack([self.xy0, self.xy1])) if len(self.xy0) else None

    def __call__(self, y0: np.ndarray, y1: np.ndarray, neighbours: int = 16) -> np.ndarray:
        """(K,) bool: candidates (K, 2) <-> (K, 2) with a similar guide flow."""
        if self._tree is None or len(y0) == 0:
            return np.zeros(len(y0), bool)
        k = min(neighbours, len(self.xy0))
        # ||(dx, dx')|| < t sqrt(2) is implied by max(|dx|, |dx'|) < t: query that ball, then check exactly.
        dist, index = self._tree.query(np.hstack([y0, y1]), k=k, distance_upper_bound=self.threshold * math.sqrt(2))
        dist, index = dist.reshape(len(y0), k), index.reshape(len(y0), k)
        valid = np.isfinite(dist)
        index = np.where(valid, index, 0)
        e0 = np.linalg.norm(self.xy0[index] - y0[:, None], axis=2)
        e1 = np.linalg.norm(self.xy1[index] - y1[:, None], axis=2)
        return (valid & (np.maximum(e0, e1) < self.threshold)).any(axis=1)


def match_tiles(
    pipeline: BasePipeline,
    level0: ScaleLevel,
    level1: ScaleLevel,
    tile_pairs: np.ndarray,
    thetas: np.ndarray,
    guide: FlowGuide,
    tile_sizes0: list[tuple[int, int]],
    tile_boxes0: list[tuple[float, float, float, float]],
    tile_sizes1: list[tuple[int, int]],
    tile_boxes1: list[tuple[float, float, float, float]],
    bins: int = 16,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Base pipeline (no RANSAC) on the tile pairs of F^theta with the plane's fixed orientation.

    Args:
        level0, level1: full-resolution features shared by the tiles (``members`` per tile).
        tile_pairs: (S, 2) tile indices (c, c') of each set of F^theta.
        thetas: (S,) the set's relative orientation theta^l_v (radians): theta = 0 in image 0, theta in 1.
        guide: the flow filter applied to the candidates before DTM.

    Returns:
        xy0, xy1 (T, 2) and scores (T,) of the tile matches, in original pixels.
    """
    jobs = sorted({(c0, c1, orientation_bin(theta, bins))
                   for (c0, c1), theta in zip(tile_pairs.tolist(), thetas.tolist())})
    describe_fixed_bins(pipeline, level0, {0: np.concatenate([level0.members[c0] for c0, _, _ in jobs])}, bins)
    requests1: dict[int, list] = {}
    for _, c1, b in jobs:
        requests1.setdefault(b, []).append(level1.members[c1])
    describe_fixed_bins(pipeline, level1, {b: np.concatenate(parts) for b, parts in requests1.items()}, bins)
    out0, out1, scores = [], [], []
    for c0, c1, b in jobs:
        f0 = fixed_features(level0, level0.members[c0], 0, bins)
        f1 = fixed_features(level1, level1.members[c1], b, bins)
        if len(f0) < 4 or len(f1) < 4:
            continue
        box0, box1 = tile_boxes0[c0], tile_boxes1[c1]
        offset0, offset1 = np.array(box0[:2]), np.array(box1[:2])

        def flow_filter(y0, y1, offset0=offset0, offset1=offset1):
            return guide(y0 + offset0, y1 + offset1)

        m = pipeline.match(shift_features(f0, box0), shift_features(f1, box1), tile_sizes0[c0], tile_sizes1[c1],
                           candidate_filter=flow_filter)
        if len(m) == 0:
            continue
        out0.append(f0.xy[torch.from_numpy(m.idx0)].cpu().numpy())
        out1.append(f1.xy[torch.from_numpy(m.idx1)].cpu().numpy())
        scores.append(m.scores)
    if not out0:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    return (np.concatenate(out0).astype(np.float64), np.concatenate(out1).astype(np.float64),
            np.concatenate(scores))


def global_dtm(xy0: np.ndarray, xy1: np.ndarray, scores: np.ndarray, size0, size1, keypoints0: np.ndarray,
               keypoints1: np.ndarray, config: DTMConfig | None = None) -> tuple[np.ndarray, np.ndarray,
                                                                                  np.ndarray]:
    """Final DTM on the union of tile and F^theta matches; exact duplicate matches are merged first.

    Returns:
        xy0, xy1 (K, 2) and scores (K,) of the kept matches, sorted by score.
    """
    if len(xy0) == 0:
        return xy0, xy1, scores
    rows = np.hstack([xy0, xy1])
    order = np.argsort(scores, kind="stable")
    _, first = np.unique(np.round(rows[order], 4), axis=0, return_index=True)
    unique = np.sort(order[first])
    xy0, xy1, scores = xy0[unique], xy1[unique], scores[unique]
    keep = dtm_filter(xy0, xy1, scores, size0, size1, unmatched0=keypoints0, unmatched1=keypoints1,
                      config=config).keep
    order = np.argsort(scores[keep], kind="stable")
    return xy0[keep][order], xy1[keep][order], scores[keep][order]
