"""Slime Secs. 3.2-3.3: block-pair planar matching and its orientation-refined re-run.

Speed by design (the paper's SM "Slime running time"): keypoints, shapes and descriptors are computed
once per image and block scale on the whole scaled image and shared by every block that contains the
keypoint (a block owns the keypoints of its core, i.e. the block minus its 32 px padding); descriptors
under a fixed orientation are computed once per (scale, orientation bin) and only for the keypoints that
a block pair needs; RANSACs of all block pairs run as one batch; the detections, the descriptions (in pieces
of keypoints, so that the workers finish together), block pairs and RANSAC batches are spread over forked
worker processes. Forked processes cannot use CUDA: on CUDA the networks run in the main process, while the
block crops' detector and the block and tile pairs run on the CPU in the workers (``uses_cuda``). How blocks
get their keypoints (``LevelRequest.detection``):

* "scale": one detection per block scale on the whole scaled image, each block owning its core's keypoints;
* "block": the paper's prototype, each block crop (zero-padded box) detected and described on its own, so
  that the adaptive HarrisZ+ thresholds follow the block's own content;
* "merged": the block crops are detected on their own as in "block", the keypoints that overlapping blocks
  share (same detector level, within ``MERGE_RADIUS`` px) are merged, and the patch stages (shape,
  orientation, descriptor) run once per scale on the whole scaled image for the merged keypoints.
"""

from __future__ import annotations

import functools
import itertools
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from ..features.laf import set_laf_angle
from ..geometry.ransac import HomographyRansacConfig, ransac_homography_many
from ..pipelines import BasePipeline, CandidateFilter
from ..types import Features, Keypoints, Matches
from .blocks import Block, points_in_blocks, resize_lanczos
from .clusters import greedy_clusters
from .forking import fork_map, torch_threads
from .planes import relative_orientation

logger = logging.getLogger("slime_match")


@dataclass
class ScaleLevel:
    """The features of one image at one block scale, shared by all blocks of that scale (or, with per-block
    detection, the features of a single block).

    Attributes:
        factor: scaled size / original size.
        size: (H, W) of the scaled image.
        context: the base pipeline's image context: of the whole scaled image, or of one block crop.
        features: (N) features in scaled-image pixels, with the pipeline's own orientation.
        blocks: indices (into the image's block list) of the blocks of this level.
        members: per block of this level, the (n_b,) indices of the features in its core.
        fixed: cache of fixed-orientation descriptors: bin -> (computed mask (N,), descriptors (N, D)).
        origin: (x, y) scaled-image position of the context's pixel (0, 0): (0, 0) for the whole scaled
            image, the box corner for a block crop (features are shifted by -origin when re-described).
    """

    factor: float
    size: tuple[int, int]
    context: Any
    features: Features
    blocks: list[int]
    members: list[np.ndarray]
    fixed: dict[int, tuple[np.ndarray, torch.Tensor | None]] = field(default_factory=dict)
    origin: tuple[float, float] = (0.0, 0.0)


def translate_features(features: Features, offset: tuple[float, float]) -> Features:
    """The same features moved by ``offset`` (x, y) px: LAF and shape-frame centres alike."""
    shift = torch.tensor(offset, dtype=features.laf.dtype, device=features.laf.device)
    laf = features.laf.clone()
    laf[:, :, 2] += shift
    shape_laf = None
    if features.shape_laf is not None:
        shape_laf = features.shape_laf.clone()
        shape_laf[:, :, 2] += shift
    return Features(laf, features.descriptors, features.response, shape_laf)


def _features_to_numpy(features: Features) -> tuple[np.ndarray | None, ...]:
    """The arrays of features (CPU numpy), to send from a forked worker: torch would pickle shared memory."""
    return tuple(None if t is None else t.detach().cpu().numpy() for t in
                 (features.laf, features.descriptors, features.response, features.shape_laf))


def _features_from_numpy(arrays: tuple[np.ndarray | None, ...], device: torch.device) -> Features:
    """Features on ``device`` from the arrays of ``_features_to_numpy``."""
    return Features(*(None if a is None else torch.from_numpy(a).to(device) for a in arrays))


DETECTIONS = ("scale", "block", "merged")
MERGE_RADIUS = 1.0  # scaled px: keypoints of one detector level this close (per coordinate) are one keypoint


