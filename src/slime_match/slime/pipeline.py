"""Slime (paper Sec. 3) on top of any base pipeline: blocks -> planes -> tiles -> epipolar -> refinement.

Stages and where they live:
    3.1 blocks and tiles ............ :mod:`.blocks`
    3.2-3.3 block-pair planes ....... :mod:`.block_matching`
    3.4 expansion and pruning ....... :func:`.planes.expand_planes`
    3.5-3.7 tile sets, epipolar consistency, fusion, global orientation ... :mod:`.tiles`
    3.8 tile refinement + global DTM  :mod:`.refine`
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from ..cpus import available_cpus
from ..geometry import ransac_kernels
from ..geometry.homography import project
from ..geometry.ransac import HomographyRansacConfig
from ..pipelines import BasePipeline
from ..resize import homography_to_original, to_original
from ..timing import StageTimer
from .block_matching import (
    BlockPairMatches,
    LevelRequest,
    ScaleLevel,
    build_levels_many,
    match_block_pairs,
)
from .blocks import Block, BlockConfig, make_blocks, make_tiles
from .forking import torch_threads
from .level_cache import LevelCache, fresh_copy, request_key
from .planes import MatchTable, PlaneConfig, deduplicate, expand_planes
from .refine import FlowGuide, PlaneGuide, global_dtm, match_tiles, merge_duplicates, tile_test
from .tiles import (
    TileConfig,
    TileSets,
    best_sets_per_tile,
    best_sets_per_tile_pair,
    epipolar_consistency,
    fuse_planes,
    global_orientation_filter,
    greedy_two_per_tile,
    plane_groups,
    tile_sets,
)

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
        min_plane_matches: a block pair yields a plane only with at least this many RANSAC inliers
            (ours: the paper does not state a minimum; 4 would be any minimal sample).
        workers: processes for the detections, block pairs and tiles, and threads for the epipolar vote
            (None = one per CPU this process may use, ``available_cpus``; the matches do not depend on it).
            On CUDA the networks stay in one process and the workers run the block crops' detector and the
            block and tile pairs (Blob matching, DTM, RANSAC) on the CPU.
        refine_tiles: run Sec. 3.8 (tile re-matching + global DTM); False stops at F^theta.
        global_dtm: the final DTM on the union of F^theta and tile matches (Sec. 3.8); None: the base
            pipeline's ``slime_global_dtm`` (the paper's Slimed Key.Net runs none). Exact duplicates are merged
            either way.
        keep_stages: keep every stage's sets in the result (for ``slime viz`` / ``--save-stages``).
        detection: how blocks get their keypoints (``block_matching.DETECTIONS``): "scale" detects and
            describes each block scale once on the whole scaled image, each block owning its core's keypoints
            (the sharing suggested by the paper's SM); "block" detects and describes each 256 px block crop on
            its own, as the paper's prototype (adaptive detection per block, slower); "merged" detects each
            block crop on its own but describes the keypoints shared by overlapping blocks once; None: the
            base pipeline's ``slime_detection`` ("merged" for Hz+, "scale" for RootSIFT and Key.Net).
        tile_detection: the same choice for the full-resolution tiles of Sec. 3.8 ("scale" by default).
        tile_test: which tile candidates Sec. 3.8 keeps (``refine.TILE_TESTS``): "flow", the paper's (a match
            of F^theta within t_perp at both ends); "plane" (within t_perp of the plane homography of one of
            the tile pair's F^theta sets, on its side: the whole tile pair where the plane holds, not only
            near the block matches; ours).
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
    keep_stages: bool = False
    detection: str | None = None
    tile_detection: str = "scale"
    tile_test: str = "flow"


@dataclass
class SlimeOutput:
    """Final matches (original px), counts per stage, warnings (why a result is empty, slow layouts), and
    optionally every stage's arrays."""

    xy0: np.ndarray
    xy1: np.ndarray
    scores: np.ndarray
    counts: dict[str, int]
    stages: dict[str, np.ndarray] | None
    warnings: list[str] = field(default_factory=list)


MANY_BLOCK_PAIRS = 4000  # 10x a 4:3 image pair's 400 at the paper's scales: warn, the run will be slow
MANY_TILES = 150  # tiles of one image: about 2048 x 1536 px (140), 12x a 640 x 480 image's


