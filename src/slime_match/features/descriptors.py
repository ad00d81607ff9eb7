"""Patch descriptors: HardNet, HardTFeat, TFeat (learned, kornia models) and RootSIFT (weight-free), all
L2-normalised.

The networks run as inference copies (:func:`~slime_match.features.inference.fuse_for_inference`); RootSIFT
is the vectorised :class:`~slime_match.features.gradients.SIFTPatchDescriptor` (kornia's ``SIFTDescriptor``
semantics and layout, about 2x faster).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch
import torch.nn.functional as F

from slime_match.choices import DESCRIPTOR_METHODS
from slime_match.errors import ConfigError, WeightsNotFoundError
from slime_match.features.gradients import SIFTPatchDescriptor
from slime_match.features.inference import fuse_for_inference
from slime_match.features.laf import PatchPyramid
from slime_match.features.weights import is_cached, load_model, load_state_dict

AUTO_ORDER = DESCRIPTOR_METHODS  # "auto" takes the first available: HardNet, HardTFeat, TFeat, then RootSIFT


@dataclass
class DescriptorConfig:
    """Descriptor options.

    Attributes:
        patch_size: side of the patches (pixels); the networks need 32.
        magnification: patch half-width in units of the LAF.
        batch_size: patches per network batch.
    """

    patch_size: int = 32
    magnification: float = 1.0
    batch_size: int = 256


def resolve_descriptor(name: str, weights_dir: str | Path | None = None,
                       candidates: tuple[str, ...] = AUTO_ORDER) -> tuple[str, str | None]:
    """Concrete descriptor for a name; "auto" is the first of ``candidates`` whose weights are cached or
    downloadable (when no download host resolves, a missing one is passed over at once instead of retried).

    Args:
        name: "auto" or one of :data:`DESCRIPTOR_METHODS`.
        weights_dir: see :func:`slime_match.features.weights.checkpoint_dir`.
        candidates: the descriptors "auto" may take, best first (:data:`AUTO_ORDER`; a pipeline that needs a
            network leaves out "rootsift").

    Returns:
        (descriptor name, warning text for the caller to record when "auto" could not take the best one, or
        None).

    Raises:
        WeightsNotFoundError: "auto" and no candidate is available.
    """
    if name != "auto":
        if name not in DESCRIPTOR_METHODS:
            raise ConfigError(f"unknown descriptor {name!r}; choose auto or one of {', '.join(DESCRIPTOR_METHODS)}")
        return name, None
    missing = []
    for candidate in candidates:
        if candidate == "rootsift" or is_cached(candidate, weights_dir):
            break
        try:  # downloads into the cache; offline, "auto" does not wait out the downloader's retries
            load_state_dict(candidate, weights_dir, retry_offline=False)
            break
        except WeightsNotFoundError as exc:
            missing.append((candidate, exc))
    else:
        raise WeightsNotFoundError(f"descriptor 'auto': none of {', '.join(candidates)} is available. {missing[-1][1]}")
    if not missing:
        return candidate, None
    kind = "weight-free" if candidate == "rootsift" else "learned"
    return candidate, (f"descriptor 'auto': {', '.join(c for c, _ in missing)} unavailable, using {candidate} "
                       f"({kind}) instead. {missing[0][1]}")


class Descriptor:
    """Describe LAF patches.

    Args:
        method: "hardnet", "hardtfeat", "tfeat" or "rootsift".
        device: torch device of the network.
        weights_dir: see :func:`slime_match.features.weights.checkpoint_dir`.
        config: options; defaults of :class:`DescriptorConfig`.
    """

    def __init__(
        self,
        method: str = "hardnet",
        device: str | torch.device = "cpu",
        weights_dir: str | Path | None = None,
        config: DescriptorConfig | None = None,
    ) -> None:
        if method not in DESCRIPTOR_METHODS:
            raise ConfigError(f"unknown descriptor {method!r}; choose one of {', '.join(DESCRIPTOR_METHODS)}")
        self.method = method
        self.config = config or DescriptorConfig()
        self.net: SIFTPatchDescriptor | torch.nn.Module
        if method == "rootsift":
            self.net = SIFTPatchDescriptor(self.config.patch_size, rootsift=True, device=device)
        else:
            self.net = fuse_for_inference(load_model(method, weights_dir, device))

    @property
    def dim(self) -> int:
        """Descriptor length (128 for all of them)."""
        return 128

    @torch.inference_mode()
    def describe_patches(self, patches: torch.Tensor) -> torch.Tensor:
        """(N, D) L2-normalised descriptors of patches (N, 1, P, P)."""
        return F.normalize(self.net(patches).reshape(patches.shape[0], -1), dim=1)

    @torch.inference_mode()
    def __call__(self, pyramid: PatchPyramid, laf: torch.Tensor) -> torch.Tensor:
        """(N, D) descriptors of the patches of LAFs (N, 2, 3) in pixels."""
        cfg = self.config
        if laf.shape[0] == 0:
            return torch.zeros(0, self.dim, device=pyramid.device)
        return torch.cat(
            [
                self.describe_patches(pyramid.extract(part, cfg.patch_size, cfg.magnification))
                for part in laf.split(cfg.batch_size)
            ]
        )