@dataclass
class LevelRequest:
    """One image's blocks (or tiles) to detect, for ``build_levels_many``.

    Attributes:
        image: (H, W, 3) float image.
        blocks: its blocks (``make_blocks``) or tiles (``make_tiles``).
        regions_only: keep only the shape frames (no own orientation or descriptors): enough for regions
            that are only described under fixed orientations (the tiles, Sec. 3.8).
        detection: "scale", "block" or "merged" (see the module docstring); each block keeps the keypoints
            of its core.
    """

    image: np.ndarray
    blocks: list[Block]
    regions_only: bool = False
    detection: str = "scale"

    def __post_init__(self) -> None:
        if self.detection not in DETECTIONS:
            raise ValueError(f"detection must be one of {DETECTIONS}, got {self.detection!r}")


@dataclass
class _Detection:
    """One detection to run: a whole scaled image (``block`` None) or one block crop of it; with
    ``keypoints`` (merged detection, or a "scale" level detected apart), only the patch stages on the whole
    scaled image, and ``members`` the merged level's keypoints of each block (None: ``_level`` finds them)."""

    request: int
    blocks: list[int]
    scaled: np.ndarray
    context: Any
    block: Block | None
    keypoints: Keypoints | None = None
    members: list[np.ndarray] | None = None

    @property
    def pixels(self) -> int:
        """Size of the detected image (the block crop or the whole scaled image), pixels."""
        return int(np.prod(self.block.shape if self.block is not None else self.scaled.shape[:2]))


def build_levels_many(pipeline: BasePipeline, requests: list[LevelRequest], workers: int = 1
                      ) -> list[list[ScaleLevel]]:
    """Detect and describe the blocks of several images: once per block scale on the whole (Lanczos-)scaled
    image, per block, or detected per block and described per scale (see ``LevelRequest``).

    The detections (one per image and scale, or per block; "merged": first the block crops' detectors, then
    the patch stages of each image and scale, in pieces of keypoints, see ``piece_size``) run in ``workers``
    forked processes (one process on CUDA), the largest first; each runs single-threaded torch, as in one
    process, so the features do not depend on ``workers``.

    Returns:
        Per request: "scale" and "merged" detection, one ScaleLevel per distinct block scale, in increasing
        scale index; "block", one ScaleLevel per block, in block order. Features are in scaled-image pixels.
    """
    # A detector that runs apart from the patch stages (Hz+) detects the "scale" levels first too, so that their
    # patch stages go in pieces when the description is forked: the same features as ``detect``.
    describers = device_workers(pipeline, workers)  # the crops' detector uses ``workers``, also on CUDA
    apart = describers > 1 and pipeline.describe_batch() is not None and pipeline.slime_detection == "merged"
    detections, keypointed = [], []
    for r, request in enumerate(requests):
        blocks = request.blocks
        for scale_index in sorted({b.scale_index for b in blocks}):
            members_blocks = [i for i, b in enumerate(blocks) if b.scale_index == scale_index]
            scaled = resize_lanczos(request.image, blocks[members_blocks[0]].factor)
            if request.detection == "block":
                detections += [_Detection(r, [i], scaled, pipeline.prepare(blocks[i].crop(scaled)), blocks[i])
                               for i in members_blocks]
            elif request.detection == "merged" or apart:
                keypointed.append(_Detection(r, members_blocks, scaled, None, None))
            else:
                detections.append(_Detection(r, members_blocks, scaled, pipeline.prepare(scaled), None))
    if keypointed:
        device = getattr(pipeline, "device", torch.device("cpu"))
        with torch_threads(1):
            for d, (keypoints, members) in zip(keypointed, _detected_keypoints(pipeline, keypointed, requests,
                                                                                workers)):
                d.context, d.keypoints, d.members = pipeline.prepare(d.scaled), keypoints.to(device), members
        detections += keypointed
    forked = describers > 1
    # whole detections first, the largest first; then the detected keypoints in pieces, the largest first
    whole = sorted((k for k, d in enumerate(detections) if d.keypoints is None), key=lambda k: -detections[k].pixels)
    size = piece_size(sum(len(d.keypoints) for d in keypointed), pipeline.describe_batch(), describers)
    pieces = [(k, slice(0, None)) for k in whole] + sorted(
        ((k, piece) for k, d in enumerate(detections) if d.keypoints is not None
         for piece in pieces_of(len(d.keypoints), size)), key=lambda job: job[1].start - job[1].stop)

    def detect(j: int) -> Features | tuple:
        k, piece = pieces[j]
        d = detections[k]
        regions_only = requests[d.request].regions_only
        if d.keypoints is not None:
            keypoints = d.keypoints.subset(torch.arange(piece.start, piece.stop, device=d.keypoints.xy.device))
            features = pipeline.describe_keypoints(d.context, keypoints, regions_only)
        else:
            features = pipeline.detect_regions(d.context) if regions_only else pipeline.detect(d.context)
        return _features_to_numpy(features) if forked else features

    found = fork_map(detect, len(pieces), describers)
    parts: list[list] = [[] for _ in detections]
    for (k, piece), result in sorted(zip(pieces, found), key=lambda done: (done[0][0], done[0][1].start)):
        parts[k].append(result)
    levels: list[list[ScaleLevel]] = [[] for _ in requests]
    for d, part in zip(detections, parts):
        if forked:
            features = _features_from_numpy(_joined(part), getattr(pipeline, "device", torch.device("cpu")))
        else:
            (features,) = part  # one piece a set in one process
        levels[d.request].append(_level(d, features, requests[d.request].blocks))
    return levels