def layout_warning(n_blocks0: int, n_blocks1: int) -> str | None:
    """A warning when the images (elongated ones: blocks follow the shorter side) give very many block pairs."""
    if n_blocks0 * n_blocks1 <= MANY_BLOCK_PAIRS:
        return None
    return (f"{n_blocks0 * n_blocks1} block pairs ({n_blocks0} x {n_blocks1} blocks; a 4:3 pair has 400): blocks "
            "follow each image's shorter side, so an elongated image makes Slime slow and memory-hungry; "
            "fewer block scales (--scales 1,2) or the base pipeline alone (--method hz+) are much faster")


def tile_count_warning(n_tiles0: int, n_tiles1: int) -> str | None:
    """A warning when an image is so large that its full-resolution tiles make Slime slow (Secs. 3.5-3.8)."""
    if max(n_tiles0, n_tiles1) <= MANY_TILES:
        return None
    return (f"{n_tiles0} and {n_tiles1} tiles of 256 px (a 640x480 image has 12): the tiles, the base pipeline run "
            "on them and the tile match sets grow with the image size, so Slime gets slow and memory-hungry; "
            "--max-side 1600 (max_side=1600) shrinks the images before matching and maps the matches back")


def empty_result_reason(counts: dict[str, int], tiles: TileConfig) -> str:
    """Which stage left no match, and why (paper Secs. 3.2-3.8), from the stage counts of ``run_slime``."""
    if counts["block_planes"] == 0:
        return ("no block pair gave a plane (Secs. 3.2-3.3: no homography RANSAC with enough inliers): the base "
                "pipeline found too few consistent matches between any two blocks")
    n_sets = counts["superset_H"]
    if counts["epipolar_kept"] == 0:
        if n_sets * (n_sets - 1) <= tiles.t_xi * n_sets:
            return (f"the epipolar vote (Sec. 3.6) cannot keep a match with only {n_sets} tile match sets: it asks "
                    f"for more than t_xi |H| = {tiles.t_xi:g} x {n_sets} agreeing fundamental matrices out of "
                    f"{n_sets * (n_sets - 1)}; small images (few tiles) or scenes with few planes end here; "
                    "the base pipeline alone (--method hz+) may still match them")
        return (f"no match agreed with enough of the fundamental matrices of the {n_sets} tile match sets "
                "(Sec. 3.6): the planes found do not share one epipolar geometry")
    if counts["ftheta_matches"] == 0:
        return "no tile match set survived plane fusion and the global orientation filter (Sec. 3.7)"
    return (f"the final global DTM (Sec. 3.8) kept none of the {counts['ftheta_matches']} plane matches and "
            f"{counts['tile_matches']} tile matches")


def _scaling(blocks: list[Block], index: np.ndarray) -> np.ndarray:
    """(n, 3, 3) maps original px -> scaled px of the blocks ``index`` (pixel-centre convention)."""
    fx = np.array([blocks[i].fx for i in index])
    fy = np.array([blocks[i].fy for i in index])
    s = np.zeros((len(index), 3, 3))
    s[:, 0, 0], s[:, 1, 1], s[:, 2, 2] = fx, fy, 1.0
    s[:, 0, 2], s[:, 1, 2] = 0.5 * fx - 0.5, 0.5 * fy - 0.5
    return s


def block_planes_to_original(bpm: BlockPairMatches, blocks0: list[Block], blocks1: list[Block]
                             ) -> tuple[MatchTable, np.ndarray, np.ndarray]:
    """Block-pair matches and homographies in original-image pixels (Sec. 3.4's reference frame).

    Returns:
        The match table (theta = 0 in image 0 and theta* of its plane in image 1, as forced by Sec. 3.3),
        (L, 3, 3) homographies original image 0 -> original image 1, and (L,) plane sides.
    """
    s0 = _scaling(blocks0, bpm.pairs[:, 0])
    s1 = _scaling(blocks1, bpm.pairs[:, 1])
    h = np.linalg.inv(s1) @ bpm.H @ s0
    pair = bpm.match_pair
    f0 = np.sqrt(s0[:, 0, 0] * s0[:, 1, 1])[pair]
    f1 = np.sqrt(s1[:, 0, 0] * s1[:, 1, 1])[pair]
    xy0 = (bpm.xy0 + 0.5) / np.stack([s0[:, 0, 0], s0[:, 1, 1]], 1)[pair] - 0.5
    xy1 = (bpm.xy1 + 0.5) / np.stack([s1[:, 0, 0], s1[:, 1, 1]], 1)[pair] - 0.5
    table = MatchTable(xy0, xy1, np.zeros(len(pair)), bpm.theta[pair], bpm.scale0 / f0, bpm.scale1 / f1,
                       np.ones(len(pair)), pair, bpm.scores)
    side = np.ones(len(h))
    for plane in range(len(h)):  # one small projection per plane
        _, w = project(h[plane], xy0[pair == plane])
        side[plane] = 1.0 if np.sum(np.sign(w)) >= 0 else -1.0
    return table, h, side


