"""Orientation of upright affine frames: OriNet (learned), dominant gradient (SIFT-like), upright, fixed.

Angles follow :mod:`slime_match.features.laf`: radians in pixel coordinates (x right, y down). OriNet and
the gradient histogram (:class:`~slime_match.features.gradients.DominantGradientOrientation`, kornia's
``PatchDominantGradientOrientation`` semantics) measure their angle in the patch of
the upright frame, counter-clockwise on screen (kornia's convention); the frame is rotated inside the
patch by the opposite angle, so that its patch x axis follows the estimated direction.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from slime_match.choices import ORIENTATION_METHODS
from slime_match.errors import ConfigError
from slime_match.features.gradients import DominantGradientOrientation
from slime_match.features.inference import fuse_for_inference
from slime_match.features.laf import PatchPyramid, rotate_laf, set_laf_angle, upright_laf
from slime_match.features.weights import load_model


@dataclass
class OrientationConfig:
    """Orientation options.

    Attributes:
        patch_size: side of the patches (pixels).
        magnification: patch half-width in units of the LAF.
        batch_size: patches per network batch.
        num_angular_bins: histogram bins of the gradient method.
        angle: image angle (radians) of every frame for the "fixed" method.
    """

    patch_size: int = 32
    magnification: float = 1.0
    batch_size: int = 256
    num_angular_bins: int = 36
    angle: float = 0.0


class Orienter:
    """Assign orientations to LAFs.

    Args:
        method: "orinet", "gradient", "upright" (angle 0) or "fixed" (``config.angle`` for all frames).
        device: torch device of the network.
        weights_dir: see :func:`slime_match.features.weights.checkpoint_dir`.
        config: options; defaults of :class:`OrientationConfig`.
    """

    def __init__(
        self,
        method: str = "orinet",
        device: str | torch.device = "cpu",
        weights_dir: str | Path | None = None,
        config: OrientationConfig | None = None,
    ) -> None:
        if method not in ORIENTATION_METHODS:
            raise ConfigError(
                f"unknown orientation method {method!r}; choose one of {', '.join(ORIENTATION_METHODS)}"
            )
        self.method = method
        self.config = config or OrientationConfig()
        self.net: torch.nn.Module | DominantGradientOrientation | None = None
        if method == "orinet":
            self.net = fuse_for_inference(load_model("orinet", weights_dir, device))
        elif method == "gradient":
            self.net = DominantGradientOrientation(self.config.patch_size, self.config.num_angular_bins, device)

    @torch.inference_mode()
    def patch_angles(self, patches: torch.Tensor) -> torch.Tensor:
        """(N,) rotation (radians, patch pixel coordinates) of the content of patches (N, 1, P, P)."""
        return -self.net(patches).reshape(-1)

    @torch.inference_mode()
    def __call__(self, pyramid: PatchPyramid, laf: torch.Tensor) -> torch.Tensor:
        """Oriented LAFs on the same ellipses.

        Args:
            pyramid: the image's patch pyramid.
            laf: (N, 2, 3) LAFs in pixels (their own orientation is ignored).

        Returns:
            (N, 2, 3) oriented LAFs.
        """
        cfg = self.config
        laf = laf.to(pyramid.device, torch.float32)
        if self.method == "upright":
            return upright_laf(laf)
        if self.method == "fixed":
            return set_laf_angle(laf, cfg.angle)
        up = upright_laf(laf)
        if up.shape[0] == 0:
            return up
        angles = torch.cat(
            [self.patch_angles(pyramid.extract(part, cfg.patch_size, cfg.magnification)) for part in up.split(cfg.batch_size)]
        )
        return rotate_laf(up, angles)