def piece_size(total: int, batch: int | None, workers: int) -> int:
    """Keypoints per call when ``total`` keypoints are described by ``workers`` processes: about a quarter of
    an even share (so that the processes finish together), a multiple of the pipeline's ``describe_batch``
    (so that the features do not depend on ``workers``); all of them (no pieces) in one process or when the
    pipeline must describe a set whole (``batch`` None)."""
    if workers <= 1 or batch is None:
        return max(total, 1)
    return batch * max(1, math.ceil(total / (4 * workers * batch)))


def pieces_of(count: int, size: int) -> list[slice]:
    """``range(count)`` in consecutive slices of ``size`` (the last one shorter; one empty slice for 0)."""
    return [slice(start, min(start + size, count)) for start in range(0, count, size)] or [slice(0, 0)]


def _joined(parts: list[tuple[np.ndarray | None, ...]]) -> tuple[np.ndarray | None, ...]:
    """The arrays of ``_features_to_numpy`` of consecutive pieces of one set, as those of the whole set."""
    return tuple(None if column[0] is None else np.concatenate(column) for column in zip(*parts))


def _detected_keypoints(pipeline: BasePipeline, levels: list[_Detection], requests: list[LevelRequest],
                        workers: int) -> list[tuple[Keypoints, list[np.ndarray] | None]]:
    """The detector alone on the levels' images, forked over ``workers`` (the whole images first): a "merged"
    level's block crops one by one, then its blocks' core keypoints merged; another level's whole scaled
    image. A CUDA pipeline with workers detects on the CPU, in the workers: one crop is too small for the GPU
    (on an H100 the 40 crops of a 640x480 pair took 1.4 s one after another).

    Returns:
        Per level: its keypoints in scaled-image px and, for a merged level, per block the indices of its
        keypoints among them (the strongest of each group, see ``merge_keypoints``); None for another level
        (``_level`` gives the blocks the keypoints of their cores).
    """
    merged = [requests[d.request].detection == "merged" for d in levels]
    crops = [(n, None) for n, m in enumerate(merged) if not m] + [(n, i) for n, m in enumerate(merged) if m
                                                                   for i in levels[n].blocks]
    device = torch.device("cpu") if uses_cuda(pipeline) and workers > 1 else None

    def detect(k: int) -> tuple[np.ndarray, ...]:
        n, i = crops[k]
        d = levels[n]
        if i is None:
            keypoints = pipeline.detect_keypoints(d.scaled, device)
            xy = keypoints.xy.cpu().numpy()
        else:
            block = requests[d.request].blocks[i]
            keypoints = pipeline.detect_keypoints(block.crop(d.scaled), device)
            core = torch.from_numpy(block.in_core_local(keypoints.xy.cpu().numpy())).to(keypoints.xy.device)
            keypoints = keypoints.subset(core)
            xy = keypoints.xy.cpu().numpy() + np.array(block.box[:2], np.float32)
        return (xy, *(t.cpu().numpy() for t in (keypoints.ellipse, keypoints.response, keypoints.level)))

    found = dict(zip(crops, fork_map(detect, len(crops), workers)))  # (level, block or None) -> arrays
    return [merge_keypoints([found[n, i] for i in d.blocks]) if m
            else (Keypoints(*(torch.from_numpy(a) for a in found[n, None])), None)
            for n, (d, m) in enumerate(zip(levels, merged))]


