"""Slime (paper Sec. 3) on top of any base pipeline: each stage takes the previous stages' results and adds
its own, with its counts.

Stages and where they live:
    3.1 blocks and tiles ............ :mod:`.blocks`; their features: :mod:`.levels` (:mod:`.level_cache`)
    3.2-3.3 block planes ............ :mod:`.block_planes` (:mod:`.fixed_descriptors`, :mod:`.jobs`)
    a second base's planes (ours) ... :mod:`.pooled_base` (they join the block planes)
    simulated views (ours) .......... :mod:`.view_step`, :mod:`.view_planes` (their planes join the block planes)
    3.4 expansion and pruning ....... :mod:`.expansion`
    3.5 tile sets ................... :mod:`.tile_sets`
    3.6 the epipolar vote ........... :mod:`.epipolar_vote`
    3.7 fusion, global orientation .. :mod:`.fusion` (3.5-3.7 in order: :mod:`.selection`)
    3.8 tile refinement + global DTM  :mod:`.refine`
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from .._runtime.compiled import warm_up
from .._runtime.cpus import available_cpus
from .._runtime.forking import torch_threads
from .._runtime.options import check_choice, check_integer
from .._runtime.timing import StageTimer
from ..errors import ConfigError
from ..geometry.frames import Frame, homographies_to_original
from ..geometry.ransac import HomographyRansacConfig
from ..pipelines import BasePipeline
from ..views import ViewConfig
from .block_planes import BLOCK_MATCHINGS, BlockPlanes, block_planes
from .blocks import Block, BlockConfig, make_blocks, make_tiles
from .diagnostics import empty_result_reason, layout_warning, tile_count_warning
from .dtm_frame import DTM_MAX_TILT
from .expansion import Expansion, PlaneConfig, expand_planes
from .fixed_descriptors import FixedDescriptors
from .level_cache import LevelCache, feature_levels
from .levels import DETECTIONS, LevelRequest
from .pooled_base import PooledBase
from .refine import TILE_TESTS, FlowGuide, PlaneGuide, TileMatches, final_matches, match_tiles, tile_test
from .selection import PlaneSelection, select_planes
from .tile_sets import TileConfig
from .view_planes import ViewPlanes, view_planes
from .view_step import PlainTilt, PlaneState, add_views

logger = logging.getLogger("slime_match")


@dataclass
class SlimeConfig:
    """Slime's parameters (paper defaults).

    Attributes:
        blocks: block/tile geometry (256 px, 32 px padding, stride 128 +- 24, scales 1, 2, 3).
        ransac: the block-pair homography RANSAC (t_perp = 15 px, 100..10,000 iterations, p = 0.9).
        planes: expansion thresholds (t_perp = 15 px, t_theta = 67.5 deg, t_sigma = 3).
        tiles: tile-set logic (2 per tile pair, 4 per tile, t_xi = 9, t_ov = 1/3, 16 bins, 45 deg).
        bins: orientation histogram bins of the block-pair refinement (16).
        min_plane_matches: a block pair yields a plane only with at least this many RANSAC inliers, as many
            distinct keypoints in each image (ours: the paper does not state a minimum; 4 would be any minimal
            sample).
        workers: processes for the detections, block pairs and tiles, and threads for the epipolar vote
            (None = one per CPU this process may use, ``available_cpus``; the matches do not depend on it).
            On CUDA the networks stay in one process and the workers run the block crops' detector and the
            block and tile pairs (Blob matching, DTM, RANSAC) on the CPU.
        refine_tiles: run Sec. 3.8 (tile re-matching + global DTM); False stops at F^theta.
        global_dtm: the final DTM on the union of F^theta and tile matches (Sec. 3.8); None: the base
            pipeline's ``slime_global_dtm`` (the paper's Slimed Key.Net runs none). Exact duplicates are merged
            either way.
        dtm_max_tilt: the global DTM compares image 0's matches in image 1's frame (through the matches'
            robust affine map) when that map stretches one direction more than this many times the other
            (ours, :mod:`.dtm_frame`: Delaunay neighbourhoods do not survive an extreme viewpoint's tilt);
            inf: always the images' own frames (the paper's).
        keep_stages: keep every stage's sets in the result (for ``slime viz`` / ``--save-stages``).
        detection: how blocks get their keypoints (``levels.DETECTIONS``): "scale" detects and
            describes each block scale once on the whole scaled image, each block owning its core's keypoints
            (the sharing suggested by the paper's SM); "block" detects and describes each 256 px block crop on
            its own, as the paper's prototype (adaptive detection per block, slower); "merged" detects each
            block crop on its own but describes the keypoints shared by overlapping blocks once; None: the
            base pipeline's ``slime_detection`` ("merged" for Hz+, "scale" for RootSIFT and Key.Net).
        tile_detection: the same choice for the full-resolution tiles of Sec. 3.8 ("scale" by default).
        block_matching: how a block pair's first matches are found (``block_planes.BLOCK_MATCHINGS``): "pairs",
            the base pipeline on each block pair (the paper's); "levels", the base pipeline once on each pair of
            block scales' whole images, each block pair taking the matches between its cores (a matcher that
            reads the whole image, LightGlue, keeps its context); None: the base pipeline's
            ``slime_block_matching`` ("pairs" for the handcrafted bases).
        tile_test: which tile candidates Sec. 3.8 keeps (``refine.TILE_TESTS``): "plane" (within t_perp of
            the plane homography of one of the tile pair's F^theta sets, on its side: the whole tile pair
            where the plane holds, not only near the block matches; ours, the default: more coverage on
            planar and hard pairs, docs/coverage.md); "flow", the paper's (a match of F^theta within t_perp
            at both ends).
        pool: a second registered base pipeline (e.g. "disk-lg" under an ALIKED base) whose block planes join
            the base's before Sec. 3.4 (:mod:`.pooled_base`); it runs with the base's options, those it reads,
            and its own detection and block matching; views, tiles and the final matches stay the base's.
            None: the base alone.
    """

    blocks: BlockConfig = field(default_factory=BlockConfig)
    ransac: HomographyRansacConfig = field(default_factory=HomographyRansacConfig)
    planes: PlaneConfig = field(default_factory=PlaneConfig)
    tiles: TileConfig = field(default_factory=TileConfig)
    bins: int = 16
    min_plane_matches: int = 8
    workers: int | None = None
    refine_tiles: bool = True
    global_dtm: bool | None = None
    dtm_max_tilt: float = DTM_MAX_TILT
    keep_stages: bool = False
    detection: str | None = None
    tile_detection: str = "scale"
    block_matching: str | None = None
    tile_test: str = "plane"
    pool: str | None = None

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> SlimeConfig:
        """Check the choices and counts (ConfigError naming the valid ones)."""
        check_integer("workers", self.workers, 1, optional=True)
        check_integer("bins", self.bins, 1)
        check_integer("min_plane_matches", self.min_plane_matches, 4)
        if not self.dtm_max_tilt >= 1:
            raise ConfigError(f"dtm_max_tilt must be >= 1 (inf: never), got {self.dtm_max_tilt}")
        if self.detection is not None:
            check_choice("detection", self.detection, DETECTIONS)
        check_choice("tile_detection", self.tile_detection, DETECTIONS)
        if self.block_matching is not None:
            check_choice("block_matching", self.block_matching, BLOCK_MATCHINGS)
        check_choice("tile_test", self.tile_test, TILE_TESTS)
        if self.pool is not None and not isinstance(self.pool, str):
            raise ConfigError(f"pool must name a base pipeline (e.g. 'disk-lg') or be None, got {self.pool!r}")
        return self


@dataclass
class SlimeOutput:
    """Final matches (original px), counts per stage, warnings (why a result is empty, slow layouts), the
    rules that decided adaptive stages and why (e.g. ``{"vote": "consensus", "vote_reason": ...}``) with the
    block detection and block matching the run took (the base's defaults where the configuration leaves them
    None), optionally every stage's arrays, and the tilt of the plain F^theta's matches (before any view)."""

    xy0: np.ndarray
    xy1: np.ndarray
    scores: np.ndarray
    counts: dict[str, int]
    stages: dict[str, np.ndarray] | None
    warnings: list[str] = field(default_factory=list)
    decisions: dict[str, str] = field(default_factory=dict)
    plain_tilt: PlainTilt | None = None


@dataclass
class Layout:
    """Sec. 3.1: the blocks (every scale) and the full-resolution tiles of each image."""

    blocks0: list[Block]
    blocks1: list[Block]
    tiles0: list[Block]
    tiles1: list[Block]

    @classmethod
    def of(cls, size0: tuple[int, int], size1: tuple[int, int], config: BlockConfig) -> Layout:
        """The layout of images of (H, W) ``size0`` and ``size1``."""
        return cls(make_blocks(*size0, config), make_blocks(*size1, config), make_tiles(*size0, config),
                   make_tiles(*size1, config))

    def arrays(self) -> dict[str, np.ndarray]:
        """Block and tile cores in original px, for ``--save-stages``."""
        return {"blocks0": _boxes_original(self.blocks0), "blocks1": _boxes_original(self.blocks1),
                "tiles0": _boxes_original(self.tiles0), "tiles1": _boxes_original(self.tiles1)}


def run_slime(pipeline: BasePipeline, image0: np.ndarray, image1: np.ndarray, config: SlimeConfig,
              timer: StageTimer | None = None, seed: int = 0, level_cache: LevelCache | None = None,
              views: ViewConfig | None = None, pooled: PooledBase | None = None) -> SlimeOutput:
    """Run Slime on two (H, W, 3) float images with ``pipeline`` as the base.

    Args:
        level_cache: block and tile features of images met before (with this pipeline and ``config``), read
            and filled by the features stage; None computes them all.
        views: simulated views (:class:`~slime_match.views.ViewConfig`); None: off. Their planes join the
            block planes before Sec. 3.4 (:mod:`.view_step`: "auto" adds them, tilt after tilt and each image's
            views a branch of its own, only while the plane selection finds too little consistent geometry).
        pooled: the second base of ``config.pool``, whose block planes join the base's; None: the base alone.

    Returns:
        SlimeOutput with matches in original pixels sorted by score (lower is better).
    """
    timer = timer or StageTimer()
    views = views or ViewConfig(mode="off")
    size0, size1 = image0.shape[:2], image1.shape[:2]
    layout = Layout.of(size0, size1, config.blocks)
    warnings: list[str] = []

    def warn(message: str) -> None:
        warnings.append(message)
        logger.warning(message)

    workers = _workers(config.workers)
    logger.info("Slime: %d x %d blocks (%d block pairs), %d and %d tiles, %d worker process%s",
                len(layout.blocks0), len(layout.blocks1), len(layout.blocks0) * len(layout.blocks1),
                len(layout.tiles0), len(layout.tiles1), workers, "" if workers == 1 else "es")
    for message in (layout_warning(len(layout.blocks0), len(layout.blocks1)),
                    tile_count_warning(len(layout.tiles0), len(layout.tiles1))):
        if message:
            warn(message)
    if workers > 1:  # loaded once here, the forked workers of every stage inherit the compiled loops
        pipeline.load_kernels()
        if pooled is not None:
            pooled.pipeline.load_kernels()
        warm_up("ransac")
    with timer("features"):  # the tiles' regions too (Sec. 3.8), so that all detections share the workers
        detection = config.detection or pipeline.slime_detection
        requests = [LevelRequest(image0, layout.blocks0, detection=detection),
                    LevelRequest(image1, layout.blocks1, detection=detection)]
        if config.refine_tiles:
            requests += [LevelRequest(image, tiles, regions_only=True, detection=config.tile_detection)
                         for image, tiles in ((image0, layout.tiles0), (image1, layout.tiles1))]
        features = feature_levels(pipeline, requests, workers, level_cache)
    fixed = FixedDescriptors(pipeline, config.bins, workers)  # shared by the plain blocks and the views
    matching = config.block_matching or pipeline.slime_block_matching
    with timer("block_pairs"), torch_threads(1):
        planes = block_planes(pipeline, *features.levels[:2], layout.blocks0, layout.blocks1, config.ransac,
                              bins=config.bins, min_matches=config.min_plane_matches, seed=seed, workers=workers,
                              fixed=fixed, matching=matching)
    pool_counts: dict[str, int] = {}
    pool_decisions: dict[str, str] = {}
    if pooled is not None:
        with timer("pooled_base"):
            pool_planes = pooled.block_planes(image0, image1, layout.blocks0, layout.blocks1, config.ransac, config.bins,
                                              config.min_plane_matches, seed, workers)
        pool_counts["pooled_planes"] = len(pool_planes.H)
        pool_decisions["pool"] = (f"{pooled.pipeline.name}: {len(pool_planes.H)} block planes pooled with the "
                                  f"base's {len(planes.H)}")
        logger.info("Pooled base %s", pool_decisions["pool"])
        planes = planes.joined(pool_planes, 0, 0)  # the same blocks: no block index moves
    images = image0, image1

    def find(image: int, tilt: float) -> ViewPlanes:
        with timer("views"), torch_threads(1):
            found = view_planes(pipeline, images[image], image, tilt, features.levels[1 - image],
                                (layout.blocks0, layout.blocks1)[1 - image], config.blocks, config.ransac, detection,
                                config.bins, config.min_plane_matches, seed, workers, level_cache, fixed, matching,
                                views.min_probe, views.screen_keypoints)
        logger.info("Views of image %d at tilt %g: %d views (%d paired), %d planes", image, tilt, found.views,
                    found.paired, len(found.planes.H))
        return found

    def select(found: BlockPlanes) -> tuple[Expansion, PlaneSelection]:
        return _select(found, layout, config, workers, timer)

    plain = PlaneState(planes, *select(planes), list(layout.blocks0), list(layout.blocks1))
    plain_tilt = PlainTilt.of(plain, size1)
    keypoints = tuple(max((len(core) for level in levels for core in level.members), default=0)
                      for levels in features.levels[:2])
    state, record = add_views(plain, views, find, select, pipeline.slime_view_gain, plain_tilt, keypoints,
                              config.min_plane_matches)
    if views.mode != "off":
        logger.info("Views: %s", record.reason)
    planes, expansion, selection = state.planes, state.expansion, state.selection
    logger.info("Epipolar vote (Sec. 3.6): %s", selection.vote_reason)
    table = planes.table
    ftheta = selection.ftheta
    in_ftheta = ftheta.union()
    tiles = None
    if config.refine_tiles:
        tiles = TileMatches.empty()
        if len(ftheta):
            with timer("tile_refinement"), torch_threads(1):
                test = tile_test(config.tile_test,
                                 FlowGuide(table.xy0[in_ftheta], table.xy1[in_ftheta], config.planes.t_perp),
                                 PlaneGuide(planes.H, planes.side, config.planes.t_perp))
                tiles = match_tiles(pipeline, *features.levels[2:], layout.tiles0, layout.tiles1,
                                    np.stack([ftheta.tile0, ftheta.tile1], 1), selection.theta, ftheta.plane, test,
                                    bins=config.tiles.bins, workers=workers)
    with timer("global_dtm"):
        run_dtm = pipeline.slime_global_dtm if config.global_dtm is None else config.global_dtm
        final = final_matches(table.xy0[in_ftheta], table.xy1[in_ftheta], table.score[in_ftheta], tiles, size0,
                              size1, run_dtm, getattr(getattr(pipeline, "config", None), "dtm", None),
                              config.dtm_max_tilt)
    results = (features, planes, expansion, selection, tiles or TileMatches.empty(), final)
    counts = {name: value for result in results for name, value in result.counts.items()}
    if not len(final.xy0):
        warn("Slime found no match: " + empty_result_reason(counts, config.tiles))
    stages = None
    if config.keep_stages:
        stages = {name: array for result in (layout, *results[1:]) for name, array in result.arrays().items()}
        for image, blocks in enumerate((state.blocks0, state.blocks1)):
            stages.update(_plane_blocks(planes.level_matches.pairs[:, image], blocks, image))
    counts["views"] = record.views
    counts.update(pool_counts)
    decisions = {"vote": selection.vote, "vote_reason": selection.vote_reason, "views": record.as_dict(),
                 "detection": detection, "block_matching": matching, **pool_decisions}
    if final.dtm_frame:
        decisions["global_dtm"] = final.dtm_frame
    return SlimeOutput(final.xy0, final.xy1, final.scores, counts, stages, warnings, decisions, plain_tilt)


def _select(planes: BlockPlanes, layout: Layout, config: SlimeConfig, workers: int, timer: StageTimer
            ) -> tuple[Expansion, PlaneSelection]:
    """Secs. 3.4-3.7 on the block planes: expansion, then the selection of F^theta."""
    with timer("expansion"):
        expansion = Expansion(expand_planes(planes.table, planes.H, planes.side, config.planes, threads=workers))
    with timer("plane_selection"):
        selection = select_planes(planes.table, expansion.memberships, layout.tiles0, layout.tiles1, config.tiles,
                                  threads=workers)
    return expansion, selection


def _workers(requested: int | None) -> int:
    """Worker processes for Slime's stages: ``requested``, or one per CPU this process may use
    (``available_cpus``). On CUDA they run only CPU work: the networks stay in one process (see
    ``device_workers`` and ``uses_cuda``)."""
    return max(1, requested) if requested is not None else available_cpus()


def _plane_blocks(block_of_plane: np.ndarray, blocks: list[Block], image: int) -> dict[str, np.ndarray]:
    """Each plane's block in image ``image`` for ``--save-stages``: ``planes_corners<image>`` (L, 4, 2) its core's
    corners in original px (a simulated view's block is a turned, stretched quadrilateral there) and
    ``planes_view<image>`` (L, 2) the tilt and angle in degrees of its view (1, 0: the image itself)."""
    corners, views = np.zeros((len(block_of_plane), 4, 2)), np.tile([1.0, 0.0], (len(block_of_plane), 1))
    for plane, w in enumerate(block_of_plane):
        block = blocks[w]
        corners[plane] = _core_corners(block)
        if block.view is not None:
            views[plane] = block.view.tilt, block.view.angle
    return {f"planes_corners{image}": corners, f"planes_view{image}": views}


def _boxes_original(blocks: list[Block]) -> np.ndarray:
    """(n, 5) [x0, y0, x1, y1, scale_index] of block cores in original px."""
    out = np.zeros((len(blocks), 5))
    for i, b in enumerate(blocks):
        corners = _core_corners(b)
        out[i] = [*corners[0], *corners[2], b.scale_index]
    return out


def _core_corners(block: Block) -> np.ndarray:
    """(4, 2) the corners of a block's core in original px: top-left, top-right, bottom-right, bottom-left of
    its level (pixel edges, half a pixel outside the centres)."""
    x0, y0, x1, y1 = (np.asarray(block.core, np.float64) - 0.5).tolist()
    return block.level_frame.to_original(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]))


def stages_to_original(stages: dict[str, np.ndarray], frame0: Frame, frame1: Frame) -> dict[str, np.ndarray]:
    """Stage arrays of images matched in working frames ``frame0``, ``frame1`` (``resize.resize_image``, image 1
    perhaps turned by quarter turns: ``quarter_turns.turned_frame``), in original-image pixels: points, block and
    tile boxes, the planes' image-0 block corners and homographies (orientations stay as measured when
    matching)."""
    out = dict(stages)
    for image, frame in ((0, frame0), (1, frame1)):
        for key, value in stages.items():
            if key.endswith(f"_xy{image}"):
                out[key] = frame.to_original(value)
        for key in (f"blocks{image}", f"tiles{image}"):
            boxes = stages[key].copy()
            corner, other = frame.to_original(boxes[:, 0:2]), frame.to_original(boxes[:, 2:4])
            boxes[:, 0:2], boxes[:, 2:4] = np.minimum(corner, other), np.maximum(corner, other)  # a turn swaps them
            out[key] = boxes
    out["planes_H"] = homographies_to_original(stages["planes_H"], frame0, frame1)
    for image, frame in ((0, frame0), (1, frame1)):
        corners = stages[f"planes_corners{image}"]
        out[f"planes_corners{image}"] = frame.to_original(corners.reshape(-1, 2)).reshape(corners.shape)
    return out
