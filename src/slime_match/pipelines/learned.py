"""Learned bases through kornia: ALIKED, DISK or XFeat keypoints and descriptors, matched by LightGlue
(LighterGlue for XFeat) or by mutual nearest neighbours with a ratio test.

Each pair of extractor and matcher is a base pipeline of its own, registered as ``<extractor>-lg`` or
``<extractor>-nn`` (:data:`LEARNED_BASES`). The networks and their weights are kornia's
(:mod:`slime_match.features.learned_weights`); the images they see are the matcher's working images (the
presets shrink them to 1024 px on the longer side), and the keypoints come back in the pixels of those images
(the centre of the top-left pixel is (0, 0)).

Slime runs on them as on any base (``slime --base aliked-lg``): the blocks' and tiles' features come from the
extractor on each block scale's image, and the block and tile pairs are matched by the pipeline's matcher. The
extractors give no orientation, so their frames are upright: every relative orientation Slime reads between
two upright images is 0, and the orientation re-run of Sec. 3.3 reuses the first run's matches. A plane
found through a simulated view carries the view's turn; its tiles are then described under that orientation
by describing the keypoints on the image turned the other way (``describe_fixed``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from ..choices import LEARNED_BASES as LEARNED_NAMES
from ..features import learned_weights
from ..geometry.frames import Frame
from ..matching.nn import match_mutual_nn_ratio
from ..types import Features, Matches
from ..views import simulate_view
from .base import BaseConfig, BasePipeline, _empty_features, _filtered

# registered name -> (extractor, matcher)
LEARNED_BASES: dict[str, tuple[str, str]] = {
    name: (name.split("-")[0], {"lg": "lightglue", "nn": "mutual-nn"}[name.split("-")[1]]) for name in LEARNED_NAMES
}
DESCRIPTOR_DIMS = {"aliked": 128, "disk": 128, "xfeat": 64}
GLUE_NAMES = {"aliked": "LightGlue", "disk": "LightGlue", "xfeat": "LighterGlue"}


def unit_frames(xy: torch.Tensor) -> torch.Tensor:
    """(N, 2, 3) upright LAFs of unit scale centred on the (N, 2) keypoints: these extractors give positions only."""
    laf = torch.zeros(len(xy), 2, 3, dtype=torch.float32, device=xy.device)
    laf[:, 0, 0] = laf[:, 1, 1] = 1.0
    laf[:, :, 2] = xy.float()
    return laf


def xfeat_pixels(keypoints: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """XFeat's (N, 2) keypoints in the pixels of the (H, W) image it was given. XFeat detects on the image resized
    to multiples of 32 (bilinear, pixel edges aligned) and scales its keypoints by the size ratio only; the exact
    map of that resize adds ``(ratio - 1) / 2`` px per axis."""
    height, width = size
    inner = (max(32, width // 32 * 32), max(32, height // 32 * 32))
    ratio = torch.tensor([width / inner[0], height / inner[1]], dtype=torch.float64)
    xy = Frame.of_sizes(inner, (width, height)).to_original((keypoints.double().cpu() / ratio).numpy())
    return torch.from_numpy(xy).float().to(keypoints.device)


class LearnedPipeline(BasePipeline):
    """A learned extractor (``extractor``: "aliked", "disk" or "xfeat") and a matcher (``matcher``: "lightglue"
    or "mutual-nn"), both kornia's networks on the working images.

    Extractors: ALIKED (``aliked_model`` n16, n16rot or n32; the score maxima above ``aliked_threshold``, at
    most ``max_keypoints``), DISK ("depth" weights, at most ``max_keypoints``), XFeat (its ``max_keypoints``
    strongest detections; XFeat resizes the image to multiples of 32 inside, which the keypoints are mapped back
    from exactly). Matchers: LightGlue with the extractor's weights (LighterGlue for XFeat), whose scores are
    ``1 - matching score``; or mutual nearest neighbours with Lowe's ratio test (``nn_ratio``), whose scores are
    the distance ratios. Both: lower is better. A ``candidate_filter`` applies to the matcher's output.

    Raises:
        WeightsNotFoundError: a network's weights are neither in kornia's cache nor downloadable (at build).
    """

    extractor: str = ""
    matcher: str = ""

    def __init__(self, config: BaseConfig, device: torch.device) -> None:
        self.config, self.device = config, device
        if self.extractor == "aliked":
            self.network = learned_weights.aliked(config.aliked_model, config.max_keypoints, config.aliked_threshold,
                                                  device)
        elif self.extractor == "disk":
            self.network = learned_weights.disk(device)
        else:
            self.network = learned_weights.xfeat(config.max_keypoints, device)
        self.glue = learned_weights.lightglue(self.extractor, device) if self.matcher == "lightglue" else None

    def _tensor(self, image: np.ndarray) -> torch.Tensor:
        """(1, 3, H, W) float32 on the pipeline's device of an (H, W, 3) float image, clipped to [0, 1]."""
        rgb = torch.from_numpy(np.clip(np.ascontiguousarray(image, dtype=np.float32), 0.0, 1.0))
        return rgb.permute(2, 0, 1)[None].to(self.device)

    @torch.inference_mode()
    def extract(self, image: np.ndarray) -> Features:
        """Keypoints (as unit upright LAFs), L2-normalised descriptors and detection scores of an (H, W, 3) image."""
        rgb = self._tensor(image)
        if self.extractor == "aliked":
            found = self.network(rgb)[0]
            xy, descriptors, scores = found.keypoints, found.descriptors, found.keypoint_scores
        elif self.extractor == "disk":
            found = self.network(rgb, n=self.config.max_keypoints, pad_if_not_divisible=True)[0]
            xy, descriptors, scores = found.keypoints, found.descriptors, found.detection_scores
        else:
            found = self.network.detectAndCompute(rgb)[0]
            xy, descriptors, scores = xfeat_pixels(found["keypoints"], image.shape[:2]), \
                found["descriptors"], found["scores"]
        if len(xy) == 0:
            return _empty_features(DESCRIPTOR_DIMS[self.extractor], self.device)
        laf = unit_frames(xy)
        return Features(laf, descriptors.float(), scores.float().reshape(-1), laf)

    @torch.inference_mode()
    def match(self, features0, features1, size0, size1, candidate_filter=None) -> Matches:
        if len(features0) < 2 or len(features1) < 2:
            return Matches.empty()
        if self.glue is None:
            matches = match_mutual_nn_ratio(features0.descriptors, features1.descriptors, self.config.nn_ratio)
        else:

            def side(features: Features, size: tuple[int, int]) -> dict[str, torch.Tensor]:
                wh = torch.tensor([[size[1], size[0]]], dtype=torch.float32, device=self.device)
                return {"keypoints": features.xy[None], "descriptors": features.descriptors[None], "image_size": wh}

            out = self.glue({"image0": side(features0, size0), "image1": side(features1, size1)})
            idx = out["matches"][0].cpu().numpy().reshape(-1, 2)
            scores = 1.0 - out["scores"][0].double().cpu().numpy().reshape(-1)
            order = np.argsort(scores, kind="stable")
            matches = Matches(idx[order, 0], idx[order, 1], scores[order])
        return _filtered(matches, features0, features1, candidate_filter)

    @torch.inference_mode()
    def describe_fixed(self, context: np.ndarray, features: Features, angle: float) -> Features:
        """``features`` of the (H, W, 3) image ``context`` under orientation ``angle`` (radians): their own at a
        multiple of a full turn; otherwise described on the image turned by ``-angle`` (ASIFT's view of tilt 1:
        bilinear, on a canvas that holds all of it), where a patch whose x axis points along ``angle`` stands
        upright."""
        if abs(math.remainder(angle, 2 * math.pi)) < 1e-9 or len(features) == 0:
            return features
        turned, view = simulate_view(context, 1.0, math.degrees(angle))  # a view of tilt 1: the turn alone
        to_turned = np.reshape(view.affine, (2, 3))
        xy = features.xy.detach().cpu().double().numpy() @ to_turned[:, :2].T + to_turned[:, 2]
        descriptors = self.describe_at(turned, torch.from_numpy(xy).float().to(self.device))
        laf = unit_frames(features.xy)
        cos, sin = math.cos(angle), math.sin(angle)
        laf[:, :, :2] = torch.tensor([[cos, -sin], [sin, cos]], dtype=laf.dtype, device=laf.device)
        return Features(laf, descriptors, features.response, laf)

    @torch.inference_mode()
    def describe_at(self, image: np.ndarray, xy: torch.Tensor) -> torch.Tensor:
        """(N, D) L2-normalised descriptors of the extractor at the (N, 2) pixel positions ``xy`` of an
        (H, W, 3) image: ALIKED's descriptor head on its dense map, DISK's dense descriptors and XFeat's
        (at 1/8 of its multiple-of-32 resize) sampled bilinearly there."""
        rgb = self._tensor(image)
        height, width = image.shape[:2]
        if self.extractor == "aliked":
            dense, _ = self.network.extract_dense_map(rgb)
            span = torch.tensor([width - 1, height - 1], dtype=torch.float32, device=self.device)
            descriptors, _ = self.network.desc_head(dense, [xy / span * 2 - 1])
            return descriptors[0].float()
        if self.extractor == "disk":
            pad = (0, -width % 16, 0, -height % 16)
            _, dense = self.network.heatmap_and_dense_descriptors(torch.nn.functional.pad(rgb, pad))
            return _sampled(dense[..., :height, :width], xy)
        inner, ratio_h, ratio_w = self.network._preprocess_tensor(rgb)
        dense = torch.nn.functional.normalize(self.network.net(inner)[0], dim=1)
        # image px -> the resized image's px (pixel edges aligned), then -> the 1/8 map's sampling grid
        ratio = torch.tensor([ratio_w, ratio_h], dtype=torch.float32, device=self.device)
        inner_xy = (xy + 0.5) / ratio - 0.5
        samples = self.network.interpolator(dense, inner_xy[None], H=inner.shape[-2], W=inner.shape[-1])[0]
        return torch.nn.functional.normalize(samples, dim=-1)

    def own_frames_upright(self) -> bool:
        return True  # unit upright frames, described by the network as they are

    def upright_by_design(self) -> bool:
        return not (self.extractor == "aliked" and self.config.aliked_model == "n16rot")  # n16rot: trained for turns

    def kernel_groups(self) -> tuple[str, ...]:
        # mutual NN runs the nearest-neighbour loops of Blob matching on the CPU
        return ("blob",) if self.matcher == "mutual-nn" and self.device.type == "cpu" else ()

    def describe(self) -> dict[str, Any]:
        summary: dict[str, Any] = {"base": self.name, "detector": self.extractor, "descriptor": self.extractor,
                                   "max_keypoints": self.config.max_keypoints}
        if self.extractor == "aliked":
            summary.update(aliked_model=self.config.aliked_model, aliked_threshold=self.config.aliked_threshold)
        if self.glue is None:
            summary.update(matcher="mutual-nn", nn_ratio=self.config.nn_ratio)
        else:
            summary["matcher"] = GLUE_NAMES[self.extractor].lower()
        return summary


