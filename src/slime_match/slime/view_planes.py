"""Simulated views of one image as more block levels (ASIFT tilts, :mod:`slime_match.views`).

A view is one more set of levels of the image it simulates: its image is detected and described once per
block scale like the image itself (through the features stage and its cache), its blocks are paired with the
other image's blocks, and its planes are mapped back to the original frame through the view's affine map
(``Block.level_frame``), so that expansion, tiles, the vote and the refinement see ordinary planes. The view
takes image 0's part in Secs. 3.2-3.3 (orientation 0) and the other image is described under the planes'
fixed orientations; the planes of image 1's views are then turned round (``BlockPlanes.swapped``) so that
every plane maps image 0 to image 1. Where blocks are matched by whole levels, a view is probed (screened,
then matched on its finest level) before its other levels are detected and paired (:func:`view_planes`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..geometry.ransac import HomographyRansacConfig
from ..pipelines import BasePipeline
from ..pipelines.view_matching import consistent_matches
from ..types import Matches
from ..views import simulate_view, views_of_tilt
from .block_planes import BlockPlanes, LevelPairMatches, block_planes, level_pair_key, match_level_pairs
from .blocks import Block, BlockConfig, make_view_blocks
from .fixed_descriptors import FixedDescriptors
from .level_cache import LevelCache, feature_levels
from .levels import LevelRequest, ScaleLevel

__all__ = ["SCREEN_FLOOR", "ViewPlanes", "view_planes"]

# consistent matches a view's screen needs: more than the 7-9 that the best fundamental matrix holds on
# matches that share no geometry (its 7-point sample and one or two more by chance)
SCREEN_FLOOR = 10


@dataclass
class ViewPlanes:
    """The planes found by the views of one image at one tilt.

    Attributes:
        image: the image whose views they are (0 or 1).
        planes: the views' block planes, image 0 -> image 1; the viewed image's block indices point into
            ``blocks``.
        blocks: the blocks of every view whose blocks were paired, view after view.
        views: how many views were simulated.
        reused: feature sets answered by the cache.
        probes: per view angle in degrees (``f"{angle:g}"``) probed in full, the matches of its probe
            consistent with one fundamental matrix; empty when the views were not probed.
        screens: per view angle, the same count on the screen's strongest keypoints; empty without a screen.
        paired: how many views had their blocks paired (all of them when not probed).
    """

    image: int
    planes: BlockPlanes
    blocks: list[Block]
    views: int
    reused: int
    probes: dict[str, int] = field(default_factory=dict)
    screens: dict[str, int] = field(default_factory=dict)
    paired: int = 0


def view_planes(pipeline: BasePipeline, image: np.ndarray, which: int, tilt: float, other_levels: list[ScaleLevel],
                other_blocks: list[Block], blocks: BlockConfig, ransac: HomographyRansacConfig, detection: str,
                bins: int, min_matches: int, seed: int, workers: int, cache: LevelCache | None,
                fixed: FixedDescriptors | None = None, matching: str = "pairs", min_probe: int = 0,
                screen_keypoints: int = 0) -> ViewPlanes:
    """Secs. 3.1-3.3 for the views at ``tilt`` (ASIFT's rotations) of image ``which`` against the other
    image's blocks.

    With level matching (``matching="levels"``) and ``min_probe`` > 0, each view is probed first: its finest
    level is matched against the other image's level of the nearest scale factor (one call of the base
    pipeline, kept for the block pairs), and only the views whose probe holds ``min_probe`` matches consistent
    with one fundamental matrix (:func:`~slime_match.pipelines.view_matching.consistent_matches`) have their
    other levels detected and their blocks paired. A view that compresses the wrong image, or the right one
    at the wrong angle, finds no common epipolar geometry at any scale, and each of its level pairs costs a
    whole-image match. With ``screen_keypoints`` > 0 the probe is screened first: the same two levels
    reduced to their ``screen_keypoints`` strongest keypoints each, and only a view whose screen holds
    ``SCREEN_FLOOR`` consistent matches is probed in full (a screen takes about a third of a probe's time).

    Args:
        image: (H, W, 3) float working image ``which`` (0 or 1).
        other_levels, other_blocks: the other image's block levels and blocks (the plain run's).
        blocks, ransac, detection, bins, min_matches, seed, workers, matching: as for the plain block stage.
        cache: the features cache (a view's features depend on the image and the view only).
        fixed: the plain block stage's fixed-orientation descriptors (the other image's are reused, not
            described again).
        min_probe: the probe's consistent matches a view needs (0: no probe, every view's blocks are paired).
        screen_keypoints: the keypoints a side of the probe's screen (0: no screen).
    """
    height, width = image.shape[:2]
    angles = views_of_tilt(tilt)
    simulated = [simulate_view(image, tilt, angle) for angle in angles]
    view_blocks = [make_view_blocks(height, width, view, blocks) for _, view in simulated]
    probing = matching == "levels" and detection != "block" and min_probe > 0
    finest = max(b.scale_index for found in view_blocks for b in found) if probing else None
    # Each view's blocks in two requests: the probe's (its finest scale; none without a probe), the coarser ones.
    split = [([b for b in found if b.scale_index == finest], [b for b in found if b.scale_index != finest])
             for found in view_blocks]
    chosen, probes, screens, probe_levels, probe_matches, reused = list(range(len(angles))), {}, {}, {}, {}, 0
    if probing:
        with_probe = [v for v in chosen if split[v][0]]
        found = feature_levels(pipeline, [LevelRequest(simulated[v][0], split[v][0], detection=detection)
                                          for v in with_probe], workers, cache)
        reused = found.reused
        probe_levels = {v: (levels[0], _nearest(levels[0], other_levels)) for v, levels in zip(with_probe, found.levels)}
        screened = with_probe
        if screen_keypoints > 0:
            reduced = {id(other): _strongest(other, screen_keypoints) for _, other in probe_levels.values()}
            small = {v: (_strongest(level, screen_keypoints), reduced[id(other)])
                     for v, (level, other) in probe_levels.items()}
            small_matches = match_level_pairs(pipeline, list(small.values()), workers)
            screen_counts = {v: _consistent(*pair, small_matches[level_pair_key(*pair)], seed)
                             for v, pair in small.items()}
            screens = {f"{angles[v]:g}": count for v, count in screen_counts.items()}
            screened = [v for v in with_probe if screen_counts[v] >= SCREEN_FLOOR]
        probe_matches = match_level_pairs(pipeline, [probe_levels[v] for v in screened], workers)
        probe_counts = {v: _consistent(*probe_levels[v], probe_matches[level_pair_key(*probe_levels[v])], seed)
                        for v in screened}
        probes = {f"{angles[v]:g}": count for v, count in probe_counts.items()}
        chosen = [v for v in screened if probe_counts[v] >= min_probe]
    rest = feature_levels(pipeline, [LevelRequest(simulated[v][0], split[v][1], detection=detection) for v in chosen],
                          workers, cache)
    all_blocks: list[Block] = []
    levels: list[ScaleLevel] = []
    matched: LevelPairMatches = {}  # the probes' matches, keyed by the renumbered levels
    for v, coarser in zip(chosen, rest.levels):  # one numbering of the views' blocks, in scale order
        levels += _renumbered(coarser, len(all_blocks))
        all_blocks += split[v][1]
        if probing:
            probe, other = probe_levels[v]
            levels += _renumbered([probe], len(all_blocks))
            matched[level_pair_key(levels[-1], other)] = probe_matches[level_pair_key(probe, other)]
            all_blocks += split[v][0]
    planes = block_planes(pipeline, levels, other_levels, all_blocks, other_blocks, ransac, bins=bins,
                          min_matches=min_matches, seed=seed, workers=workers, fixed=fixed, matching=matching,
                          matched=matched)
    return ViewPlanes(which, planes if which == 0 else planes.swapped(), all_blocks, len(angles),
                      reused + rest.reused, probes, screens, len(chosen))


def _renumbered(levels: list[ScaleLevel], offset: int) -> list[ScaleLevel]:
    """The levels with their block indices moved by ``offset`` (their blocks' place among all views')."""
    return [replace(level, blocks=[offset + i for i in level.blocks]) for level in levels]


def _strongest(level: ScaleLevel, keypoints: int) -> ScaleLevel:
    """The level reduced to its ``keypoints`` features of highest detector response (members re-indexed)."""
    if len(level.features) <= keypoints:
        return level
    keep = level.features.strongest(keypoints).sort().values  # in index order, as the level's
    index = np.full(len(level.features), -1, np.int64)
    index[keep.cpu().numpy()] = np.arange(len(keep))
    members = [index[m][index[m] >= 0] for m in level.members]
    return replace(level, features=level.features.subset(keep), members=members)


def _nearest(level: ScaleLevel, others: list[ScaleLevel]) -> ScaleLevel:
    """The level of ``others`` whose scale factor is nearest ``level``'s (in ratio)."""
    return min(others, key=lambda other: abs(math.log(other.factor / level.factor)))


def _consistent(level: ScaleLevel, other: ScaleLevel, matches: Matches, seed: int) -> int:
    """The matches of two levels, those on ``level``'s blocks' cores, consistent with one fundamental matrix."""
    on_blocks = np.zeros(len(level.features), bool)
    for members in level.members:
        on_blocks[members] = True
    keep = on_blocks[matches.idx0]
    xy0 = level.features.xy.detach().cpu().numpy().astype(np.float64)[matches.idx0[keep]]
    xy1 = other.features.xy.detach().cpu().numpy().astype(np.float64)[matches.idx1[keep]]
    return consistent_matches(xy0, xy1, seed)
