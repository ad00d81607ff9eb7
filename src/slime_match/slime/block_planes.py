"""Block planes (Secs. 3.2-3.3): every block pair matched by the base pipeline and a homography RANSAC, then
re-matched under the plane's fixed orientations (theta = 0 in image 0, theta* in image 1) and RANSAC again:
the planes M_l, H_l, mapped to original-image pixels for the later stages.

A block pair's first matches come from the base pipeline on the two blocks' features (``matching="pairs"``, the
paper's), or from the base pipeline on the two blocks' whole levels, each pair of levels matched once and shared
out to its block pairs by their cores (``matching="levels"``: a matcher that reads the whole image, such as
LightGlue, keeps that context; one match per pair of block scales instead of one per block pair).

The pairs and RANSACs run in the job runner's workers (:mod:`.jobs`): RANSACs of all block pairs as batches,
the fixed-orientation descriptors once per (level, bin) for the blocks that a re-run needs
(:class:`.fixed_descriptors.FixedDescriptors`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch

from .._runtime.forking import fork_map
from ..geometry.frames import stack_matrices
from ..geometry.homography import project
from ..geometry.ransac import HomographyRansacConfig
from ..pipelines import BasePipeline
from ..types import Features, Matches
from .blocks import Block
from .fixed_descriptors import FixedDescriptors
from .jobs import JobMatches, MatchJob, device_workers, match_jobs, pair_workers, ransac_batches
from .levels import ScaleLevel
from .match_table import MatchTable, deduplicate
from .orientations import orientation_bin, relative_orientation

BLOCK_MATCHINGS = ("pairs", "levels")  # how a block pair's first matches are found (module docstring)
LevelPairMatches = dict[tuple[int, int], Matches]  # the base pipeline's matches per pair of levels (level_pair_key)

__all__ = ["BLOCK_MATCHINGS", "BlockPairMatches", "BlockPlanes", "LevelPairMatches", "block_planes",
           "block_planes_to_original", "distinct_keypoints", "level_pair_key", "match_block_pairs",
           "match_level_pairs", "plane_sides"]


@dataclass
class BlockPairMatches:
    """Matches of block pairs, in scaled-image pixels of each side.

    Attributes:
        pairs: (P, 2) block indices (w in image 0, w' in image 1) of the pairs that produced a plane.
        H: (P, 3, 3) homographies from scaled image 0 (of block w) to scaled image 1 (of block w').
        theta: (P,) orientation of image 1's patches against image 0's (radians) in the refined run: theta*
            (image 1's turned by it; for a simulated view of image 1, image 0's turned by -theta).
        match_pair: (M,) index into ``pairs`` of each match.
        xy0, xy1: (M, 2) matched keypoints in the scaled images.
        scale0, scale1: (M,) patch scales in scaled-image pixels.
        scores: (M,) base-pipeline dissimilarities.
    """

    pairs: np.ndarray
    H: np.ndarray
    theta: np.ndarray
    match_pair: np.ndarray
    xy0: np.ndarray
    xy1: np.ndarray
    scale0: np.ndarray
    scale1: np.ndarray
    scores: np.ndarray

    def joined(self, other: BlockPairMatches, offset0: int, offset1: int = 0) -> BlockPairMatches:
        """These planes followed by ``other``'s, whose block indices are shifted by ``offset0`` in image 0 and
        ``offset1`` in image 1."""
        pairs = np.concatenate([self.pairs, other.pairs + np.array([offset0, offset1])])
        return BlockPairMatches(pairs, np.concatenate([self.H, other.H]), np.concatenate([self.theta, other.theta]),
                                np.concatenate([self.match_pair, other.match_pair + len(self.pairs)]),
                                *(np.concatenate([getattr(self, k), getattr(other, k)])
                                  for k in ("xy0", "xy1", "scale0", "scale1", "scores")))

    def swapped(self) -> BlockPairMatches:
        """The same planes with the two images' roles exchanged (found with image 1's blocks as image 0's)."""
        return BlockPairMatches(self.pairs[:, ::-1].copy(), np.linalg.inv(self.H), np.mod(-self.theta, 2 * math.pi),
                                self.match_pair, self.xy1, self.xy0, self.scale1, self.scale0, self.scores)


class _BlockSide:
    """One image's blocks as the block pairs see them: each block's own features and, per orientation bin,
    its fixed-orientation features (each built once, shared by the block's pairs)."""

    def __init__(self, levels: list[ScaleLevel], blocks: list[Block], fixed: FixedDescriptors) -> None:
        self.blocks, self.fixed = blocks, fixed
        self.where = {w: (level, i) for level in levels for i, w in enumerate(level.blocks)}
        self._own: dict[int, Features] = {}
        self._fixed: dict[tuple[int, int], Features] = {}

    def own(self, block: int) -> Features:
        """The features of ``block``'s core with the pipeline's own orientations (level pixels)."""
        if block not in self._own:
            level, i = self.where[block]
            self._own[block] = level.features.subset(torch.from_numpy(level.members[i]))
        return self._own[block]

    def wanted(self, block: int) -> tuple[ScaleLevel, np.ndarray]:
        """The level of ``block`` and the indices of its core's features there."""
        level, i = self.where[block]
        return level, level.members[i]

    def under(self, block: int, bin_index: int) -> Features:
        """The features of ``block``'s core under the fixed orientation of ``bin_index`` (computed before)."""
        if (block, bin_index) not in self._fixed:
            self._fixed[block, bin_index] = self.fixed.features(*self.wanted(block), bin_index)
        return self._fixed[block, bin_index]


def match_block_pairs(
    pipeline: BasePipeline,
    levels0: list[ScaleLevel],
    levels1: list[ScaleLevel],
    blocks0: list[Block],
    blocks1: list[Block],
    ransac: HomographyRansacConfig,
    bins: int = 16,
    min_matches: int = 8,
    seed: int = 0,
    workers: int = 1,
    fixed: FixedDescriptors | None = None,
    matching: str = "pairs",
    matched: LevelPairMatches | None = None,
) -> tuple[BlockPairMatches, dict[str, int]]:
    """Secs. 3.2 + 3.3 for every block pair: base pipeline + homography RANSAC, then the re-run with
    fixed orientations (theta = 0 in image 0, theta* in image 1) + RANSAC -> M_l and H_l.

    The first run matches each block pair (``matching="pairs"``) or each pair of levels (``"levels"``, see the
    module docstring); the re-run matches each block pair.

    A plane needs ``min_matches`` RANSAC inliers with as many distinct keypoints in each image (the base
    pipeline may match one keypoint several times). ``fixed`` holds the fixed-orientation descriptors of
    earlier calls on the same levels (image 1's, shared by the plain blocks and the simulated views); None
    starts an empty one. ``matched`` holds level pairs the base pipeline already matched (``"levels"``).

    Returns:
        The refined planes and their matches, in level pixels, and counts for the summary: block pairs,
        first-run planes, pairs re-matched under fixed orientations (on an upright base none: the first run's
        matches are reused, ``BasePipeline.own_frames_upright``) and refined planes.
    """
    fixed = fixed if fixed is not None else FixedDescriptors(pipeline, bins, workers)
    side0, side1 = _BlockSide(levels0, blocks0, fixed), _BlockSide(levels1, blocks1, fixed)
    pairs = [(w0, w1) for w0 in range(len(blocks0)) for w1 in range(len(blocks1))]

    def own_job(k: int) -> MatchJob:
        w0, w1 = pairs[k]
        return side0.own(w0), side1.own(w1), blocks0[w0], blocks1[w1], None

    # 3.2: the base pipeline with its own orientations, then RANSAC.
    if matching == "levels":
        first = _from_level_pairs(pipeline, side0, side1, pairs, workers, matched)
    else:
        first = match_jobs(pipeline, len(pairs), own_job, pair_workers(len(pairs), workers))
    results = ransac_batches([(xy0, xy1) for _, xy0, xy1 in first], ransac, seed, workers)
    thetas = {}
    for pair, (m, _, _), res in zip(pairs, first, results):
        if res.model is None or distinct_keypoints(m.subset(res.inliers)) < min_matches:
            continue
        m_in = m.subset(res.inliers)
        angle0 = side0.own(pair[0]).angle[torch.from_numpy(m_in.idx0)].cpu().numpy()
        angle1 = side1.own(pair[1]).angle[torch.from_numpy(m_in.idx1)].cpu().numpy()
        thetas[pair] = relative_orientation(angle0, angle1, bins=bins)

    # 3.3: re-run with fixed orientations on the pairs that produced a plane.
    refined_pairs = list(thetas)
    bin_of = {pair: orientation_bin(theta, bins) for pair, theta in thetas.items()}
    upright = pipeline.own_frames_upright()
    if upright:  # the features' own descriptors are those of bin 0 (angle 0)
        fixed.use_own([*levels0, *levels1])
    requests: dict[int, tuple[ScaleLevel, dict[int, list]]] = {}  # by level: bin -> the blocks' indices
    for pair in refined_pairs:
        for (level, index), bin_index in ((side0.wanted(pair[0]), 0), (side1.wanted(pair[1]), bin_of[pair])):
            requests.setdefault(id(level), (level, {}))[1].setdefault(bin_index, []).append(index)
    fixed.compute([(level, {b: np.concatenate(parts) for b, parts in wanted.items()})
                   for level, wanted in requests.values()])

    def fixed_job(k: int) -> MatchJob:
        w0, w1 = pair = refined_pairs[k]
        return side0.under(w0, 0), side1.under(w1, bin_of[pair]), blocks0[w0], blocks1[w1], None

    # On an upright base a pair with theta* = 0 (all of them: every angle is 0) would match exactly as in the
    # first run: its matches are reused, and only its RANSAC runs again.
    repeats = [upright and bin_of[pair] == 0 for pair in refined_pairs]
    redo = [k for k, repeat in enumerate(repeats) if not repeat]
    rerun = iter(match_jobs(pipeline, len(redo), lambda j: fixed_job(redo[j]), pair_workers(len(redo), workers)))
    second = [first[w0 * len(blocks1) + w1] if repeat else next(rerun)  # ``pairs`` order
              for (w0, w1), repeat in zip(refined_pairs, repeats)]
    results = ransac_batches([(xy0, xy1) for _, xy0, xy1 in second], ransac, seed + 1, workers)

    keep_pairs, hs, theta_out, parts = [], [], [], []
    for pair, (m, _, _), res in zip(refined_pairs, second, results):
        if res.model is None or distinct_keypoints(m.subset(res.inliers)) < min_matches:
            continue
        m_in = m.subset(res.inliers)
        keep_pairs.append(pair)
        hs.append(res.model)
        theta_out.append(bin_of[pair] * 2 * math.pi / bins)
        parts.append((len(keep_pairs) - 1, side0.under(pair[0], 0), side1.under(pair[1], bin_of[pair]), m_in))
    counts = {"block_pairs": len(pairs), "block_planes_first": len(thetas), "block_pairs_rerun": len(redo),
              "block_planes": len(keep_pairs)}
    return _collect(keep_pairs, hs, theta_out, parts), counts


def level_pair_key(level0: ScaleLevel, level1: ScaleLevel) -> tuple[int, int]:
    """The key of a pair of levels (the very objects) in a :data:`LevelPairMatches`."""
    return id(level0), id(level1)


def match_level_pairs(pipeline: BasePipeline, pairs: list[tuple[ScaleLevel, ScaleLevel]], workers: int
                      ) -> LevelPairMatches:
    """The base pipeline's matches of each pair of whole levels, in ``workers`` processes (one on CUDA)."""

    def match(k: int) -> Matches:
        level0, level1 = pairs[k]
        return pipeline.match(level0.features, level1.features, level0.size, level1.size)

    found = fork_map(match, len(pairs), device_workers(pipeline, workers))
    return {level_pair_key(*pair): m for pair, m in zip(pairs, found)}


def _from_level_pairs(pipeline: BasePipeline, side0: _BlockSide, side1: _BlockSide, pairs: list[tuple[int, int]],
                      workers: int, matched: LevelPairMatches | None = None) -> list[JobMatches]:
    """Per block pair, the matches between its two cores taken from the base pipeline on the blocks' whole
    levels (each pair of levels matched once, unless ``matched`` holds it)."""
    level_of = [{w: side.wanted(w)[0] for w in range(len(side.blocks))} for side in (side0, side1)]
    level_pairs = sorted({level_pair_key(level_of[0][w0], level_of[1][w1]) for w0, w1 in pairs})
    levels = {id(level): level for side in level_of for level in side.values()}
    matched = matched or {}
    missing = [(levels[key0], levels[key1]) for key0, key1 in level_pairs if (key0, key1) not in matched]
    found = {**matched, **match_level_pairs(pipeline, missing, workers)}
    xy = {key: level.features.xy.detach().cpu().numpy().astype(np.float64) for key, level in levels.items()}
    local = [{}, {}]  # per side and block: level index -> index among the block's own features (-1: outside)

    def local_index(side: int, w: int) -> np.ndarray:
        if w not in local[side]:
            level, members = (side0, side1)[side].wanted(w)
            index = np.full(len(level.features), -1, np.int64)
            index[members] = np.arange(len(members))
            local[side][w] = index
        return local[side][w]

    out = []
    for w0, w1 in pairs:
        key0, key1 = id(level_of[0][w0]), id(level_of[1][w1])
        m = found[key0, key1]
        i0, i1 = local_index(0, w0)[m.idx0], local_index(1, w1)[m.idx1]
        inside = (i0 >= 0) & (i1 >= 0)
        out.append((Matches(i0[inside], i1[inside], m.scores[inside]), xy[key0][m.idx0[inside]],
                    xy[key1][m.idx1[inside]]))
    return out


def distinct_keypoints(matches: Matches) -> int:
    """The fewer of the two images' distinct keypoints among ``matches``."""
    return min(len(np.unique(matches.idx0)), len(np.unique(matches.idx1)))


def _collect(pairs, hs, thetas, parts) -> BlockPairMatches:
    if not parts:
        z = np.zeros
        return BlockPairMatches(z((0, 2), np.int64), z((0, 3, 3)), z(0), z(0, np.int64), z((0, 2)), z((0, 2)),
                                z(0), z(0), z(0))
    cols = {k: [] for k in ("pair", "xy0", "xy1", "s0", "s1", "score")}
    for index, f0, f1, m in parts:
        i0, i1 = torch.from_numpy(m.idx0), torch.from_numpy(m.idx1)
        cols["pair"].append(np.full(len(m), index))
        cols["xy0"].append(f0.xy[i0].cpu().numpy())
        cols["xy1"].append(f1.xy[i1].cpu().numpy())
        cols["s0"].append(f0.scale[i0].cpu().numpy())
        cols["s1"].append(f1.scale[i1].cpu().numpy())
        cols["score"].append(m.scores)
    cat = {k: np.concatenate(v).astype(np.int64 if k == "pair" else np.float64) for k, v in cols.items()}
    return BlockPairMatches(np.asarray(pairs, np.int64), np.stack(hs), np.asarray(thetas), cat["pair"],
                            cat["xy0"], cat["xy1"], cat["s0"], cat["s1"], cat["score"])


def block_planes_to_original(bpm: BlockPairMatches, blocks0: list[Block], blocks1: list[Block]
                             ) -> tuple[MatchTable, np.ndarray, np.ndarray]:
    """Block-pair matches and homographies in original-image pixels (Sec. 3.4's reference frame).

    Returns:
        The match table (theta = 0 in image 0 and theta* of its plane in image 1, as forced by Sec. 3.3),
        (L, 3, 3) homographies original image 0 -> original image 1, and (L,) plane sides.
    """
    s0 = stack_matrices([blocks0[i].level_frame for i in bpm.pairs[:, 0]])  # original px -> level px
    s1 = stack_matrices([blocks1[i].level_frame for i in bpm.pairs[:, 1]])
    h = np.linalg.inv(s1) @ bpm.H @ s0
    pair = bpm.match_pair
    xy0, xy1 = np.zeros_like(bpm.xy0), np.zeros_like(bpm.xy1)
    for plane, (w0, w1) in enumerate(bpm.pairs):  # level px -> original px, each plane through its blocks' frames
        rows = pair == plane
        xy0[rows] = blocks0[w0].level_frame.to_original(bpm.xy0[rows])
        xy1[rows] = blocks1[w1].level_frame.to_original(bpm.xy1[rows])
    # The level's upright patch (theta = 0 in image 0) seen in the original: the direction of its x axis there
    # (a simulated view's affine map turns it; a plain level does not), and the patch scales by the frames' areas.
    back0 = np.linalg.inv(s0)[pair]
    angle0 = np.arctan2(back0[:, 1, 0], back0[:, 0, 0])
    f0, f1 = (np.sqrt(np.abs(s[:, 0, 0] * s[:, 1, 1] - s[:, 0, 1] * s[:, 1, 0]))[pair] for s in (s0, s1))
    table = MatchTable(xy0, xy1, angle0, bpm.theta[pair], bpm.scale0 / f0, bpm.scale1 / f1,
                       np.ones(len(pair)), pair, bpm.scores)
    return table, h, plane_sides(h, xy0, pair)


def plane_sides(h: np.ndarray, xy0: np.ndarray, plane_of: np.ndarray) -> np.ndarray:
    """(L,) the side of each plane (+1 or -1): the sign that most of its (M, 2) image-0 matches ``xy0``
    (``plane_of``: (M,) their plane) get as the projective depth of the (L, 3, 3) homographies ``h``."""
    side = np.ones(len(h))
    for plane in range(len(h)):  # one small projection per plane
        _, w = project(h[plane], xy0[plane_of == plane])
        side[plane] = 1.0 if np.sum(np.sign(w)) >= 0 else -1.0
    return side


@dataclass
class BlockPlanes:
    """The planes of Secs. 3.2-3.3 in original-image pixels, the frame of every later stage.

    Attributes:
        level_matches: the planes and their matches as found, in level pixels.
        raw: (M rows) every plane's matches (theta = 0 in image 0, theta* of its plane in image 1).
        table: ``raw`` with exact duplicates merged into weighted rows (``deduplicate``): the match table of
            Secs. 3.4-3.8.
        H: (L, 3, 3) homographies original image 0 -> original image 1; side: (L,) their plane sides.
        counts: block pairs, first-run planes, re-matched pairs, planes, block matches, unique block matches.
    """

    level_matches: BlockPairMatches
    raw: MatchTable
    table: MatchTable
    H: np.ndarray
    side: np.ndarray
    counts: dict[str, int]

    def joined(self, other: BlockPlanes, offset0: int, offset1: int = 0) -> BlockPlanes:
        """These planes followed by ``other``'s (found with blocks numbered from ``offset0`` in image 0 and
        ``offset1`` in image 1, e.g. a simulated view's), in one deduplicated match table; the counts add up."""
        raw = MatchTable.concatenate([self.raw, replace(other.raw, source=other.raw.source + len(self.H))])
        table, _ = deduplicate(raw)
        counts = {k: self.counts.get(k, 0) + other.counts.get(k, 0) for k in {*self.counts, *other.counts}}
        counts.update(block_matches=len(raw), block_matches_unique=len(table))
        return BlockPlanes(self.level_matches.joined(other.level_matches, offset0, offset1), raw, table,
                           np.concatenate([self.H, other.H]), np.concatenate([self.side, other.side]), counts)

    def swapped(self) -> BlockPlanes:
        """The same planes with the two images' roles exchanged: homographies inverted, each match's image 1
        keypoint first."""
        raw = self.raw.swapped()
        h = np.linalg.inv(self.H)
        return BlockPlanes(self.level_matches.swapped(), raw, self.table.swapped(), h,
                           plane_sides(h, raw.xy0, raw.source), dict(self.counts))

    def arrays(self) -> dict[str, np.ndarray]:
        """The planes and the match table, for ``--save-stages``."""
        return {"planes_pairs": self.level_matches.pairs, "planes_H": self.H, "planes_theta": self.level_matches.theta,
                "block_matches_xy0": self.raw.xy0, "block_matches_xy1": self.raw.xy1,
                "block_matches_plane": self.raw.source,
                "table_xy0": self.table.xy0, "table_xy1": self.table.xy1, "table_weight": self.table.weight}


def block_planes(pipeline: BasePipeline, levels0: list[ScaleLevel], levels1: list[ScaleLevel], blocks0: list[Block],
                 blocks1: list[Block], ransac: HomographyRansacConfig, bins: int = 16, min_matches: int = 8,
                 seed: int = 0, workers: int = 1, fixed: FixedDescriptors | None = None, matching: str = "pairs",
                 matched: LevelPairMatches | None = None) -> BlockPlanes:
    """Secs. 3.2-3.3 (``match_block_pairs``, same arguments), the planes mapped to original pixels and their
    matches gathered in one deduplicated match table."""
    matches, counts = match_block_pairs(pipeline, levels0, levels1, blocks0, blocks1, ransac, bins=bins,
                                        min_matches=min_matches, seed=seed, workers=workers, fixed=fixed,
                                        matching=matching, matched=matched)
    raw, h, side = block_planes_to_original(matches, blocks0, blocks1)
    table, _ = deduplicate(raw)
    counts.update(block_matches=len(raw), block_matches_unique=len(table))
    return BlockPlanes(matches, raw, table, h, side, counts)
