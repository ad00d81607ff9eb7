"""Simulated views of image 0 as more block levels (ASIFT tilts, :mod:`slime_match.views`).

A view is one more set of levels of image 0: its image is detected and described once per block scale like
the image itself (through the features stage and its cache), its blocks are paired with image 1's blocks,
and its planes are mapped back to the original frame through the view's affine map
(``Block.level_frame``), so that expansion, tiles, the vote and the refinement see ordinary planes.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..geometry.ransac import HomographyRansacConfig
from ..pipelines import BasePipeline
from ..views import simulate_view, views_of_tilt
from .block_planes import BlockPlanes, block_planes
from .blocks import Block, BlockConfig, make_view_blocks
from .fixed_descriptors import FixedDescriptors
from .level_cache import LevelCache, feature_levels
from .levels import LevelRequest, ScaleLevel

__all__ = ["ViewPlanes", "view_planes"]


@dataclass
class ViewPlanes:
    """The planes found by the views of one tilt.

    Attributes:
        planes: the views' block planes (image-0 block indices into ``blocks``).
        blocks: every view's blocks, view after view.
        views: how many views were simulated.
        reused: feature sets answered by the cache.
    """

    planes: BlockPlanes
    blocks: list[Block]
    views: int
    reused: int


def view_planes(pipeline: BasePipeline, image0: np.ndarray, tilt: float, levels1: list[ScaleLevel],
                blocks1: list[Block], blocks: BlockConfig, ransac: HomographyRansacConfig, detection: str,
                bins: int, min_matches: int, seed: int, workers: int, cache: LevelCache | None,
                fixed: FixedDescriptors | None = None, matching: str = "pairs") -> ViewPlanes:
    """Secs. 3.1-3.3 for the views of image 0 at ``tilt`` (ASIFT's rotations) against image 1's blocks.

    Args:
        image0: (H, W, 3) float image 0 (the working image).
        levels1, blocks1: image 1's block levels and blocks (the plain run's).
        blocks, ransac, detection, bins, min_matches, seed, workers, matching: as for the plain block stage.
        cache: the features cache (a view's features depend on the image and the view only).
        fixed: the plain block stage's fixed-orientation descriptors (image 1's are reused, not described again).
    """
    height, width = image0.shape[:2]
    requests = []
    for angle in views_of_tilt(tilt):
        view_image, view = simulate_view(image0, tilt, angle)
        requests.append(LevelRequest(view_image, make_view_blocks(height, width, view, blocks), detection=detection))
    features = feature_levels(pipeline, requests, workers, cache)
    all_blocks: list[Block] = []
    levels0: list[ScaleLevel] = []
    for request, levels in zip(requests, features.levels):  # one numbering of the views' blocks
        offset = len(all_blocks)
        levels0 += [replace(level, blocks=[offset + i for i in level.blocks]) for level in levels]
        all_blocks += request.blocks
    planes = block_planes(pipeline, levels0, levels1, all_blocks, blocks1, ransac, bins=bins,
                          min_matches=min_matches, seed=seed, workers=workers, fixed=fixed, matching=matching)
    return ViewPlanes(planes, all_blocks, len(requests), features.reused)
