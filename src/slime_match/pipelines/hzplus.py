"""Hz+: HarrisZ+ keypoints, AffNet|Baumberg shapes, OriNet|gradient|upright orientations, HardNet|TFeat|RootSIFT
descriptors, Blob matching and DTM (the paper's base pipeline)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from ..features.extractor import LocalFeatureExtractor, PatchConfig
from ..features.harrisz import HarrisZConfig, detect_harrisz
from ..features.laf import PatchPyramid
from ..io import to_tensor
from ..matching.blob import blob_match
from ..matching.dtm import dtm_filter
from ..types import Features, Keypoints, Matches
from .base import BaseConfig, BasePipeline


@dataclass
class HzContext:
    image: torch.Tensor
    pyramid: PatchPyramid


class HzPlusPipeline(BasePipeline):
    """Hz+: HarrisZ+ -> AffNet|Baumberg -> OriNet|gradient|upright -> HardNet|TFeat|RootSIFT -> Blob -> DTM."""

    name = "hz+"
    slime_detection = "merged"
    options = frozenset({"descriptor", "shape", "orientation", "upright", "max_keypoints", "magnification",
                         "weights_dir", "use_dtm", "blob", "dtm"})

    def __init__(self, config: BaseConfig, device: torch.device) -> None:
        self.config = config
        self.device = device
        orientation = "upright" if config.upright else config.orientation
        patch = PatchConfig(shape=config.shape, orientation=orientation, descriptor=config.descriptor,
                            weights_dir=config.weights_dir)
        if config.magnification is not None:
            patch.magnification = config.magnification
        self.patch = patch
        self.extractor = LocalFeatureExtractor(patch, device=device)
        self.harrisz = HarrisZConfig(max_keypoints=config.max_keypoints)

    def prepare(self, image: np.ndarray) -> HzContext:
        tensor = to_tensor(image, self.device)
        return HzContext(tensor, PatchPyramid(tensor))

    def detect(self, context: HzContext) -> Features:
        return self.describe_keypoints(context, detect_harrisz(context.image, self.harrisz))

    def detect_regions(self, context: HzContext) -> Features:
        return self.describe_keypoints(context, detect_harrisz(context.image, self.harrisz), regions_only=True)

    def detect_keypoints(self, image: np.ndarray, device: torch.device | None = None) -> Keypoints:
        return detect_harrisz(to_tensor(image, device or self.device), self.harrisz)

    def describe_keypoints(self, context: HzContext, keypoints: Keypoints, regions_only: bool = False) -> Features:
        if not regions_only:
            return self.extractor.extract(context.image, keypoints, pyramid=context.pyramid)
        shape_laf = self.extractor.shape_frames(context.pyramid, keypoints)
        descriptors = torch.zeros(len(keypoints), 0, device=shape_laf.device)
        return Features(shape_laf, descriptors, keypoints.response.to(shape_laf.device), shape_laf)

    def describe_fixed(self, context: HzContext, features: Features, angle: float) -> Features:
        return self.extractor.describe_fixed(context.pyramid, features.shape_laf, angle)

    def describe_batch(self) -> int | None:
        return self.patch.batch_size  # the networks' batches; the compiled CPU patch loops go patch by patch

    def own_frames_upright(self) -> bool:
        # upright frames are the shape frames at angle 0, described by the same descriptor
        return self.patch.orientation == "upright"

    def match(self, features0, features1, size0, size1, candidate_filter=None) -> Matches:
        if len(features0) == 0 or len(features1) == 0:
            return Matches.empty()
        candidates = blob_match(features0.descriptors, features1.descriptors, features0.xy, features1.xy,
                                self.config.blob)
        xy0 = features0.xy.detach().cpu().numpy().astype(np.float64)
        xy1 = features1.xy.detach().cpu().numpy().astype(np.float64)
        if candidate_filter is not None and len(candidates):
            candidates = candidates.subset(candidate_filter(xy0[candidates.idx0], xy1[candidates.idx1]))
        if not self.config.use_dtm or len(candidates) == 0:
            return candidates
        keep = dtm_filter(xy0[candidates.idx0], xy1[candidates.idx1], candidates.scores, size0, size1,
                          unmatched0=_unmatched(xy0, candidates.idx0), unmatched1=_unmatched(xy1, candidates.idx1),
                          config=self.config.dtm).keep
        return candidates.subset(keep)

    def kernel_groups(self) -> tuple[str, ...]:
        return ("patches", "blob", "dtm") if self.device.type == "cpu" else ("blob", "dtm")

    def describe(self) -> dict[str, Any]:
        return {"base": "hz+", "detector": "harrisz+", **dataclasses.asdict(self.harrisz),
                **self.patch.summary(),
                "matcher": "blob+dtm" if self.config.use_dtm else "blob"}


def _unmatched(xy: np.ndarray, used: np.ndarray) -> np.ndarray:
    mask = np.ones(len(xy), bool)
    mask[used] = False
    return xy[mask]
