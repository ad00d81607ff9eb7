"""Key.Net: kornia's Key.Net detector, AffNet, OriNet|upright, HardNet|TFeat and AdaLAM (the paper's Key.Net
pipeline)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import torch

from ..errors import ConfigError
from ..features.extractor import LocalFeatureExtractor, PatchConfig
from ..features.laf import PatchPyramid
from ..types import Features, Matches
from .base import BaseConfig, BasePipeline, _empty_features, _filtered

KORNIA_PYRDOWN_SIGMA = 1.0  # kornia's pyrdown kernel [1, 4, 6, 4, 1] / 16 has variance 1


@dataclass
class KeyNetContext:
    pyramid: PatchPyramid  # of the image's luminance

    @property
    def grey(self) -> torch.Tensor:
        """(1, 1, H, W) float luminance in [0, 1]: the pyramid's level 0, Key.Net's input."""
        return self.pyramid.levels[0]


class KeyNetPipeline(BasePipeline):
    """Key.Net -> AffNet -> OriNet|upright -> HardNet|TFeat -> AdaLAM: the paper's Key.Net pipeline (kornia's
    ``KeyNetAffNetHardNet`` + ``match_adalam``).

    kornia's Key.Net detector gives the frames (its LAFs already span ``mr_size`` = 6 detection scales, so
    patches are sampled at magnification 1, as kornia's patch modules do); the patch networks then run in
    the package's :class:`LocalFeatureExtractor` (compiled patch sampling, inference-folded networks), the
    same stages as Hz+, on a pyramid blurred like kornia's (``KORNIA_PYRDOWN_SIGMA``). Against kornia's own
    modules: features about 2x faster, 0.6-2.3% fewer correct matches on graf 1->2..1->4 (TFeat; 2-5% fewer
    with the default anti-aliased pyramid). Only filled detections are kept (kornia pads to
    ``max_keypoints`` with zero frames). AdaLAM scores are its inverse local-RANSAC confidences. A
    ``candidate_filter`` (Slime's tile refinement) is applied to AdaLAM's output: AdaLAM starts from every
    keypoint's nearest neighbour, so it cannot take a pre-filtered candidate list.
    """

    name = "keynet"
    slime_global_dtm = False
    options = frozenset({"descriptor", "shape", "orientation", "upright", "max_keypoints", "magnification",
                         "weights_dir"})

    def __init__(self, config: BaseConfig, device: torch.device) -> None:
        import kornia.feature as KF

        from ..features.weights import load_model

        if config.descriptor not in ("hardnet", "hardtfeat", "tfeat"):
            raise ConfigError("the keynet base pipeline describes with hardnet, hardtfeat or tfeat, not "
                              f"{config.descriptor!r}")
        if config.shape != "affnet":
            raise ConfigError(f"the keynet base pipeline uses AffNet shapes, not {config.shape!r}")
        upright = config.upright or config.orientation == "upright"
        if not upright and config.orientation != "orinet":
            raise ConfigError(f"the keynet base pipeline orients with orinet or upright, not {config.orientation!r}")
        self.config, self.device = config, device
        self.detector = KF.KeyNetDetector(False, num_features=config.max_keypoints)
        self.detector.model = load_model("keynet", config.weights_dir)
        self.detector = self.detector.to(device).eval()
        magnification = 1.0 if config.magnification is None else config.magnification
        self.patch = PatchConfig(shape="affnet", orientation="upright" if upright else "orinet",
                                 descriptor=config.descriptor, magnification=magnification,
                                 weights_dir=config.weights_dir)
        self.extractor = LocalFeatureExtractor(self.patch, device=device)

    def prepare(self, image: np.ndarray) -> KeyNetContext:
        grey = cv2.cvtColor(np.ascontiguousarray(image, dtype=np.float32), cv2.COLOR_RGB2GRAY)
        grey = torch.from_numpy(grey)[None].to(self.device)
        return KeyNetContext(PatchPyramid(grey, decimation_sigma=KORNIA_PYRDOWN_SIGMA))

    @torch.inference_mode()
    def _frames(self, context: KeyNetContext) -> tuple[torch.Tensor, torch.Tensor]:
        """Key.Net's filled detections: LAFs (N, 2, 3) in pixels and responses (N,)."""
        responses, lafs = self.detector.detect(context.grey)
        filled = responses[0] > 0
        return lafs[0, filled], responses[0, filled]

    def detect_regions(self, context: KeyNetContext) -> Features:
        laf, response = self._frames(context)
        shape = self.extractor.adapt_shape(context.pyramid, laf)
        return Features(shape, torch.zeros(len(shape), 0, device=shape.device), response, shape)

    def detect(self, context: KeyNetContext) -> Features:
        laf, response = self._frames(context)
        if len(laf) == 0:
            return _empty_features(128, self.device)
        return self.extractor.extract_frames(context.pyramid, laf, response)

    def describe_fixed(self, context: KeyNetContext, features: Features, angle: float) -> Features:
        if len(features) == 0:
            return _empty_features(128, self.device)
        return self.extractor.describe_fixed(context.pyramid, features.shape_laf, angle)

    def describe_batch(self) -> int | None:
        return self.patch.batch_size  # as for Hz+

    def own_frames_upright(self) -> bool:
        return self.patch.orientation == "upright"  # as for Hz+

    def kernel_groups(self) -> tuple[str, ...]:
        return ("patches",) if self.device.type == "cpu" else ()

    @torch.inference_mode()
    def match(self, features0, features1, size0, size1, candidate_filter=None) -> Matches:
        import kornia.feature as KF

        if len(features0) < 2 or len(features1) < 2:
            return Matches.empty()
        dists, idx = KF.match_adalam(features0.descriptors, features1.descriptors, features0.laf[None],
                                     features1.laf[None], hw1=tuple(size0), hw2=tuple(size1))
        idx = idx.cpu().numpy()
        matches = Matches(idx[:, 0], idx[:, 1], dists.reshape(-1).cpu().numpy())
        return _filtered(matches, features0, features1, candidate_filter)

    def describe(self) -> dict[str, Any]:
        return {"base": "keynet", "detector": "keynet", "max_keypoints": self.config.max_keypoints,
                **self.patch.summary(),
                "matcher": "adalam"}
