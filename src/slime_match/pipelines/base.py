"""The base pipeline interface: what every pipeline implements, and the hooks Slime calls, with defaults.

A base pipeline turns an image into :class:`~slime_match.types.Features` and two feature sets into
:class:`~slime_match.types.Matches`. A new pipeline subclasses :class:`BasePipeline` and implements:

* ``extract(image)`` -> features of an (H, W, 3) float RGB image (values in [0, 1], up to the slight
  overshoot of Slime's Lanczos scaling); or instead ``prepare(image)`` -> an image context (tensor, patch
  pyramid...) and ``detect(context)`` -> features, which Slime calls apart so that each block's context is
  built once;
* ``match(f0, f1, size0, size1, candidate_filter)`` -> candidate matches after the pipeline's own filter
  (DTM / FGINN / AdaLAM...).

Slime also calls these hooks; each has a default built on the part above where one can be:

* ``prepare(image)``: the image itself; ``detect(context)``: ``extract`` of that image;
* ``detect_regions(context)``: ``detect(context)``, for regions only ever described under fixed orientations;
* ``describe_fixed(context, features, angle)``: the same regions re-described under one fixed orientation
  (Slime's orientation-refined re-run, Sec. 3.3 of the paper, and its tile refinement). No default: Slime
  needs it, and ``make_config`` refuses Slime on a base pipeline without it;
* ``detect_keypoints(image)`` and ``describe_keypoints(context, keypoints)``: the detector and the
  description apart, for Slime's "merged" detection (``slime_detection = "merged"`` requires them);
* ``describe_batch()``: None (a feature set is described whole); ``own_frames_upright()``: False;
  ``upright_by_design()``: False;
  ``kernel_groups()``: no compiled loops to load before forking; ``describe()``: no parameters to report.

:func:`unimplemented` lists what a class still lacks; ``register_pipeline`` refuses such a class.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from .._runtime.compiled import warm_up
from .._runtime.options import check_choice, check_integer
from ..choices import ALIKED_MODELS, DESCRIPTOR_CHOICES, ORIENTATION_CHOICES, SHAPE_METHODS
from ..errors import ConfigError
from ..matching.blob import BlobConfig
from ..matching.dtm import DTMConfig
from ..types import Features, Keypoints, Matches

CandidateFilter = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class BaseConfig:
    """Options of a base pipeline.

    Attributes:
        name: the registered name of the pipeline: "hz+" (HarrisZ+ + AffNet + OriNet + descriptor + Blob
            matching + DTM), "rootsift" (OpenCV DoG + RootSIFT + FGINN, the paper's handcrafted baseline),
            "keynet" (Key.Net + AffNet + OriNet + HardNet/TFeat + AdaLAM, kornia's detector, networks and
            matcher), a learned one ("aliked-lg", "aliked-nn", "disk-lg", "disk-nn", "xfeat-lg", "xfeat-nn":
            kornia's ALIKED, DISK or XFeat with LightGlue or mutual nearest neighbours), or one added with
            ``register_pipeline``.
        descriptor: Hz+ descriptor: "auto" | "hardnet" | "hardtfeat" | "tfeat" | "rootsift" (Key.Net: a
            learned one); "auto" takes the best available (HardNet, HardTFeat, TFeat, then RootSIFT).
        shape: Hz+ affine shape: "affnet" | "baumberg" (Key.Net: "affnet").
        orientation: Hz+ orientation: "orinet" | "gradient" | "upright" (Key.Net: "orinet" | "upright").
        upright: no orientation estimation at all (the paper's upright variants); overrides ``orientation``.
        max_keypoints: detector cap.
        magnification: patch magnification over the detector region (None = the pipeline's default: 6 over
            HarrisZ+'s ellipses, 1 over Key.Net's frames, which already span 6 detection scales).
        weights_dir: a folder holding the model weights (else kornia's torch-hub cache, ``TORCH_HOME``).
        fginn_ratio, fginn_radius: FGINN ratio and spatial radius (px) for the RootSIFT pipeline.
        aliked_model: the ALIKED weights of the aliked-* pipelines: "n16" | "n16rot" (trained for rotations) |
            "n32".
        aliked_threshold: ALIKED's detection threshold on its score map: the score maxima above it, at most
            ``max_keypoints`` (0: the ``max_keypoints`` strongest maxima, however weak).
        nn_ratio: Lowe's ratio of the mutual nearest-neighbour matcher of the *-nn learned pipelines (1: mutual
            nearest neighbours alone).
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
    aliked_model: str = "n16"
    aliked_threshold: float = 0.2
    nn_ratio: float = 0.9
    use_dtm: bool = True
    blob: BlobConfig = field(default_factory=BlobConfig)
    dtm: DTMConfig = field(default_factory=DTMConfig)

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> BaseConfig:
        """Check the choices (ConfigError naming the valid ones); the name is checked against the registry
        by ``MatchConfig``."""
        check_choice("descriptor", self.descriptor, DESCRIPTOR_CHOICES)
        check_choice("shape", self.shape, SHAPE_METHODS)
        check_choice("orientation", self.orientation, ORIENTATION_CHOICES)
        check_integer("max_keypoints", self.max_keypoints, 1)
        check_choice("aliked_model", self.aliked_model, ALIKED_MODELS)
        if not (isinstance(self.aliked_threshold, numbers.Real) and not isinstance(self.aliked_threshold, bool)
                and 0 <= self.aliked_threshold < 1):
            raise ConfigError(f"aliked_threshold must be in [0, 1), got {self.aliked_threshold!r}")
        if not (isinstance(self.nn_ratio, numbers.Real) and not isinstance(self.nn_ratio, bool)
                and 0 < self.nn_ratio <= 1):
            raise ConfigError(f"nn_ratio must be in (0, 1], got {self.nn_ratio!r}")
        return self


class BasePipeline:
    """A base pipeline (see the module docstring for what a subclass implements).

    Attributes:
        name: the pipeline's name in messages and summaries (the built-in ones: their registered name).
        slime_global_dtm: whether Slime ends with a global DTM over its matches on this base (the paper:
            yes for Hz+ and RootSIFT; not for Key.Net, where a global AdaLAM is "mostly equivalent to running
            the base Key.Net alone"). The DTM reads ``config.dtm``.
        slime_detection: Slime's default block detection on this base (``SlimeConfig.detection``): "merged"
            where the detector runs apart from the patch stages (Hz+), else "scale".
        slime_block_matching: how Slime finds a block pair's first matches on this base by default
            (``SlimeConfig.block_matching``): "pairs" (each block pair, the paper's) or "levels" (each pair of
            block scales' whole images, for a matcher that reads the whole image).
        slime_view_gain: the fraction of ``ViewConfig.min_support`` that simulated views must add to the plain
            F^theta (the planes Slime's epipolar vote keeps) on this base to be kept though F^theta stays under
            ``min_support`` (:mod:`slime_match.slime.view_step`): it scales with how densely the base matches
            the same planes.
        options: the :class:`BaseConfig` fields this pipeline reads (``make_config`` refuses the others).
    """

    name: str = "base"
    slime_global_dtm: bool = True
    slime_detection: str = "scale"
    slime_block_matching: str = "pairs"
    slime_view_gain: float = 1.0
    options: frozenset[str] = frozenset()

    def __init__(self, config: BaseConfig, device: torch.device) -> None:
        """A pipeline with ``config`` that puts its features on ``device`` (``make_base_pipeline`` builds it)."""
        self.config = config
        self.device = device

    # The required part.

    def extract(self, image: np.ndarray) -> Features:
        """Features of an (H, W, 3) float RGB image: by default ``detect(prepare(image))``."""
        return self.detect(self.prepare(image))

    def match(self, features0: Features, features1: Features, size0: tuple[int, int],
              size1: tuple[int, int], candidate_filter: CandidateFilter | None = None) -> Matches:
        """Matches of two feature sets of images of (H, W) ``size0`` / ``size1``.

        ``candidate_filter(xy0, xy1) -> (K,) bool`` drops candidates before the pipeline's spatial filter
        (Slime's tile refinement keeps only flows close to its planes' flows).
        """
        raise NotImplementedError(f"the {self.name} base pipeline does not implement match(features0, "
                                  "features1, size0, size1, candidate_filter=None)")

    # Slime's hooks.

    def prepare(self, image: np.ndarray) -> Any:
        """The context of an (H, W, 3) float image that the other calls read (by default the image itself)."""
        return image

    def detect(self, context: Any) -> Features:
        """Features of the image of ``context``, with their own orientation (or upright when configured so);
        by default ``extract`` of the image that the default ``prepare`` keeps as the context."""
        if type(self).extract is BasePipeline.extract:
            raise NotImplementedError(f"the {self.name} base pipeline implements neither extract(image) nor "
                                      "prepare(image) and detect(context)")
        return self.extract(context)

    def detect_regions(self, context: Any) -> Features:
        """Keypoints with their shape frames, for regions that will only ever be described under fixed
        orientations (Slime's tiles). A pipeline may leave out the orientation and the descriptors ((N, 0));
        by default ``detect(context)``."""
        return self.detect(context)

    def describe_fixed(self, context: Any, features: Features, angle: float) -> Features:
        """``features`` (from ``detect`` or ``detect_regions`` on ``context``) described under the fixed
        orientation ``angle`` (radians) instead of their own."""
        raise NotImplementedError(f"the {self.name} base pipeline does not implement describe_fixed(context, "
                                  "features, angle): Slime re-describes regions under fixed orientations")

    def detect_keypoints(self, image: np.ndarray, device: torch.device | None = None) -> Keypoints:
        """The detector alone on an (H, W, 3) float image (Slime's merged per-block detection), on ``device``
        (None: the pipeline's; Slime's forked workers detect on the CPU for a CUDA pipeline); only pipelines
        whose ``slime_detection`` is "merged" have it."""
        raise ConfigError(f"the {self.name} base pipeline has no detector separate from its descriptor "
                          "(detect_keypoints and describe_keypoints): Slime's 'merged' detection needs one "
                          "(use detection 'scale' or 'block')")

    def describe_keypoints(self, context: Any, keypoints: Keypoints, regions_only: bool = False) -> Features:
        """Features of ``keypoints`` (from :meth:`detect_keypoints`, in the context's pixels) on the image of
        ``context``; ``regions_only`` as for :meth:`detect_regions`."""
        raise ConfigError(f"the {self.name} base pipeline cannot describe given keypoints (no describe_keypoints):"
                          " Slime's 'merged' detection needs it (use detection 'scale' or 'block')")

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

    def upright_by_design(self) -> bool:
        """Whether the features are upright whatever the image (no orientation of their own, a network not trained
        for rotations), so that Slime first checks how image 1 is turned (:mod:`slime_match.quarter_turns`)."""
        return False

    def kernel_groups(self) -> tuple[str, ...]:
        """The groups of compiled loops (``_runtime.compiled.GROUPS``) this pipeline's calls run on the CPU
        (none by default)."""
        return ()

    def load_kernels(self) -> None:
        """Load the compiled loops of ``kernel_groups`` in this process. Call it before forking workers that
        run the pipeline, or each of them loads them again."""
        groups = self.kernel_groups()
        if groups:
            warm_up(*groups)

    def describe(self) -> dict[str, Any]:
        """Parameters actually used (for the output summary)."""
        return {}


def unimplemented(cls: type[BasePipeline], slime: bool = False) -> list[str]:
    """The methods that the pipeline class ``cls`` must still implement ([] when none): ``match``, ``extract``
    (or ``prepare`` and ``detect``), the merged-detection pair where ``slime_detection`` is "merged", and with
    ``slime``, what Slime needs beyond the defaults (``describe_fixed``)."""

    def own(name: str) -> bool:
        return getattr(cls, name) is not getattr(BasePipeline, name)

    missing = [] if own("match") else ["match(features0, features1, size0, size1, candidate_filter=None)"]
    if not (own("extract") or own("detect")):
        missing.append("extract(image) (or prepare(image) and detect(context))")
    elif own("prepare") and not own("detect"):
        missing.append("detect(context), which reads what its prepare(image) returns")
    if cls.slime_detection == "merged":
        missing += [signature for signature in ("detect_keypoints(image, device=None)",
                                                "describe_keypoints(context, keypoints, regions_only=False)")
                    if not own(signature.partition("(")[0])]
    if slime and not own("describe_fixed"):
        missing.append("describe_fixed(context, features, angle)")
    return missing


def _filtered(matches: Matches, features0: Features, features1: Features,
              candidate_filter: CandidateFilter | None) -> Matches:
    """The matches that ``candidate_filter(xy0, xy1)`` keeps (all of them without a filter)."""
    if candidate_filter is None or not len(matches):
        return matches
    xy0 = features0.xy.detach().cpu().numpy().astype(np.float64)[matches.idx0]
    xy1 = features1.xy.detach().cpu().numpy().astype(np.float64)[matches.idx1]
    return matches.subset(candidate_filter(xy0, xy1))


def _empty_features(dim: int, device: torch.device) -> Features:
    zeros = lambda *shape: torch.zeros(shape, device=device)
    return Features(zeros(0, 2, 3), zeros(0, dim), zeros(0), zeros(0, 2, 3))
