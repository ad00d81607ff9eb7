"""Keypoint ellipses to described local features: LAF, affine shape, orientation, descriptor.

Features keep frames at the detector's scale (the unit circle of ``laf`` is the adapted ellipse); the
patches of every stage span ``magnification`` times that frame (``PatchConfig.magnification``, 6 by default
over HarrisZ+ ellipses: larger supports give more correct matches, flattening after 4-5; the measurements are
in docs/quality.md, "Patch magnification").
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from functools import cache
from pathlib import Path

import torch

from slime_match._runtime.options import config_from_dict
from slime_match.errors import ConfigError
from slime_match.features.descriptors import Descriptor, DescriptorConfig
from slime_match.features.gradients import DominantGradientOrientation, SIFTPatchDescriptor
from slime_match.features.laf import PatchPyramid, ellipse_to_laf, set_laf_angle
from slime_match.features.orientation import OrientationConfig, Orienter
from slime_match.features.shape import ShapeConfig, ShapeEstimator, second_moment_shape
from slime_match.types import Features, Keypoints

logger = logging.getLogger("slime_match")


@dataclass
class PatchConfig:
    """Options of the patch pipeline.

    Attributes:
        shape: "affnet", "baumberg" or "none" (keep the detector ellipse).
        orientation: "orinet", "gradient" or "upright".
        descriptor: "hardnet", "hardtfeat", "tfeat" or "rootsift" (resolve "auto" first with
            :func:`slime_match.features.descriptors.resolve_descriptor`).
        magnification: patch half-width over the detector ellipse, for every stage.
        patch_size: patch side in pixels (the networks need 32).
        batch_size: patches per network batch. On CPU 256 is ~20% faster than 2048 (activations stay in
            the allocator's reused heap) and bounds memory: peak of a 640x480 AffNet+OriNet+TFeat pair
            484 -> 150 MB (benchmarks/bench_base.py).
        weights_dir: folder of the weights; None for kornia's cache (``TORCH_HOME``).
    """

    shape: str = "affnet"
    orientation: str = "orinet"
    descriptor: str = "tfeat"
    magnification: float = 6.0
    patch_size: int = 32
    batch_size: int = 256
    weights_dir: str | Path | None = None

    @classmethod
    def from_dict(cls, options: dict) -> PatchConfig:
        """Config from a dict; unknown keys raise :class:`ConfigError`."""
        return config_from_dict(cls, options)

    def summary(self) -> dict:
        """The fields as JSON-ready values (``weights_dir`` as text), for an output summary."""
        return {k: str(v) if k == "weights_dir" else v for k, v in asdict(self).items()}


class LocalFeatureExtractor:
    """Describe keypoints: ellipse (HarrisZ+) or LAF (Key.Net) -> shape -> orientation -> descriptor.

    Args:
        config: pipeline options.
        device: torch device for the networks and the patch pyramid.
    """

    def __init__(self, config: PatchConfig | None = None, device: str | torch.device = "cpu") -> None:
        self.config = cfg = config or PatchConfig()
        self.device = torch.device(device)
        if cfg.orientation == "fixed":
            raise ConfigError("orientation 'fixed' needs an angle: use LocalFeatureExtractor.describe_fixed")
        common = {"patch_size": cfg.patch_size, "magnification": cfg.magnification, "batch_size": cfg.batch_size}
        self.shape = (
            None
            if cfg.shape == "none"
            else ShapeEstimator(cfg.shape, self.device, cfg.weights_dir, ShapeConfig(**common))
        )
        self.orienter = Orienter(cfg.orientation, self.device, cfg.weights_dir, OrientationConfig(**common))
        self.descriptor = Descriptor(cfg.descriptor, self.device, cfg.weights_dir, DescriptorConfig(**common))

    def pyramid(self, image: torch.Tensor) -> PatchPyramid:
        """Patch pyramid of a (C, H, W) float image in [0, 1], on the extractor's device."""
        return PatchPyramid(image.to(self.device))

    def extract(self, image: torch.Tensor, keypoints: Keypoints, pyramid: PatchPyramid | None = None) -> Features:
        """Described features of keypoints.

        Args:
            image: (C, H, W) float image in [0, 1] (ignored when ``pyramid`` is given).
            keypoints: detector keypoints with their ellipses.
            pyramid: the image's pyramid, to share it with other extractions of the same image.

        Returns:
            Features with ``laf`` (oriented), ``descriptors`` (N, 128), ``response`` and ``shape_laf``
            (upright affine-normalised frames, for :meth:`describe_fixed`).
        """
        pyr = pyramid if pyramid is not None else self.pyramid(image)
        return self.extract_frames(pyr, keypoint_frames(keypoints, self.device), keypoints.response)

    def extract_frames(self, pyramid: PatchPyramid, laf: torch.Tensor, response: torch.Tensor) -> Features:
        """Described features of a detector's frames (another detector's LAFs, e.g. Key.Net's).

        Args:
            pyramid: the image's pyramid.
            laf: (N, 2, 3) frames in pixels, any orientation (only centre, scale and ellipse are used).
            response: (N,) detector responses to carry.

        Returns:
            Features as :meth:`extract`.
        """
        shape_laf = self.adapt_shape(pyramid, laf)
        oriented = self.orienter(pyramid, shape_laf)
        desc = self.descriptor(pyramid, oriented)
        response = response.to(self.device, torch.float32)
        return Features(laf=oriented, descriptors=desc, response=response, shape_laf=shape_laf)

    def shape_frames(self, pyramid: PatchPyramid, keypoints: Keypoints) -> torch.Tensor:
        """(N, 2, 3) upright affine-normalised frames of keypoints (ellipse -> LAF -> shape estimator)."""
        return self.adapt_shape(pyramid, keypoint_frames(keypoints, self.device))

    def adapt_shape(self, pyramid: PatchPyramid, laf: torch.Tensor) -> torch.Tensor:
        """(N, 2, 3) upright frames of LAFs (N, 2, 3) after the shape estimator (upright input without one)."""
        laf = laf.to(self.device, torch.float32)
        return self.shape(pyramid, laf) if self.shape is not None else set_laf_angle(laf, 0.0)

    def describe_fixed(
        self, pyramid: PatchPyramid, shape_laf: torch.Tensor, angle: float, response: torch.Tensor | None = None
    ) -> Features:
        """Re-describe upright frames under one fixed image angle (Slime's orientation-refined run); no OriNet.

        Args:
            pyramid: the image's pyramid.
            shape_laf: (N, 2, 3) upright affine frames (``Features.shape_laf``).
            angle: image angle in radians, pixel coordinates (0 in image 1, theta* in image 2).
            response: optional (N,) responses to carry (zeros otherwise).

        Returns:
            Features whose patch x axes all point at ``angle``.
        """
        laf = set_laf_angle(shape_laf.to(pyramid.device, torch.float32), angle)
        desc = self.descriptor(pyramid, laf)
        if response is None:
            response = torch.zeros(laf.shape[0], device=laf.device)
        return Features(laf=laf, descriptors=desc, response=response.to(laf.device), shape_laf=shape_laf)


def keypoint_frames(keypoints: Keypoints, device: torch.device) -> torch.Tensor:
    """(N, 2, 3) LAFs mapping the unit circle onto the keypoints' ellipses, on ``device``."""
    xy = keypoints.xy.to(device, torch.float32)
    return ellipse_to_laf(xy, keypoints.ellipse.to(device, torch.float32))


@cache
def warm_up() -> None:
    """Load the compiled patch loops (``patch_kernels``: sampling, Baumberg moments, orientation and SIFT
    histograms) in this process, once, by running each on a few CPU patches (from numba's on-disk cache, or
    compiled on first use: a few seconds). Call it before forking workers that extract features on CPU, or
    each of them pays it."""
    g = torch.Generator().manual_seed(0)
    pyramid = PatchPyramid(torch.rand(1, 48, 48, generator=g))
    laf = torch.tensor([[[4.0, 0.0, 24.0], [0.0, 4.0, 24.0]]]).repeat(3, 1, 1)
    patches = pyramid.extract(laf, 32, 1.0)
    second_moment_shape(patches, 10.0)
    DominantGradientOrientation(32)(patches)
    SIFTPatchDescriptor(32)(patches)
