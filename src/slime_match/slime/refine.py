"""Slime Sec. 3.8: tile matching refinement and the final global DTM."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from slime_match.choices import TILE_TESTS

from ..geometry.homography import two_sided_error_batch
from ..matching.dtm import DTMConfig, dtm_filter
from ..pipelines import BasePipeline
from .blocks import Block
from .clusters import greedy_clusters
from .dtm_frame import DTM_MAX_TILT, DTMFrame, dtm_frame
from .fixed_descriptors import FixedDescriptors
from .jobs import MatchJob, match_jobs
from .levels import ScaleLevel
from .orientations import orientation_bin


@dataclass
class FlowGuide:
    """The flows (x, x') of the block matches of F^theta, to test tile candidates against.

    A tile candidate (y, y') is kept when some guide match has ``max(|x - y|, |x' - y'|) < t``: every guide
    within ``t sqrt(2)`` of it in 4-D (which that bound implies) is tested.
    """

    xy0: np.ndarray
    xy1: np.ndarray
    threshold: float

    def __post_init__(self) -> None:
        self._tree = cKDTree(np.hstack([self.xy0, self.xy1])) if len(self.xy0) else None

    def __call__(self, y0: np.ndarray, y1: np.ndarray) -> np.ndarray:
        """(K,) bool: candidates (K, 2) <-> (K, 2) with a similar guide flow."""
        if self._tree is None or len(y0) == 0:
            return np.zeros(len(y0), bool)
        # ||(dx, dx')|| < t sqrt(2) is implied by max(|dx|, |dx'|) < t: every guide in that ball, checked exactly
        near = self._tree.query_ball_point(np.hstack([y0, y1]), r=self.threshold * math.sqrt(2))
        counts = np.fromiter(map(len, near), np.int64, len(near))
        guide = np.fromiter(itertools.chain.from_iterable(near), np.int64, int(counts.sum()))
        candidate = np.repeat(np.arange(len(y0)), counts)
        e0 = np.linalg.norm(self.xy0[guide] - y0[candidate], axis=1)
        e1 = np.linalg.norm(self.xy1[guide] - y1[candidate], axis=1)
        passed = candidate[np.maximum(e0, e1) < self.threshold]
        return np.bincount(passed, minlength=len(y0)) > 0


@dataclass
class PlaneGuide:
    """The planes of F^theta's sets, to test the candidates of their tile pairs against (``tile_test="plane"``).

    A candidate (y, y') is kept when, for the plane H_l of some set on its tile pair, the two-sided error
    ``max(|y' - H_l y|, |y - H_l^-1 y'|)`` is below ``threshold`` and y lies on the plane's side: the tests of
    Sec. 3.4's expansion, where the paper's flow test asks for a F^theta match within ``threshold``.

    Attributes:
        homographies: (P, 3, 3) plane homographies (image 0 -> image 1, px); sides: (P,) +-1 sign of w on
        the plane's own matches; threshold: t_perp in px.
    """

    homographies: np.ndarray
    sides: np.ndarray
    threshold: float

    def __call__(self, y0: np.ndarray, y1: np.ndarray, planes: np.ndarray) -> np.ndarray:
        """(K,) bool: candidates (K, 2) <-> (K, 2) that fit one of ``planes`` (indices into homographies)."""
        if len(planes) == 0 or len(y0) == 0:
            return np.zeros(len(y0), bool)
        error, w = two_sided_error_batch(self.homographies[planes], y0, y1)
        return ((error < self.threshold) & (np.sign(w) == self.sides[planes][:, None])).any(axis=0)




def tile_test(kind: str, flow: FlowGuide, plane: PlaneGuide
              ) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """The candidate test of the tile stage: ``test(y0, y1, planes) -> (K,) bool`` for candidates (K, 2) <->
    (K, 2) in original px of a tile pair whose F^theta sets have the planes ``planes``.

    "flow": the paper's (a F^theta match within t_perp at both ends, ``FlowGuide``); "plane": fits the plane
    of one of the tile pair's sets (``PlaneGuide``). Passing either of the two covered less than "plane"
    (docs/coverage.md), so it is not offered.
    """
    if kind == "flow":
        return lambda y0, y1, planes: flow(y0, y1)
    if kind == "plane":
        return plane
    raise ValueError(f"tile test {kind!r} is not one of {', '.join(TILE_TESTS)}")


@dataclass
class TileMatches:
    """Sec. 3.8's tile matches: xy0, xy1 (T, 2) in original px and scores (T,)."""

    xy0: np.ndarray
    xy1: np.ndarray
    scores: np.ndarray

    @classmethod
    def empty(cls) -> TileMatches:
        return cls(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))

    @property
    def counts(self) -> dict[str, int]:
        return {"tile_matches": len(self.xy0)}

    def arrays(self) -> dict[str, np.ndarray]:
        return {"tile_matches_xy0": self.xy0, "tile_matches_xy1": self.xy1}


@dataclass
class FinalMatches:
    """Slime's output matches (K, 2), (K, 2), (K,) in original px sorted by score, and the last step's input:
    F^theta's matches then the tile matches (the global DTM's input where it runs), and the frame the global
    DTM compared them in ("" where it did not run)."""

    xy0: np.ndarray
    xy1: np.ndarray
    scores: np.ndarray
    input_xy0: np.ndarray
    input_xy1: np.ndarray
    input_scores: np.ndarray
    dtm_frame: str = ""

    @property
    def counts(self) -> dict[str, int]:
        return {"final": len(self.xy0)}

    def arrays(self) -> dict[str, np.ndarray]:
        return {"dtm_input_xy0": self.input_xy0, "dtm_input_xy1": self.input_xy1,
                "dtm_input_score": self.input_scores, "final_xy0": self.xy0, "final_xy1": self.xy1}


def match_tiles(
    pipeline: BasePipeline,
    levels0: list[ScaleLevel],
    levels1: list[ScaleLevel],
    tiles0: list[Block],
    tiles1: list[Block],
    tile_pairs: np.ndarray,
    thetas: np.ndarray,
    planes: np.ndarray,
    test: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    bins: int = 16,
    workers: int = 1,
) -> TileMatches:
    """Base pipeline (no RANSAC) on the tile pairs of F^theta with the plane's fixed orientation.

    Args:
        levels0, levels1: full-resolution tile features (``build_levels`` on the tiles, shared or per tile).
        tiles0, tiles1: the tiles of each image.
        tile_pairs: (S, 2) tile indices (c, c') of each set of F^theta.
        thetas: (S,) the set's relative orientation theta^l_v (radians): theta = 0 in image 0, theta in 1.
        planes: (S,) the set's plane (block pair) index l.
        test: ``tile_test``'s filter of the candidates before DTM, given a tile pair's candidates in original
            px and the planes of its sets.
        workers: forked processes for the descriptors and the tile pairs (``fork_map``; same results).

    Returns:
        The tile matches, in original pixels.
    """
    where0 = {c: (level, i) for level in levels0 for i, c in enumerate(level.blocks)}
    where1 = {c: (level, i) for level in levels1 for i, c in enumerate(level.blocks)}
    job_planes: dict[tuple[int, int, int], set[int]] = {}
    for (c0, c1), theta, plane in zip(tile_pairs.tolist(), thetas.tolist(), planes.tolist()):
        job_planes.setdefault((c0, c1, orientation_bin(theta, bins)), set()).add(plane)
    jobs = sorted(job_planes)
    requests: dict[int, tuple[ScaleLevel, dict[int, list]]] = {}
    for c0, c1, b in jobs:
        for (level, i), bin_index in ((where0[c0], 0), (where1[c1], b)):
            requests.setdefault(id(level), (level, {}))[1].setdefault(bin_index, []).append(level.members[i])
    fixed = FixedDescriptors(pipeline, bins, workers)
    fixed.compute([(level, {b: np.concatenate(parts) for b, parts in wanted.items()})
                   for level, wanted in requests.values()])

    def job(k: int) -> MatchJob:
        c0, c1, b = jobs[k]
        (level0, i0), (level1, i1) = where0[c0], where1[c1]
        offset0, offset1 = np.array(tiles0[c0].box[:2]), np.array(tiles1[c1].box[:2])
        f0 = fixed.features(level0, level0.members[i0], 0)
        f1 = fixed.features(level1, level1.members[i1], b)
        job_plane = np.array(sorted(job_planes[jobs[k]]), dtype=np.int64)
        return f0, f1, tiles0[c0], tiles1[c1], lambda y0, y1: test(y0 + offset0, y1 + offset1, job_plane)

    found = [(xy0, xy1, m.scores) for m, xy0, xy1 in match_jobs(pipeline, len(jobs), job, workers) if len(m)]
    out0, out1, scores = (list(column) for column in zip(*found)) if found else ([], [], [])
    if not out0:
        return TileMatches.empty()
    return TileMatches(np.concatenate(out0).astype(np.float64), np.concatenate(out1).astype(np.float64),
                       np.concatenate(scores))


def merge_duplicates(xy0: np.ndarray, xy1: np.ndarray, scores: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                                  np.ndarray]:
    """Matches (K, 2), (K, 2), (K,) without exact duplicates (the best-scored one kept, ties: the first), in
    input order."""
    order = np.argsort(scores, kind="stable")
    _, first = np.unique(np.round(np.hstack([xy0, xy1]), 4)[order], axis=0, return_index=True)
    unique = np.sort(order[first])
    return xy0[unique], xy1[unique], scores[unique]


CLUSTER_RADIUS = 4.0  # px: a match within this distance of a better one at both ends joins its cluster


def cluster_representatives(xy0: np.ndarray, xy1: np.ndarray, scores: np.ndarray,
                            radius: float = CLUSTER_RADIUS) -> tuple[np.ndarray, np.ndarray]:
    """Near-duplicate matches grouped greedily (the paper's SM: a cluster of matches stands for its members).

    In score order, each match not yet clustered becomes a representative and takes every unclustered match
    whose ends both lie within ``radius`` px of its own (per coordinate), so representatives are never
    within ``radius`` of each other at both ends.

    Args:
        xy0, xy1: (K, 2) match ends in px; scores: (K,) lower is better.

    Returns:
        (C,) index of each cluster's representative (its best-scored match), (K,) cluster of each match.
    """
    return greedy_clusters(np.hstack([xy0, xy1]), scores, radius)


def global_dtm(xy0: np.ndarray, xy1: np.ndarray, scores: np.ndarray, size0, size1,
               config: DTMConfig | None = None, cluster_radius: float = CLUSTER_RADIUS,
               max_tilt: float = DTM_MAX_TILT) -> tuple[np.ndarray, np.ndarray, np.ndarray, DTMFrame]:
    """Final DTM on the union of tile and F^theta matches.

    Exact duplicate matches are merged first. Overlapping blocks and tiles leave clusters of matches a few
    pixels apart; DTM runs on one representative per cluster (``cluster_representatives``) and the members
    share its verdict. Within such clusters Delaunay neighbourhoods follow the keypoints' localisation noise,
    not the scene, so they disagree between the images, and DTM's contraction would erode correct matches
    until too few are left for its expansion to recover (docs/method.md, Sec. 3.8).

    The hull is not carved with unmatched keypoints (the base DTM's ``unmatched0/1``): the candidates come
    from block levels and tiles, so no keypoint set is "the others" of them, and carving with the tile
    keypoints removes correct matches on strongly rotated pairs.

    Under a strong tilt the representatives of image 0 are compared in image 1's frame (:mod:`.dtm_frame`).

    Args:
        xy0, xy1: (K, 2) match ends in px; scores: (K,) lower is better; size0, size1: (H, W) image sizes.
        config: the DTM's parameters (the base pipeline's); cluster_radius: px, see ``cluster_representatives``.
        max_tilt: see :func:`~.dtm_frame.dtm_frame` (inf: always the images' own frames, the paper's DTM).

    Returns:
        xy0, xy1 (K, 2) and scores (K,) of the kept matches, sorted by score, and the frame DTM ran in.
    """
    if len(xy0) == 0:
        return xy0, xy1, scores, dtm_frame(xy0, xy1, size0, size1, max_tilt)
    xy0, xy1, scores = merge_duplicates(xy0, xy1, scores)
    rep, cluster = cluster_representatives(xy0, xy1, scores, cluster_radius)
    frame = dtm_frame(xy0[rep], xy1[rep], size0, size1, max_tilt)
    keep = dtm_filter(frame.map(xy0[rep]), xy1[rep], scores[rep], frame.size, size1, config=config).keep[cluster]
    order = np.argsort(scores[keep], kind="stable")
    return xy0[keep][order], xy1[keep][order], scores[keep][order], frame


def final_matches(xy0: np.ndarray, xy1: np.ndarray, scores: np.ndarray, tiles: TileMatches | None, size0, size1,
                  run_dtm: bool, dtm: DTMConfig | None = None, max_tilt: float = DTM_MAX_TILT) -> FinalMatches:
    """The matches of F^theta (K, 2), (K, 2), (K,) and the tile matches (None: Sec. 3.8 did not run) as
    Slime's output: with tiles, exact duplicates merged, then the global DTM when ``run_dtm``; sorted by score.

    Args:
        size0, size1: (H, W) of the images; dtm: the global DTM's parameters (the base pipeline's; None: the
            defaults); max_tilt: see :func:`global_dtm`.
    """
    found = tiles or TileMatches.empty()
    all0, all1 = np.vstack([xy0, found.xy0]), np.vstack([xy1, found.xy1])
    all_scores = np.concatenate([scores, found.scores])
    frame = ""
    if tiles is not None and run_dtm:
        out0, out1, out_scores, dtm_in = global_dtm(all0, all1, all_scores, size0, size1, dtm, max_tilt=max_tilt)
        frame = dtm_in.reason
    else:
        merged = merge_duplicates(all0, all1, all_scores) if tiles is not None else (all0, all1, all_scores)
        order = np.argsort(merged[2], kind="stable")
        out0, out1, out_scores = (column[order] for column in merged)
    return FinalMatches(out0, out1, out_scores, all0, all1, all_scores, frame)