def _workers(requested: int | None) -> int:
    """Worker processes for Slime's stages: ``requested``, or one per CPU this process may use
    (``available_cpus``). On CUDA they run only CPU work: the networks stay in one process (see
    ``device_workers`` and ``uses_cuda``)."""
    return max(1, requested) if requested is not None else available_cpus()


def select_planes(table: MatchTable, expanded, tiles0: list[Block], tiles1: list[Block], config: TileConfig,
                  threads: int = 1) -> dict[str, TileSets | np.ndarray | float]:
    """Secs. 3.5-3.7: tile sets -> H* -> H -> M+ -> F-bar -> fused F^{l*} -> F^theta (the epipolar vote in
    ``threads`` threads: the same result for any number)."""
    w = table.weight
    sets = tile_sets(table, expanded, tiles0, tiles1)
    star = sets.subset(best_sets_per_tile_pair(sets, w, q=config.q_pair))
    superset = star.subset(best_sets_per_tile(star, w, q=config.q_tile))
    keep = epipolar_consistency(table, superset, t_perp=config.t_perp, t_xi=config.t_xi,
                                min_union=config.min_union, chunk=config.chunk, threads=threads)
    filtered = superset.restrict(keep)
    groups = None if config.same_homography == "set" else plane_groups(filtered, config.t_ov,
                                                                         config.same_homography)
    fbar = filtered.subset(greedy_two_per_tile(filtered, w, t_ov=config.t_ov, groups=groups))
    fused = fuse_planes(sets.restrict(keep), fbar, w, t_ov=config.t_ov)
    ok, theta, theta_plus = global_orientation_filter(table, fused, bins=config.bins,
                                                      t_theta_plus=config.t_theta_plus)
    return {"sets": sets, "superset": superset, "keep": keep, "fbar": fbar, "fused": fused,
            "ftheta": fused.subset(ok), "theta": theta[ok], "theta_plus": theta_plus}


