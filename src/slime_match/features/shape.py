"""Affine shape adaptation of LAFs: AffNet (learned) or Baumberg's second-moment iteration (weight-free).

Both estimate, on the patch of the current upright frame ``U``, a shape ``S`` in patch coordinates and
return the upright frame of ``U S``, rescaled to the scale (sqrt det) of the input: centre and scale are
kept, only the ellipse's anisotropy and direction change.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from slime_match.choices import SHAPE_METHODS
from slime_match.errors import ConfigError
from slime_match.features.gradients import patch_gradients
from slime_match.features.inference import fuse_for_inference
from slime_match.features.laf import PatchPyramid, laf_scale, upright_laf
from slime_match.features.patch_kernels import second_moments
from slime_match.features.weights import load_model

# Frames per Baumberg step: no network, so large steps amortise the per-call overhead (16 MiB of patches).
_BAUMBERG_CHUNK = 4096


@dataclass
class ShapeConfig:
    """Shape estimation options.

    Attributes:
        patch_size: side of the patches the estimator sees (pixels).
        magnification: patch half-width in units of the LAF.
        batch_size: patches per network batch.
        baumberg_iterations: shape-adaptation steps of the Baumberg method.
        max_anisotropy: largest axis ratio accepted; a keypoint whose estimate exceeds it keeps its input shape.
    """

    patch_size: int = 32
    magnification: float = 1.0
    batch_size: int = 256
    baumberg_iterations: int = 4
    max_anisotropy: float = 6.0


def _compose_keep_scale(up: torch.Tensor, shape: torch.Tensor, max_anisotropy: float) -> torch.Tensor:
    """Upright frame of ``U S`` with the scale of ``U``; the input where S is degenerate or too anisotropic.

    Args:
        up: (N, 2, 3) upright LAFs.
        shape: (N, 2, 2) shapes in normalised patch coordinates.
        max_anisotropy: largest accepted axis ratio of the result.

    Returns:
        (N, 2, 3) upright LAFs.
    """
    a = up[:, :, :2] @ shape
    det = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
    scale = laf_scale(up)
    a = a * (scale / det.abs().clamp_min(1e-30).sqrt())[:, None, None]
    sv = torch.linalg.svdvals(a)
    ok = torch.isfinite(a).flatten(1).all(1) & (det > 0) & (sv[:, 0] <= max_anisotropy * sv[:, 1])
    out = upright_laf(torch.cat([a, up[:, :, 2:]], dim=2))
    return torch.where(ok[:, None, None], out, up)


def _second_moments(patches: torch.Tensor, window_sigma: float) -> torch.Tensor:
    """(N, 3) float64 Gaussian-weighted sums of ``gx^2``, ``gx gy``, ``gy^2`` (Sobel) of patches (N, 1, P, P).

    A compiled per-patch loop on CPU (:func:`~slime_match.features.patch_kernels.second_moments`), whole-batch
    torch operations elsewhere.
    """
    p = patches.shape[-1]
    t = torch.arange(p, dtype=patches.dtype, device=patches.device) - (p - 1) / 2
    w1 = torch.exp(-0.5 * (t / window_sigma) ** 2)
    w = w1[:, None] * w1[None, :]  # (P, P)
    if patches.device.type == "cpu":
        return torch.from_numpy(second_moments(patches[:, 0].numpy(), w.numpy()))
    return _torch_second_moments(patches, w)


def _torch_second_moments(patches: torch.Tensor, window: torch.Tensor) -> torch.Tensor:
    """:func:`_second_moments` by whole-batch torch operations, for the Gaussian ``window`` (P, P)."""
    n, _, p, _ = patches.shape
    gx, gy = patch_gradients(patches, "sobel")  # (N, P, P) each
    w = window.reshape(p * p)
    gx, gy = gx.reshape(n, p * p), gy.reshape(n, p * p)
    wgx = gx * w
    return torch.stack([(wgx * gx).sum(1), (wgx * gy).sum(1), (gy * gy * w).sum(1)], 1).double()


def second_moment_shape(patches: torch.Tensor, window_sigma: float) -> torch.Tensor:
    """Baumberg step: the normalising transform ``M^{-1/2}`` of the patches' gradient second-moment matrix.

    Args:
        patches: (N, 1, P, P) grey patches.
        window_sigma: Gaussian window sigma in patch pixels.

    Returns:
        (N, 2, 2) shapes ``M^{-1/2}`` with det 1 (identity for flat patches).
    """
    a, b, c = _second_moments(patches, window_sigma).unbind(1)  # M = [[a, b], [b, c]]
    det = a * c - b * b
    tr = a + c
    flat = ~(det > 1e-12 * tr.square()) | ~(tr > 1e-12)
    one, zero = torch.ones_like(a), torch.zeros_like(a)
    a, b, c = torch.where(flat, one, a), torch.where(flat, zero, b), torch.where(flat, one, c)
    # For 2x2 SPD M, R = M + sqrt(det M) I is proportional to M^{1/2}; R^{-1} normalised to det 1 is
    # adj(R) / sqrt(det R) (closed form, no batched LAPACK call).
    s = (a * c - b * b).sqrt()
    r00, r11 = a + s, c + s
    norm = (r00 * r11 - b * b).rsqrt()
    inv = torch.stack([torch.stack([r11, -b], -1), torch.stack([-b, r00], -1)], -2) * norm[:, None, None]
    return inv.to(patches.dtype)


class ShapeEstimator:
    """Affine shape of LAFs by AffNet or Baumberg.

    Args:
        method: "affnet" or "baumberg".
        device: torch device of the network.
        weights_dir: see :func:`slime_match.features.weights.checkpoint_dir`.
        config: options; defaults of :class:`ShapeConfig`.
    """

    def __init__(
        self,
        method: str = "affnet",
        device: str | torch.device = "cpu",
        weights_dir: str | Path | None = None,
        config: ShapeConfig | None = None,
    ) -> None:
        if method not in SHAPE_METHODS:
            raise ConfigError(f"unknown shape method {method!r}; choose one of {', '.join(SHAPE_METHODS)}")
        self.method = method
        self.config = config or ShapeConfig()
        self.net = fuse_for_inference(load_model("affnet", weights_dir, device)) if method == "affnet" else None

    def _affnet_shape(self, patches: torch.Tensor) -> torch.Tensor:
        """(N, 2, 2) AffNet shapes ``[[1 + a, 0], [b, 1 + c]]`` of patches (N, 1, 32, 32)."""
        out = self.net.features(self.net._normalize_input(patches)).view(-1, 3)
        zero = torch.zeros_like(out[:, 0])
        return torch.stack([torch.stack([1 + out[:, 0], zero], -1), torch.stack([out[:, 1], 1 + out[:, 2]], -1)], -2)

    @torch.inference_mode()
    def __call__(self, pyramid: PatchPyramid, laf: torch.Tensor) -> torch.Tensor:
        """Affine-adapted upright LAFs.

        Args:
            pyramid: the image's patch pyramid.
            laf: (N, 2, 3) LAFs in pixels.

        Returns:
            (N, 2, 3) upright LAFs with the input centres and scales.
        """
        cfg = self.config
        up = upright_laf(laf.to(pyramid.device, torch.float32))
        chunks = []
        for part in up.split(cfg.batch_size if self.method == "affnet" else _BAUMBERG_CHUNK):
            if self.method == "affnet":
                patches = pyramid.extract(part, cfg.patch_size, cfg.magnification)
                part = _compose_keep_scale(part, self._affnet_shape(patches), cfg.max_anisotropy)
            else:
                # The window covers the unit ellipse: radius (P - 1) / (2 m) patch pixels = 1.5 sigma.
                sigma = (cfg.patch_size - 1) / (2.0 * cfg.magnification) / 1.5
                for _ in range(cfg.baumberg_iterations):
                    patches = pyramid.extract(part, cfg.patch_size, cfg.magnification)
                    part = _compose_keep_scale(part, second_moment_shape(patches, sigma), cfg.max_anisotropy)
            chunks.append(part)
        return torch.cat(chunks) if chunks else up