def merge_keypoints(parts: list[tuple[np.ndarray, ...]], radius: float = MERGE_RADIUS
                    ) -> tuple[Keypoints, list[np.ndarray]]:
    """The keypoints that several blocks detected, once.

    Args:
        parts: per block, its keypoints as arrays xy (n, 2) in scaled-image px, ellipse (n, 2, 2), response
            (n,), level (n,).
        radius: keypoints of the same detector level within this many px (per coordinate) are one, the
            strongest response standing for the group.

    Returns:
        The merged keypoints (K), and per block the (n_b,) sorted unique indices of its keypoints among them.
    """
    xy, ellipse, response, level = (np.concatenate(column) for column in zip(*parts))
    apart = 4.0 * radius * (level.astype(np.float64) + 1.0)  # different levels never within radius
    rep, cluster = greedy_clusters(np.c_[xy, apart], -response, radius)
    edges = np.cumsum([0] + [len(part[0]) for part in parts])
    members = [np.unique(cluster[a:b]) for a, b in itertools.pairwise(edges)]
    keypoints = Keypoints(*(torch.from_numpy(np.ascontiguousarray(a[rep])) for a in (xy, ellipse, response, level)))
    return keypoints, members


def _level(d: _Detection, features: Features, blocks: list[Block]) -> ScaleLevel:
    """The ScaleLevel of one detection: the scale's blocks and the features each owns (its core's)."""
    factor = blocks[d.blocks[0]].factor
    if d.members is not None:  # merged detection: the blocks' own keypoints, described once
        return ScaleLevel(factor, d.scaled.shape[:2], d.context, features, d.blocks, d.members)
    if d.block is not None:  # a block crop: keep its core's features, in scaled-image pixels
        inside = d.block.in_core_local(features.xy.detach().cpu().numpy())
        origin = (float(d.block.box[0]), float(d.block.box[1]))
        features = translate_features(features.subset(torch.from_numpy(inside).to(features.laf.device)), origin)
        return ScaleLevel(factor, d.scaled.shape[:2], d.context, features, d.blocks, [np.arange(len(features))],
                          origin=origin)
    original = blocks[d.blocks[0]].to_original(features.xy.detach().cpu().numpy())
    inside = points_in_blocks(original, [blocks[i] for i in d.blocks])
    members = [inside.indices[inside.indptr[k]:inside.indptr[k + 1]] for k in range(len(d.blocks))]
    return ScaleLevel(factor, d.scaled.shape[:2], d.context, features, d.blocks, members)


def build_levels(pipeline: BasePipeline, image: np.ndarray, blocks: list[Block],
                 regions_only: bool = False, detection: str = "scale", workers: int = 1) -> list[ScaleLevel]:
    """``build_levels_many`` for one image (see ``LevelRequest`` for the arguments)."""
    return build_levels_many(pipeline, [LevelRequest(image, blocks, regions_only, detection)], workers)[0]


def orientation_bin(angle: float, bins: int) -> int:
    """Index of the histogram bin whose centre is ``angle`` (radians), bins of 2 pi / bins from 0."""
    return round(angle / (2 * math.pi / bins)) % bins


