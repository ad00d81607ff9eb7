"""Base matching pipelines (Hz+, RootSIFT and Key.Net) behind one interface.

A base pipeline turns an image into :class:`~slime_match.types.Features` and two feature sets into
:class:`~slime_match.types.Matches`. Slime drives it through four calls:

* ``prepare(image)`` -> an image context (tensor, patch pyramid...) built once per image or block;
* ``detect(context)`` -> features with their own orientation (or upright when configured so);
* ``describe_fixed(context, features, angle)`` -> the same regions re-described under one fixed
  orientation (Slime's orientation-refined re-run, Sec. 3.3 of the paper);
* ``match(f0, f1, size0, size1)`` -> candidate matches after the pipeline's own filter (DTM / FGINN /
  AdaLAM).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import torch

from .errors import ConfigError
from .features.extractor import LocalFeatureExtractor, PatchConfig
from .features.extractor import load_kernels as load_patch_kernels
from .features.harrisz import HarrisZConfig, detect_harrisz
from .features.laf import PatchPyramid
from .io import to_tensor
from .matching import blob, dtm
from .matching.blob import BlobConfig, blob_match
from .matching.dtm import DTMConfig, dtm_filter
from .matching.nn import match_fginn
from .types import Features, Keypoints, Matches

logger = logging.getLogger("slime_match")

BASE_NAMES = ("hz+", "rootsift", "keynet")

CandidateFilter = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class BaseConfig:
    """Options of a base pipeline.

    Attributes:
        name: "hz+" (HarrisZ+ + AffNet + OriNet + descriptor + Blob matching + DTM), "rootsift"
            (OpenCV DoG + RootSIFT + FGINN, the paper's handcrafted baseline) or "keynet" (Key.Net + AffNet +
            OriNet + HardNet/TFeat + AdaLAM, kornia's detector, networks and matcher).
        descriptor: Hz+ descriptor: "auto" | "hardnet" | "tfeat" | "rootsift" (Key.Net: "hardnet" | "tfeat").
        shape: Hz+ affine shape: "affnet" | "baumberg" (Key.Net: "affnet").
        orientation: Hz+ orientation: "orinet" | "gradient" | "upright" (Key.Net: "orinet" | "upright").
        upright: no orientation estimation at all (the paper's upright variants); overrides ``orientation``.
        max_keypoints: detector cap.
        magnification: patch magnification over the detector region (None = the pipeline's default: 6 over
            HarrisZ+'s ellipses, 1 over Key.Net's frames, which already span 6 detection scales).
        weights_dir: a folder holding the model weights (else kornia's torch-hub cache, ``TORCH_HOME``).
        fginn_ratio, fginn_radius: FGINN ratio and spatial radius (px) for the RootSIFT pipeline.
        use_dtm: run DTM after Blob matching (Hz+); False only for inspection.
    """

    name: str = "hz+"
    descriptor: str = "auto"
    shape: str = "affnet"
    orientation: str = "orinet"
    upright: bool = False
    max_keypoints: int = 8000
    magnification: float | None = None
    weights_dir: str | None = None
    fginn_ratio: float = 0.8
    fginn_radius: float = 10.0
    use_dtm: bool = True
    blob: BlobConfig = field(default_factory=BlobConfig)
    dtm: DTMConfig = field(default_factory=DTMConfig)


class BasePipeline:
    """Interface of a base pipeline (see the module docstring).

    Attributes:
        slime_global_dtm: whether Slime ends with a global DTM over its matches on this base (the paper:
            yes for Hz+ and RootSIFT; not for Key.Net, where a global AdaLAM is "mostly equivalent to running
            the base Key.Net alone").
        slime_detection: Slime's default block detection on this base (``SlimeConfig.detection``): "merged"
            where the detector runs apart from the patch stages (Hz+), else "scale".
        options: the :class:`BaseConfig` fields this pipeline reads (``make_config`` refuses the others).
    """

    name: str = "base"
    slime_global_dtm: bool = True
    slime_detection: str = "scale"
    options: frozenset[str] = frozenset()

    def prepare(self, image: np.ndarray) -> Any:
        raise NotImplementedError

    def detect(self, context: Any) -> Features:
        raise NotImplementedError

    def detect_regions(self, context: Any) -> Features:
        """Keypoints with their shape frames only (no orientation, (N, 0) descriptors): for regions that
        will only ever be described under fixed orientations (Slime's tiles)."""
        raise NotImplementedError

    def detect_keypoints(self, image: np.ndarray, device: torch.device | None = None) -> Keypoints:
        """The detector alone on an (H, W, 3) float image (Slime's merged per-block detection), on ``device``
        (None: the pipeline's; Slime's forked workers detect on the CPU for a CUDA pipeline); only pipelines
        whose ``slime_detection`` is "merged" have it."""
        raise ConfigError(f"the {self.name} base pipeline has no detector separate from its descriptor: "
                          "Slime's 'merged' detection needs one (use detection 'scale' or 'block')")

    def describe_keypoints(self, context: Any, keypoints: Keypoints, regions_only: bool = False) -> Features:
        """Features of ``keypoints`` (from :meth:`detect_keypoints`, in the context's pixels) on the image of
        ``context``; ``regions_only`` as for :meth:`detect_regions`."""
        raise ConfigError(f"the {self.name} base pipeline cannot describe given keypoints")

    def describe_fixed(self, context: Any, features: Features, angle: float) -> Features:
        raise NotImplementedError

    def describe_batch(self) -> int | None:
        """The number of keypoints whose patches the patch stages process together. Describing a set in
        pieces that start at multiples of it gives the set's features bit for bit (the same network batches,
        and every elementwise op's vector lanes see the same values), so Slime may spread one set over its
        workers. None: a set must be described whole."""
        return None

    def own_frames_upright(self) -> bool:
        """Whether ``describe_fixed`` at angle 0 gives exactly (bit for bit) the frames and descriptors that
        ``detect`` and ``describe_keypoints`` gave the features (an upright pipeline's own orientation)."""
        return False

    def match(self, features0: Features, features1: Features, size0: tuple[int, int],
              size1: tuple[int, int], candidate_filter: CandidateFilter | None = None) -> Matches:
        """Matches of two feature sets of images of (H, W) ``size0`` / ``size1``.

        ``candidate_filter(xy0, xy1) -> (K,) bool`` drops candidates before the pipeline's spatial filter
        (Slime's tile refinement keeps only flows close to its planes' flows).
        """
        raise NotImplementedError

    def extract(self, image: np.ndarray) -> Features:
        """Features of an (H, W, 3) float image."""
        return self.detect(self.prepare(image))

    def load_kernels(self) -> None:
        """Load the compiled loops that this pipeline's calls run on CPU, in this process (none by default).
        Call it before forking workers that run the pipeline, or each of them loads them again."""

    def describe(self) -> dict[str, Any]:
        """Parameters actually used (for the output summary)."""
        return {}


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

    def load_kernels(self) -> None:
        if self.device.type == "cpu":
            load_patch_kernels()
        blob.load_kernels()
        dtm.load_kernels()

    def describe(self) -> dict[str, Any]:
        return {"base": "hz+", "detector": "harrisz+", **dataclasses.asdict(self.harrisz),
                **self.patch.summary(),
                "matcher": "blob+dtm" if self.config.use_dtm else "blob"}


def _unmatched(xy: np.ndarray, used: np.ndarray) -> np.ndarray:
    mask = np.ones(len(xy), bool)
    mask[used] = False
    return xy[mask]


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

    def load_kernels(self) -> None:
        blob.load_kernels()  # FGINN runs the nearest-neighbour loops of Blob matching

    def describe(self) -> dict[str, Any]:
        return {"base": "rootsift", "detector": "opencv-dog", "descriptor": "rootsift", "matcher": "fginn",
                "upright": self.config.upright, "fginn_ratio": self.config.fginn_ratio,
                "fginn_radius": self.config.fginn_radius}


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

        from .features.weights import load_model

        if config.descriptor not in ("hardnet", "tfeat"):
            raise ConfigError(f"the keynet base pipeline describes with hardnet or tfeat, not {config.descriptor!r}")
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

    def load_kernels(self) -> None:
        if self.device.type == "cpu":
            load_patch_kernels()

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


def _filtered(matches: Matches, features0: Features, features1: Features,
              candidate_filter: CandidateFilter | None) -> Matches:
    """The matches that ``candidate_filter(xy0, xy1)`` keeps (all of them without a filter)."""
    if candidate_filter is None or not len(matches):
        return matches
    xy0 = features0.xy.detach().cpu().numpy().astype(np.float64)[matches.idx0]
    xy1 = features1.xy.detach().cpu().numpy().astype(np.float64)[matches.idx1]
    return matches.subset(candidate_filter(xy0, xy1))


def _upright_unique(keypoints) -> list:
    """Drop OpenCV's extra orientations of one DoG point and set every angle to 0."""
    seen, out = set(), []
    for k in keypoints:
        key = (round(k.pt[0], 3), round(k.pt[1], 3), round(k.size, 3))
        if key not in seen:
            seen.add(key)
            out.append(cv2.KeyPoint(k.pt[0], k.pt[1], k.size, 0.0, k.response, k.octave, k.class_id))
    return out


def _empty_features(dim: int, device: torch.device) -> Features:
    zeros = lambda *shape: torch.zeros(shape, device=device)
    return Features(zeros(0, 2, 3), zeros(0, dim), zeros(0), zeros(0, 2, 3))


PIPELINES: dict[str, type[BasePipeline]] = {"hz+": HzPlusPipeline, "rootsift": RootSiftPipeline,
                                            "keynet": KeyNetPipeline}


def make_base_pipeline(config: BaseConfig, device: torch.device | str = "cpu") -> BasePipeline:
    """Build the base pipeline named by ``config.name``."""
    if config.name not in PIPELINES:
        raise ConfigError(f"unknown base pipeline {config.name!r}: choose one of {', '.join(BASE_NAMES)}")
    return PIPELINES[config.name](config, torch.device(device))


__all__ = ["PIPELINES", "BaseConfig", "BasePipeline", "HzPlusPipeline", "KeyNetPipeline", "RootSiftPipeline",
           "make_base_pipeline"]
