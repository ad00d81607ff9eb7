"""Feature levels (Secs. 3.1 and 3.8): the blocks' and tiles' keypoints, shapes and descriptors of one image.

Speed by design (the paper's SM "Slime running time"): keypoints, shapes and descriptors are computed once
per image and block scale on the whole scaled image and shared by every block that contains the keypoint (a
block owns the keypoints of its core, i.e. the block minus its 32 px padding). The detections (in pieces of
keypoints, so that the workers finish together) are spread over forked worker processes (:mod:`.jobs`); on
CUDA the networks run in this process and the block crops' detector in the workers. How blocks get their
keypoints (``LevelRequest.detection``):

* "scale": one detection per block scale on the whole scaled image, each block owning its core's keypoints;
* "block": the paper's prototype, each block crop (zero-padded box) detected and described on its own, so
  that the adaptive HarrisZ+ thresholds follow the block's own content;
* "merged": the block crops are detected on their own as in "block", the keypoints that overlapping blocks
  share (same detector level, within ``MERGE_RADIUS`` px) are merged, and the patch stages (shape,
  orientation, descriptor) run once per scale on the whole scaled image for the merged keypoints.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from slime_match.choices import DETECTIONS

from .._runtime.forking import fork_map, torch_threads
from ..features.image_ops import resize_lanczos
from ..pipelines import BasePipeline
from ..types import Features, Keypoints
from .blocks import Block, points_in_blocks
from .clusters import greedy_clusters
from .jobs import (
    device_workers,
    features_from_numpy,
    features_to_numpy,
    joined,
    piece_size,
    pieces_of,
    uses_cuda,
)

__all__ = ["DETECTIONS", "LevelRequest", "ScaleLevel", "build_levels", "build_levels_many", "merge_keypoints"]


@dataclass(frozen=True)
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
        origin: (x, y) scaled-image position of the context's pixel (0, 0): (0, 0) for the whole scaled
            image, the box corner for a block crop (features are shifted by -origin when re-described).
    """

    factor: float
    size: tuple[int, int]
    context: Any
    features: Features
    blocks: list[int]
    members: list[np.ndarray]
    origin: tuple[float, float] = (0.0, 0.0)


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
        return features_to_numpy(features) if forked else features

    found = fork_map(detect, len(pieces), describers)
    parts: list[list] = [[] for _ in detections]
    for (k, piece), result in sorted(zip(pieces, found), key=lambda done: (done[0][0], done[0][1].start)):
        parts[k].append(result)
    levels: list[list[ScaleLevel]] = [[] for _ in requests]
    for d, part in zip(detections, parts):
        if forked:
            features = features_from_numpy(joined(part), getattr(pipeline, "device", torch.device("cpu")))
        else:
            (features,) = part  # one piece a set in one process
        levels[d.request].append(_level(d, features, requests[d.request].blocks))
    return levels


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
            local = keypoints.xy.cpu().numpy()
            core = torch.from_numpy(block.in_core_local(local) & block.off_border_local(local)).to(keypoints.xy.device)
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
        local = features.xy.detach().cpu().numpy()
        inside = d.block.in_core_local(local) & d.block.off_border_local(local)
        origin = (float(d.block.box[0]), float(d.block.box[1]))
        features = features.subset(torch.from_numpy(inside).to(features.laf.device)).moved(origin)
        return ScaleLevel(factor, d.scaled.shape[:2], d.context, features, d.blocks, [np.arange(len(features))],
                          origin=origin)
    original = blocks[d.blocks[0]].level_frame.to_original(features.xy.detach().cpu().numpy())
    inside = points_in_blocks(original, [blocks[i] for i in d.blocks])
    members = [inside.indices[inside.indptr[k]:inside.indptr[k + 1]] for k in range(len(d.blocks))]
    return ScaleLevel(factor, d.scaled.shape[:2], d.context, features, d.blocks, members)


def build_levels(pipeline: BasePipeline, image: np.ndarray, blocks: list[Block],
                 regions_only: bool = False, detection: str = "scale", workers: int = 1) -> list[ScaleLevel]:
    """``build_levels_many`` for one image (see ``LevelRequest`` for the arguments)."""
    return build_levels_many(pipeline, [LevelRequest(image, blocks, regions_only, detection)], workers)[0]