def describe_fixed_bins(pipeline: BasePipeline, requests: list[tuple[ScaleLevel, dict[int, np.ndarray]]],
                        bins: int, workers: int = 1) -> None:
    """Compute (once, cached in ``level.fixed``) the descriptors of features under fixed orientations.

    Args:
        requests: (level, orientation bin -> indices of the level's features needed under that bin's angle),
            each level at most once. Each (level, bin) is described in batched calls (one, or pieces spread
            over the workers), and only for features not already cached.
        workers: forked processes sharing the calls, each (level, bin) in pieces (``piece_size``: the same
            descriptors as in one process); one process on CUDA.
    """
    wanted_sets = []
    for level, wanted in requests:
        for bin_index, index in wanted.items():
            computed, _ = level.fixed.get(bin_index, (np.zeros(len(level.features), bool), None))
            missing = np.unique(index)
            missing = missing[~computed[missing]]
            if len(missing):
                wanted_sets.append((level, bin_index, missing))
    workers = device_workers(pipeline, workers)
    forked = workers > 1
    size = piece_size(sum(len(missing) for *_, missing in wanted_sets), pipeline.describe_batch(), workers)
    tasks = [(level, bin_index, missing[piece]) for level, bin_index, missing in wanted_sets
             for piece in pieces_of(len(missing), size)]
    tasks.sort(key=lambda task: -len(task[2]))  # the largest first: even loads over the workers

    def describe(k: int) -> np.ndarray | torch.Tensor:
        level, bin_index, missing = tasks[k]
        regions = level.features.subset(torch.from_numpy(missing))
        if level.origin != (0.0, 0.0):
            regions = translate_features(regions, (-level.origin[0], -level.origin[1]))
        fresh = pipeline.describe_fixed(level.context, regions, bin_index * 2 * math.pi / bins).descriptors
        return fresh.detach().cpu().numpy() if forked else fresh.detach()  # no device round trip in-process

    for (level, bin_index, missing), fresh in zip(tasks, fork_map(describe, len(tasks), workers)):
        n, device = len(level.features), level.features.laf.device
        computed, descriptors = level.fixed.get(bin_index, (np.zeros(n, bool), None))
        if descriptors is None:
            descriptors = torch.zeros(n, fresh.shape[1], device=device)
        descriptors[torch.from_numpy(missing).to(device)] = torch.as_tensor(fresh, device=device)
        computed = computed.copy()
        computed[missing] = True
        level.fixed[bin_index] = (computed, descriptors)


def fixed_features(level: ScaleLevel, index: np.ndarray, bin_index: int, bins: int) -> Features:
    """Features ``index`` of a level under the fixed orientation of ``bin_index`` (see describe_fixed_bins).

    An empty ``index`` (a block or tile without keypoints, for which nothing was described) gives no features.
    """
    if len(index) == 0:
        return level.features.subset(torch.zeros(0, dtype=torch.long, device=level.features.laf.device))
    computed, descriptors = level.fixed[bin_index]
    if not computed[index].all():
        raise RuntimeError("fixed-orientation descriptors requested before describe_fixed_bins")
    select = torch.from_numpy(index).to(descriptors.device)
    laf = set_laf_angle(level.features.shape_laf[select], bin_index * 2 * math.pi / bins)
    return Features(laf, descriptors[select], level.features.response[select])


@dataclass
class BlockPairMatches:
    """Matches of block pairs, in scaled-image pixels of each side.

    Attributes:
        pairs: (P, 2) block indices (w in image 0, w' in image 1) of the pairs that produced a plane.
        H: (P, 3, 3) homographies from scaled image 0 (of block w) to scaled image 1 (of block w').
        theta: (P,) plane orientation theta* (radians) used for the refined run.
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


def to_block_frame(features: Features, block: Block) -> Features:
    """The same features in a block's own pixel frame (the block image's top-left pixel at (0, 0))."""
    return translate_features(features, (-block.box[0], -block.box[1]))


def uses_cuda(pipeline: BasePipeline) -> bool:
    """Whether the pipeline computes on a CUDA device (forked processes cannot use CUDA)."""
    device = getattr(pipeline, "device", None)
    return device is not None and device.type == "cuda"


def device_workers(pipeline: BasePipeline, workers: int) -> int:
    """Workers for calls that run the pipeline's networks or read its tensors: one on CUDA, else ``workers``."""
    return 1 if uses_cuda(pipeline) else workers


MatchJob = tuple[Features, Features, Block, Block, CandidateFilter | None]
JobMatches = tuple[Matches, np.ndarray, np.ndarray]


