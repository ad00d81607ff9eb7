"""A second base pipeline's block planes (Secs. 3.2-3.3), pooled with the base's before Sec. 3.4.

Two bases find planes in different places (another detector, another descriptor, another matcher): ALIKED
and DISK, for instance, each match some wide-baseline block pairs the other misses. The second base detects
and describes the same blocks with its own detection and block matching, and its planes join the base's in
one match table (:meth:`~.block_planes.BlockPlanes.joined`), as simulated views' planes do; expansion,
the tile sets and the epipolar vote then choose among all of them. Views, tiles (Sec. 3.8) and the final
matches stay the base's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._runtime.forking import torch_threads
from ..geometry.ransac import HomographyRansacConfig
from ..pipelines import BasePipeline
from .block_planes import BlockPlanes, block_planes
from .blocks import Block
from .fixed_descriptors import FixedDescriptors
from .level_cache import LevelCache, feature_levels
from .levels import LevelRequest

__all__ = ["PooledBase"]


@dataclass
class PooledBase:
    """The second base pipeline of ``SlimeConfig.pool`` and the block features it has computed.

    Attributes:
        pipeline: the second base pipeline (its own ``slime_detection`` and ``slime_block_matching``).
        level_cache: its block features of images met before (None: computed each time).
    """

    pipeline: BasePipeline
    level_cache: LevelCache | None = None

    def block_planes(self, image0: np.ndarray, image1: np.ndarray, blocks0: list[Block], blocks1: list[Block],
                     ransac: HomographyRansacConfig, bins: int, min_matches: int, seed: int, workers: int
                     ) -> BlockPlanes:
        """Secs. 3.2-3.3 on the second base for the (H, W, 3) float working images and their blocks (the
        base's layout): planes image 0 -> image 1 in original px, with block indices into ``blocks0`` and
        ``blocks1``, ready to join the base's planes."""
        pipeline = self.pipeline
        detection = pipeline.slime_detection
        features = feature_levels(pipeline, [LevelRequest(image0, blocks0, detection=detection),
                                             LevelRequest(image1, blocks1, detection=detection)],
                                  workers, self.level_cache)
        with torch_threads(1):
            return block_planes(pipeline, *features.levels, blocks0, blocks1, ransac, bins=bins,
                                min_matches=min_matches, seed=seed, workers=workers,
                                fixed=FixedDescriptors(pipeline, bins, workers),
                                matching=pipeline.slime_block_matching)
