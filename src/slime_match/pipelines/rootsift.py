"""RootSIFT: OpenCV DoG keypoints, RootSIFT descriptors and FGINN matching (the paper's handcrafted baseline)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import torch

from ..matching.nn import match_fginn
from ..types import Features, Matches
from .base import BaseConfig, BasePipeline, _empty_features, _filtered


@dataclass
class SiftContext:
    grey: np.ndarray  # (H, W) uint8


class RootSiftPipeline(BasePipeline):
    """OpenCV DoG keypoints + RootSIFT descriptors + FGINN matching (upright: all angles set to 0)."""

    name = "rootsift"
    options = frozenset({"upright", "max_keypoints", "fginn_ratio", "fginn_radius"})

    def __init__(self, config: BaseConfig, device: torch.device) -> None:
        self.config = config
        self.device = device
        self.sift = cv2.SIFT_create(nfeatures=config.max_keypoints)

    def prepare(self, image: np.ndarray) -> SiftContext:
        grey = cv2.cvtColor((np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8), cv2.COLOR_RGB2GRAY)
        return SiftContext(grey)

    def detect(self, context: SiftContext) -> Features:
        keypoints = self.sift.detect(context.grey, None)
        if self.config.upright:
            keypoints = _upright_unique(keypoints)
        return self._describe(context, keypoints)

    def detect_regions(self, context: SiftContext) -> Features:
        keypoints = _upright_unique(self.sift.detect(context.grey, None))
        if not keypoints:
            return _empty_features(0, self.device)
        _laf, shape, response = self._frames(keypoints)
        return Features(shape, torch.zeros(len(keypoints), 0, device=self.device), response, shape)

    def describe_fixed(self, context: SiftContext, features: Features, angle: float) -> Features:
        laf = features.laf.detach().cpu().numpy()
        scale = features.scale.detach().cpu().numpy()
        keypoints = [cv2.KeyPoint(float(x), float(y), float(2.0 * s), math.degrees(angle) % 360.0)
                     for (x, y), s in zip(laf[:, :, 2], scale)]
        return self._describe(context, keypoints)

    def _describe(self, context: SiftContext, keypoints) -> Features:
        if not keypoints:
            return _empty_features(128, self.device)
        keypoints, descriptors = self.sift.compute(context.grey, keypoints)
        if descriptors is None or not keypoints:
            return _empty_features(128, self.device)
        descriptors = descriptors.astype(np.float32)
        descriptors /= np.maximum(descriptors.sum(1, keepdims=True), 1e-12)
        laf, shape, response = self._frames(keypoints)
        return Features(laf, torch.from_numpy(np.sqrt(descriptors)).to(self.device), response, shape)

    def _frames(self, keypoints) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Oriented LAFs (N, 2, 3), upright LAFs of the same scale, and responses (N,) of OpenCV keypoints.

        OpenCV's angle is in degrees in pixel coordinates (y down), the package's convention; the scale is
        the keypoint radius, size / 2.
        """
        xy = np.array([k.pt for k in keypoints], np.float32)
        scale = np.array([k.size / 2.0 for k in keypoints], np.float32)
        angle = np.radians(np.array([k.angle for k in keypoints], np.float32))
        cos, sin = np.cos(angle) * scale, np.sin(angle) * scale
        laf = np.stack([np.stack([cos, -sin, xy[:, 0]], 1), np.stack([sin, cos, xy[:, 1]], 1)], 1)
        shape = laf.copy()
        shape[:, :, :2] = np.eye(2, dtype=np.float32) * scale[:, None, None]
        response = np.array([k.response for k in keypoints], np.float32)
        return tuple(torch.from_numpy(a).to(self.device) for a in (laf, shape, response))

    def match(self, features0, features1, size0, size1, candidate_filter=None) -> Matches:
        if len(features0) < 2 or len(features1) < 2:
            return Matches.empty()
        matches = match_fginn(features0.descriptors, features1.descriptors, features0.xy, features1.xy,
                              ratio=self.config.fginn_ratio, spatial_radius=self.config.fginn_radius)
        return _filtered(matches, features0, features1, candidate_filter)

    def kernel_groups(self) -> tuple[str, ...]:
        return ("blob",)  # FGINN runs the nearest-neighbour loops of Blob matching

    def describe(self) -> dict[str, Any]:
        return {"base": "rootsift", "detector": "opencv-dog", "descriptor": "rootsift", "matcher": "fginn",
                "upright": self.config.upright, "fginn_ratio": self.config.fginn_ratio,
                "fginn_radius": self.config.fginn_radius}


def _upright_unique(keypoints) -> list:
    """Drop OpenCV's extra orientations of one DoG point and set every angle to 0."""
    seen, out = set(), []
    for k in keypoints:
        key = (round(k.pt[0], 3), round(k.pt[1], 3), round(k.size, 3))
        if key not in seen:
            seen.add(key)
            out.append(cv2.KeyPoint(k.pt[0], k.pt[1], k.size, 0.0, k.response, k.octave, k.class_id))
    return out