def match_jobs(pipeline: BasePipeline, count: int, job: Callable[[int], MatchJob | None], workers: int = 1
               ) -> list[JobMatches]:
    """The base pipeline on ``count`` block (or tile) pairs, in ``workers`` forked processes (``fork_map``).

    ``job(k)`` gives pair k's features (in their level's pixels), its two blocks and a candidate filter (on
    block-frame positions), or None for no match. On CUDA the jobs' features are first copied to the CPU in
    this process, as forked processes cannot use CUDA, and matched there: one pair's Blob matching is too
    small a problem for a GPU (3.8 ms a pair on an H100, in one process, in the profile of a Slime call).

    Returns:
        Per pair: the matches, and the matched positions (K, 2) float64 in the features' level pixels.
    """
    if not uses_cuda(pipeline):
        return fork_map(lambda k: _match_job(pipeline, job(k)), count, workers)
    copies: dict[int, tuple[Features, Features]] = {}  # id -> (features, CPU copy): pairs share block features

    def on_cpu(features: Features) -> Features:
        if id(features) not in copies:
            copies[id(features)] = features, features.to("cpu")
        return copies[id(features)][1]

    jobs = [None if j is None else (on_cpu(j[0]), on_cpu(j[1]), *j[2:]) for j in map(job, range(count))]
    return fork_map(lambda k: _match_job(pipeline, jobs[k]), count, workers)


def _match_job(pipeline: BasePipeline, job: MatchJob | None) -> JobMatches:
    """The base pipeline on one pair (features shifted into each block's own frame): its matches and matched
    positions in the features' own pixels."""
    if job is None or len(job[0]) < 4 or len(job[1]) < 4:
        return Matches.empty(), np.zeros((0, 2)), np.zeros((0, 2))
    f0, f1, b0, b1, candidate_filter = job
    m = pipeline.match(to_block_frame(f0, b0), to_block_frame(f1, b1), b0.shape, b1.shape,
                       candidate_filter=candidate_filter)
    xy0, xy1 = (f.xy.detach().cpu().numpy().astype(np.float64) for f in (f0, f1))
    return m, xy0[m.idx0], xy1[m.idx1]


RANSAC_BATCH = 50  # block pairs per batched RANSAC: a fixed split, so results do not depend on the workers