def run_slime(pipeline: BasePipeline, image0: np.ndarray, image1: np.ndarray, config: SlimeConfig,
              timer: StageTimer | None = None, seed: int = 0, level_cache: LevelCache | None = None
              ) -> SlimeOutput:
    """Run Slime on two (H, W, 3) float images with ``pipeline`` as the base.

    Args:
        level_cache: block and tile features of images met before (with this pipeline and ``config``), read
            and filled by the features stage; None computes them all.

    Returns:
        SlimeOutput with matches in original pixels sorted by score (lower is better).
    """
    timer = timer or StageTimer()
    (h0, w0), (h1, w1) = image0.shape[:2], image1.shape[:2]
    blocks0, blocks1 = make_blocks(h0, w0, config.blocks), make_blocks(h1, w1, config.blocks)
    tiles0, tiles1 = make_tiles(h0, w0, config.blocks), make_tiles(h1, w1, config.blocks)
    warnings: list[str] = []

    def warn(message: str) -> None:
        warnings.append(message)
        logger.warning(message)

    workers = _workers(config.workers)
    logger.info("Slime: %d x %d blocks (%d block pairs), %d and %d tiles, %d worker process%s", len(blocks0),
                len(blocks1), len(blocks0) * len(blocks1), len(tiles0), len(tiles1), workers,
                "" if workers == 1 else "es")
    for message in (layout_warning(len(blocks0), len(blocks1)), tile_count_warning(len(tiles0), len(tiles1))):
        if message:
            warn(message)
    if workers > 1:  # loaded once here, the forked workers of every stage inherit the compiled loops
        pipeline.load_kernels()
        ransac_kernels.load_kernels()
    with timer("features"):  # the tiles' regions too (Sec. 3.8), so that all detections share the workers
        detection = config.detection or pipeline.slime_detection
        requests = [LevelRequest(image0, blocks0, detection=detection),
                    LevelRequest(image1, blocks1, detection=detection)]
        if config.refine_tiles:
            requests += [LevelRequest(image, tiles, regions_only=True, detection=config.tile_detection)
                         for image, tiles in ((image0, tiles0), (image1, tiles1))]
        (levels0, levels1, *tile_levels), cached_sets = _levels(pipeline, requests, workers, level_cache)
    with timer("block_pairs"), torch_threads(1):
        bpm, counts = match_block_pairs(pipeline, levels0, levels1, blocks0, blocks1, config.ransac,
                                        bins=config.bins, min_matches=config.min_plane_matches, seed=seed,
                                        workers=workers)
    raw_table, h, side = block_planes_to_original(bpm, blocks0, blocks1)
    table, _ = deduplicate(raw_table)
    counts.update(feature_sets=len(requests), cached_feature_sets=cached_sets, block_matches=len(raw_table),
                  block_matches_unique=len(table))
    with timer("expansion"):
        expanded = expand_planes(table, h, side, config.planes, threads=workers)
    counts["expanded_memberships"] = int(expanded.nnz)
    with timer("plane_selection"):
        selected = select_planes(table, expanded, tiles0, tiles1, config.tiles, threads=workers)
    ftheta = selected["ftheta"]
    in_ftheta = ftheta.union()
    counts.update(tile_sets=len(selected["sets"]), superset_H=len(selected["superset"]),
                  epipolar_kept=int(selected["keep"].sum()), fbar_sets=len(selected["fbar"]),
                  ftheta_sets=len(ftheta), ftheta_matches=int(in_ftheta.sum()))
    guide_xy0, guide_xy1 = table.xy0[in_ftheta], table.xy1[in_ftheta]
    tile_xy0 = tile_xy1 = np.zeros((0, 2))
    tile_scores = np.zeros(0)
    tile_levels0, tile_levels1 = tile_levels or ([], [])
    if config.refine_tiles and len(ftheta):
        with timer("tile_refinement"), torch_threads(1):
            test = tile_test(config.tile_test, FlowGuide(guide_xy0, guide_xy1, config.planes.t_perp),
                             PlaneGuide(h, side, config.planes.t_perp))
            tile_xy0, tile_xy1, tile_scores = match_tiles(
                pipeline, tile_levels0, tile_levels1, tiles0, tiles1, np.stack([ftheta.tile0, ftheta.tile1], 1),
                selected["theta"], ftheta.plane, test, bins=config.tiles.bins, workers=workers)
    counts["tile_matches"] = len(tile_xy0)
    with timer("global_dtm"):
        all0 = np.vstack([guide_xy0, tile_xy0])
        all1 = np.vstack([guide_xy1, tile_xy1])
        all_scores = np.concatenate([table.score[in_ftheta], tile_scores])
        use_dtm = pipeline.slime_global_dtm if config.global_dtm is None else config.global_dtm
        if config.refine_tiles and use_dtm:
            xy0, xy1, scores = global_dtm(all0, all1, all_scores, (h0, w0), (h1, w1),
                                          getattr(getattr(pipeline, "config", None), "dtm", None))
        else:
            if config.refine_tiles:
                all0, all1, all_scores = merge_duplicates(all0, all1, all_scores)
            order = np.argsort(all_scores, kind="stable")
            xy0, xy1, scores = all0[order], all1[order], all_scores[order]
    counts["final"] = len(xy0)
    if not len(xy0):
        warn("Slime found no match: " + empty_result_reason(counts, config.tiles))
    stages = None
    if config.keep_stages:
        stages = _stage_arrays(blocks0, blocks1, tiles0, tiles1, bpm, raw_table, table, h, expanded, selected,
                               tile_xy0, tile_xy1, (all0, all1, all_scores), xy0, xy1)
    return SlimeOutput(xy0, xy1, scores, counts, stages, warnings)