def _sampled(dense: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
    """(N, D) L2-normalised bilinear samples of a (1, D, H, W) dense map at (N, 2) pixel positions."""
    height, width = dense.shape[-2:]
    span = torch.tensor([max(width - 1, 1), max(height - 1, 1)], dtype=torch.float32, device=dense.device)
    grid = (xy / span * 2 - 1)[None, None]
    samples = torch.nn.functional.grid_sample(dense, grid, mode="bilinear", align_corners=True)[0, :, 0].T
    return torch.nn.functional.normalize(samples, dim=-1)


def learned_pipeline_class(name: str) -> type[LearnedPipeline]:
    """The pipeline class registered as ``name`` (a key of :data:`LEARNED_BASES`)."""
    extractor, matcher = LEARNED_BASES[name]
    options = {"max_keypoints"} | ({"aliked_model", "aliked_threshold"} if extractor == "aliked" else set()) \
        | ({"nn_ratio"} if matcher == "mutual-nn" else set())
    return type(f"{extractor.upper()}{'LightGlue' if matcher == 'lightglue' else 'MutualNN'}Pipeline",
                (LearnedPipeline,), {"name": name, "extractor": extractor, "matcher": matcher,
                                     "options": frozenset(options), "__module__": __name__,
                                     # LightGlue reads the whole image: Slime gives it whole block levels
                                     "slime_block_matching": "levels" if matcher == "lightglue" else "pairs",
                                     # a third of Hz+'s: Slime's F^theta on ALIKED holds 0.33-0.38 of its
                                     # matches on Hz+ on graf 1->3 and 1->4 (at most 3072 keypoints a scale)
                                     "slime_view_gain": 0.35,
                                     "__doc__": f"{extractor} + {matcher} (see :class:`LearnedPipeline`)."})