def ransac_batches(problems: list[tuple[np.ndarray, np.ndarray]], config: HomographyRansacConfig, seed: int,
                   workers: int = 1) -> list:
    """``ransac_homography_many`` on consecutive batches of ``RANSAC_BATCH`` problems (batch b seeded with
    (seed, b)), spread over ``workers`` forked processes; the same results for any number of workers."""
    starts = range(0, len(problems), RANSAC_BATCH)
    parts = fork_map(lambda b: ransac_homography_many(problems[starts[b]:starts[b] + RANSAC_BATCH], config,
                                                      seed=[seed, b]), len(starts), workers)
    return [result for part in parts for result in part]


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
) -> tuple[BlockPairMatches, dict[str, int]]:
    """Secs. 3.2 + 3.3 for every block pair: base pipeline + homography RANSAC, then the re-run with
    fixed orientations (theta = 0 in image 0, theta* in image 1) + RANSAC -> M_l and H_l.

    Returns:
        The refined planes and their matches, and counts for the summary: block pairs, first-run planes,
        pairs re-matched under fixed orientations (on an upright base none: the first run's matches are
        reused, ``BasePipeline.own_frames_upright``) and refined planes.
    """
    where0 = {w: (lv, i) for lv in levels0 for i, w in enumerate(lv.blocks)}
    where1 = {w: (lv, i) for lv in levels1 for i, w in enumerate(lv.blocks)}
    pairs = [(w0, w1) for w0 in range(len(blocks0)) for w1 in range(len(blocks1))]

    where = (where0, where1)

    @functools.cache
    def own_block(side: int, block: int) -> Features:
        level, i = where[side][block]
        return level.features.subset(torch.from_numpy(level.members[i]))

    def own0(pair):
        return own_block(0, pair[0])

    def own1(pair):
        return own_block(1, pair[1])

    def own_job(k: int) -> MatchJob:
        w0, w1 = pairs[k]
        return own_block(0, w0), own_block(1, w1), blocks0[w0], blocks1[w1], None

    # 3.2: the base pipeline with its own orientations, then RANSAC.
    first = match_jobs(pipeline, len(pairs), own_job, _pair_workers(len(pairs), workers))
    results = ransac_batches([(xy0, xy1) for _, xy0, xy1 in first], ransac, seed, workers)
    thetas = {}
    for pair, (m, _, _), res in zip(pairs, first, results):
        if res.model is None or res.inliers.sum() < min_matches:
            continue
        f0, f1 = own0(pair), own1(pair)
        m_in = m.subset(res.inliers)
        angle0 = f0.angle[torch.from_numpy(m_in.idx0)].cpu().numpy()
        angle1 = f1.angle[torch.from_numpy(m_in.idx1)].cpu().numpy()
        thetas[pair] = relative_orientation(angle0, angle1, bins=bins)

    # 3.3: re-run with fixed orientations on the pairs that produced a plane.
    refined_pairs = list(thetas)
    bin_of = {pair: orientation_bin(theta, bins) for pair, theta in thetas.items()}
    upright = pipeline.own_frames_upright()
    if upright:  # the features' own descriptors are those of bin 0 (angle 0): cache them as such
        for level in (*levels0, *levels1):
            level.fixed.setdefault(0, (np.ones(len(level.features), bool), level.features.descriptors))

    requests0: dict[int, dict[int, list]] = {}
    requests1: dict[int, dict[int, list]] = {}
    for pair in refined_pairs:
        level0, i0 = where0[pair[0]]
        level1, i1 = where1[pair[1]]
        requests0.setdefault(id(level0), {}).setdefault(0, []).append(level0.members[i0])
        requests1.setdefault(id(level1), {}).setdefault(bin_of[pair], []).append(level1.members[i1])
    describe_fixed_bins(pipeline, [(level, {b: np.concatenate(parts) for b, parts in requests[id(level)].items()})
                                   for levels, requests in ((levels0, requests0), (levels1, requests1))
                                   for level in levels if id(level) in requests], bins, workers)

    @functools.cache
    def fixed_block(side: int, block: int, bin_index: int) -> Features:
        level, i = where[side][block]
        return fixed_features(level, level.members[i], bin_index, bins)

    def fixed0(pair):
        return fixed_block(0, pair[0], 0)

    def fixed1(pair):
        return fixed_block(1, pair[1], bin_of[pair])

    def fixed_job(k: int) -> MatchJob:
        pair = refined_pairs[k]
        return fixed0(pair), fixed1(pair), blocks0[pair[0]], blocks1[pair[1]], None

    # On an upright base a pair with theta* = 0 (all of them: every angle is 0) would match exactly as in the
    # first run: its matches are reused, and only its RANSAC runs again.
    repeats = [upright and bin_of[pair] == 0 for pair in refined_pairs]
    redo = [k for k, repeat in enumerate(repeats) if not repeat]
    rerun = iter(match_jobs(pipeline, len(redo), lambda j: fixed_job(redo[j]), _pair_workers(len(redo), workers)))
    second = [first[w0 * len(blocks1) + w1] if repeat else next(rerun)  # ``pairs`` order
              for (w0, w1), repeat in zip(refined_pairs, repeats)]
    results = ransac_batches([(xy0, xy1) for _, xy0, xy1 in second], ransac, seed + 1, workers)

    keep_pairs, hs, theta_out, parts = [], [], [], []
    for pair, (m, _, _), res in zip(refined_pairs, second, results):
        if res.model is None or res.inliers.sum() < min_matches:
            continue
        f0, f1 = fixed0(pair), fixed1(pair)
        m_in = m.subset(res.inliers)
        keep_pairs.append(pair)
        hs.append(res.model)
        theta_out.append(bin_of[pair] * 2 * math.pi / bins)
        parts.append((len(keep_pairs) - 1, f0, f1, m_in))
    counts = {"block_pairs": len(pairs), "block_planes_first": len(thetas), "block_pairs_rerun": len(redo),
              "block_planes": len(keep_pairs)}
    return _collect(keep_pairs, hs, theta_out, parts), counts


def _pair_workers(count: int, workers: int) -> int:
    """Forking pays only from about four block pairs a worker."""
    return workers if count >= 4 * workers else 1


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


__all__ = [
    "BlockPairMatches",
    "LevelRequest",
    "ScaleLevel",
    "build_levels",
    "build_levels_many",
    "describe_fixed_bins",
    "device_workers",
    "fixed_features",
    "match_block_pairs",
    "match_jobs",
    "orientation_bin",
    "ransac_batches",
    "to_block_frame",
    "translate_features",
    "uses_cuda",
]