def _levels(pipeline: BasePipeline, requests: list[LevelRequest], workers: int, cache: LevelCache | None
            ) -> tuple[list[list[ScaleLevel]], int]:
    """``build_levels_many`` on the requests that ``cache`` cannot answer (each distinct one once), and how
    many requests were not computed: answered by the cache, or a repeat of an earlier request of this pair
    (a self-pair's second image), so that computed = ``len(requests)`` minus it."""
    if cache is None:
        return build_levels_many(pipeline, requests, workers), 0
    digests: dict[int, str] = {}
    keys = [request_key(request, digests) for request in requests]
    first: dict[tuple, int] = {}  # each distinct request, at its first place, in request order
    for k, key in enumerate(keys):
        first.setdefault(key, k)
    found = {key: cache.get(key) for key in first}
    missing = [key for key, levels in found.items() if levels is None]
    fresh = build_levels_many(pipeline, [requests[first[key]] for key in missing], workers) if missing else []
    for key, levels in zip(missing, fresh):
        cache.put(key, levels)
        found[key] = levels
    reused = len(keys) - len(missing)
    logger.info("Slime features: %d of %d feature sets (the blocks, the tiles of each image) reused",
                reused, len(keys))
    return [found[key] if first[key] == k else fresh_copy(found[key]) for k, key in enumerate(keys)], reused


def _boxes_original(blocks: list[Block]) -> np.ndarray:
    """(n, 5) [x0, y0, x1, y1, scale_index] of block cores in original px."""
    out = np.zeros((len(blocks), 5))
    for i, b in enumerate(blocks):
        lo = b.to_original(np.array([[b.core[0] - 0.5, b.core[1] - 0.5]]))[0]
        hi = b.to_original(np.array([[b.core[2] - 0.5, b.core[3] - 0.5]]))[0]
        out[i] = [*lo, *hi, b.scale_index]
    return out


def stages_to_original(
    stages: dict[str, np.ndarray], scale0: tuple[float, float], scale1: tuple[float, float]
) -> dict[str, np.ndarray]:
    """Stage arrays of images matched resized by (sx, sy) = original / resized, in original-image pixels:
    points, block and tile boxes and plane homographies (orientations stay as measured when matching)."""
    out = dict(stages)
    for image, scale in ((0, scale0), (1, scale1)):
        for key, value in stages.items():
            if key.endswith(f"_xy{image}"):
                out[key] = to_original(value, scale)
        for key in (f"blocks{image}", f"tiles{image}"):
            boxes = stages[key].copy()
            boxes[:, 0:2], boxes[:, 2:4] = to_original(boxes[:, 0:2], scale), to_original(boxes[:, 2:4], scale)
            out[key] = boxes
    out["planes_H"] = homography_to_original(stages["planes_H"], scale0, scale1)
    return out


def _sets_arrays(prefix: str, sets: TileSets) -> dict[str, np.ndarray]:
    return {f"{prefix}_plane": sets.plane, f"{prefix}_tile0": sets.tile0, f"{prefix}_tile1": sets.tile1,
            f"{prefix}_indptr": sets.indptr, f"{prefix}_indices": sets.indices}


def _stage_arrays(blocks0, blocks1, tiles0, tiles1, bpm, raw_table, table, h, expanded, selected, tile_xy0,
                  tile_xy1, dtm_input, xy0, xy1) -> dict[str, np.ndarray]:
    """Every stage's sets as flat arrays (match sets index the rows of ``table_*``); ``dtm_input`` = the last
    step's input, F^theta's matches then the tile matches, as xy0 (K, 2), xy1 (K, 2), scores (K,) (the global
    DTM's input where it runs)."""
    coo = expanded.tocoo()
    out = {
        "blocks0": _boxes_original(blocks0), "blocks1": _boxes_original(blocks1),
        "tiles0": _boxes_original(tiles0), "tiles1": _boxes_original(tiles1),
        "planes_pairs": bpm.pairs, "planes_H": h, "planes_theta": bpm.theta,
        "block_matches_xy0": raw_table.xy0, "block_matches_xy1": raw_table.xy1,
        "block_matches_plane": raw_table.source,
        "table_xy0": table.xy0, "table_xy1": table.xy1, "table_weight": table.weight,
        "expanded_plane": coo.row.astype(np.int64), "expanded_match": coo.col.astype(np.int64),
        "epipolar_keep": selected["keep"], "ftheta_theta": selected["theta"],
        "theta_plus": np.array(selected["theta_plus"]),
        "tile_matches_xy0": tile_xy0, "tile_matches_xy1": tile_xy1,
        "dtm_input_xy0": dtm_input[0], "dtm_input_xy1": dtm_input[1], "dtm_input_score": dtm_input[2],
        "final_xy0": xy0, "final_xy1": xy1,
    }
    for name in ("superset", "fbar", "ftheta"):
        out.update(_sets_arrays(name, selected[name]))
    return out
