"""Simulated views of one image as more block levels (ASIFT tilts, :mod:`slime_match.views`).

A view is one more set of levels of the image it simulates: its image is detected and described once per
block scale like the image itself (through the features stage and its cache), its blocks are paired with the
other image's blocks, and its planes are mapped back to the original frame through the view's affine map
(``Block.level_frame``), so that expansion, tiles, the vote and the refinement see ordinary planes. The view
takes image 0's part in Secs. 3.2-3.3 (orientation 0) and the other image is described under the planes'
fixed orientations; the planes of image 1's views are then turned round (``BlockPlanes.swapped``) so that
every plane maps image 0 to image 1.
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
    """The planes found by the views of one image at one tilt.

    Attributes:
        image: the image whose views they are (0 or 1).
        planes: the views' block planes, image 0 -> image 1; the viewed image's block indices point into
            ``blocks``.
        blocks: every view's blocks, view after view.
        views: how many views were simulated.
        reused: feature sets answered by the cache.
    """

    image: int
    planes: BlockPlanes
    blocks: list[Block]
    views: int
    reused: int


def view_planes(pipeline: BasePipeline, image: np.ndarray, which: int, tilt: float, other_levels: list[ScaleLevel],
                other_blocks: list[Block], blocks: BlockConfig, ransac: HomographyRansacConfig, detection: str,
                bins: int, min_matches: int, seed: int, workers: int, cache: LevelCache | None,
                fixed: FixedDescriptors | None = None, matching: str = "pairs") -> ViewPlanes:
    """Secs. 3.1-3.3 for the views at ``tilt`` (ASIFT's rotations) of image ``which`` against the other
    image's blocks.

    Args:
        image: (H, W, 3) float working image ``which`` (0 or 1).
        other_levels, other_blocks: the other image's block levels and blocks (the plain run's).
        blocks, ransac, detection, bins, min_matches, seed, workers, matching: as for the plain block stage.
        cache: the features cache (a view's features depend on the image and the view only).
        fixed: the plain block stage's fixed-orientation descriptors (the other image's are reused, not
            described again).
    """
    height, width = image.shape[:2]
    requests = []
    for angle in views_of_tilt(tilt):
        view_image, view = simulate_view(image, tilt, angle)
        requests.append(LevelRequest(view_image, make_view_blocks(height, width, view, blocks), detection=detection))
    features = feature_levels(pipeline, requests, workers, cache)
    all_blocks: list[Block] = []
    levels: list[ScaleLevel] = []
    for request, found in zip(requests, features.levels):  # one numbering of the views' blocks
        offset = len(all_blocks)
        levels += [replace(level, blocks=[offset + i for i in level.blocks]) for level in found]
        all_blocks += request.blocks
    planes = block_planes(pipeline, levels, other_levels, all_blocks, other_blocks, ransac, bins=bins,
                          min_matches=min_matches, seed=seed, workers=workers, fixed=fixed, matching=matching)
    return ViewPlanes(which, planes if which == 0 else planes.swapped(), all_blocks, len(requests), features.reused)
