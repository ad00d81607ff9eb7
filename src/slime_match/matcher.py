"""The public matcher: images in, MatchResult out (Slime or a base pipeline, optional RANSAC)."""

from __future__ import annotations

import copy
import dataclasses
import logging
import time
from typing import Any

import numpy as np
import torch

from . import __version__
from ._runtime import compiled
from ._runtime.timing import StageTimer
from .auto_method import passed_over
from .config import MatchConfig, make_config
from .errors import ConfigError, ImageError, caused_by_interrupt
from .geometry.backends import estimate_geometry
from .geometry.frames import Frame
from .io import MIN_IMAGE_SIDE, ImageLike, load_image
from .pipelines import BaseConfig, make_base_pipeline, resolve_auto_descriptor
from .pipelines.view_matching import match_views
from .quarter_turns import check_quarter_turns, turned_frame
from .resize import pair_factors, resize_image
from .result import MatchResult
from .rotation_fallback import RotationFallback
from .slime.level_cache import LevelCache
from .slime.pipeline import run_slime, stages_to_original
from .slime.pooled_base import PooledBase

logger = logging.getLogger("slime_match")

FEATURE_CACHE_MB = 512  # default memory for the features of recent images (about 10-25 images of 0.3-0.7 MP)


def resolve_device(name: str) -> torch.device:
    """"auto" -> CUDA when available else CPU; "cuda" without a GPU is an error."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise ConfigError("device 'cuda' requested but no CUDA GPU is available: use --device cpu")
    return torch.device(name)


class Matcher:
    """A configured matcher; models are loaded once and reused for every pair.

    Example:
        >>> matcher = Matcher(make_config("slime", descriptor="tfeat"))
        >>> result = matcher("a.jpg", "b.jpg")
    """

    def __init__(self, config: MatchConfig | None = None, feature_cache_mb: float = FEATURE_CACHE_MB) -> None:
        """Args:
            config: the configuration (``make_config()``'s default when None); a copy is kept.
            feature_cache_mb: memory (MiB) for Slime's block and tile features of the images matched last,
                reused when a later pair shares an image (the matches are the same); 0 turns it off. A pooled
                second base (``slime.pool``) gets as much again for its block features, and so does the
                rotation fallback's base (:mod:`slime_match.rotation_fallback`) once a pair needs it.
        """
        if not feature_cache_mb >= 0:  # NaN too
            raise ConfigError(f"feature_cache_mb must be >= 0 MiB, got {feature_cache_mb}")
        compiled.install_notice()  # a notice when a first run compiles the loops
        self.config = copy.deepcopy(config or make_config()).validate()  # the caller's config is left as it is
        self.level_cache = _level_cache(feature_cache_mb)
        self.device = resolve_device(self.config.device)
        self.warnings: list[str] = []
        if passed_over(self.config.auto_choice):
            logger.warning(self.config.auto_choice)
            self.warnings.append(self.config.auto_choice)
        elif self.config.auto_choice:
            logger.info(self.config.auto_choice)
        base = self.config.base
        self._resolve_descriptor(base)
        self.pipeline = make_base_pipeline(base, self.device)
        self.pooled = None  # Slime's second base (``slime.pool``), with the base's options
        if self.config.method == "slime" and self.config.slime.pool is not None:
            pool_base = dataclasses.replace(base, name=self.config.slime.pool)
            self._resolve_descriptor(pool_base)
            self.pooled = PooledBase(make_base_pipeline(pool_base, self.device), _level_cache(feature_cache_mb))
        self.rotation_fallback = None  # Slime on Hz+ where an upright base finds no match (or no tilt: "edge-on")
        if (self.config.method == "slime" and self.config.rotation_fallback != "off"
                and self.pipeline.upright_by_design()):
            self.rotation_fallback = RotationFallback(self.device, base.weights_dir, _level_cache(feature_cache_mb))

    def _resolve_descriptor(self, base: BaseConfig) -> None:
        """Set a descriptor "auto" of a base that reads one to the best available (a warning names what it
        passed over)."""
        if warning := resolve_auto_descriptor(base):
            logger.warning(warning)
            self.warnings.append(warning)

    def __repr__(self) -> str:
        """One line: the method and the choices that most change its results and speed."""
        config, base = self.config, self.config.base
        text = f"Matcher(method={config.method!r}"
        if config.method == "slime":
            text += f", base={base.name!r}, scales={config.slime.blocks.scales}"
            if config.slime.pool is not None:
                text += f", pool={config.slime.pool!r}"
        for key in ("shape", "orientation", "descriptor"):
            if key in self.pipeline.options and not (key == "orientation" and base.upright):
                text += f", {key}={getattr(base, key)!r}"
        if base.upright:
            text += ", upright=True"  # no orientation estimation, whatever ``orientation`` says
        return text + f", device={str(self.device)!r})"

    def __call__(self, image0: ImageLike, image1: ImageLike) -> MatchResult:
        """Match two images (paths, numpy arrays or torch tensors); see :func:`slime_match.match`."""
        try:
            return self._match(image0, image1)
        except Exception as error:
            if caused_by_interrupt(error):  # a Ctrl-C inside compiled code surfaces as a SystemError
                raise KeyboardInterrupt from error
            raise

    def _match(self, image0: ImageLike, image1: ImageLike) -> MatchResult:
        timer = StageTimer()
        start = time.perf_counter()
        compiling = compiled.compile_seconds()
        config = self.config
        with timer("load"):
            original0, original1 = load_image(image0), load_image(image1)
            min_side, max_side = config.side_limits()
            factors = pair_factors(_size(original0), _size(original1), min_side, max_side)
            (array0, frame0), (array1, frame1) = (_working_image(image, factor, max_side)
                                                  for image, factor in zip((original0, original1), factors))
        stages = None
        warnings = list(self.warnings)
        decisions: dict[str, Any] = {}
        working1 = _size(array1)
        if config.method == "slime" and config.quarter_turns == "auto" and self.pipeline.upright_by_design():
            with timer("quarter_turns"):
                turn = check_quarter_turns(self.pipeline, array0, array1, config.seed)
            array1 = np.ascontiguousarray(np.rot90(array1, turn.quarter_turns))
            frame1 = turned_frame(frame1, _size(original1), turn.quarter_turns)
            decisions["quarter_turns"] = turn.as_dict()
        if config.method == "slime":
            output = run_slime(self.pipeline, array0, array1, config.slime, timer, seed=config.seed,
                               level_cache=self.level_cache, views=config.views, pooled=self.pooled)
            fallback = self.rotation_fallback
            if fallback is not None and (trigger := fallback.trigger(output, config.rotation_fallback)):
                with timer("rotation_fallback"):
                    output, decisions["rotation_fallback"] = fallback.run(
                        output, trigger, self.pipeline.name, self.pipeline.slime_view_gain, array0, array1,
                        config.slime, config.seed, config.views)
            xy0, xy1, scores, counts, stages = output.xy0, output.xy1, output.scores, output.counts, output.stages
            warnings += output.warnings
            decisions |= output.decisions
        else:
            xy0, xy1, scores, counts, views = self._run_base(array0, array1, timer)
            decisions = {"views": views.as_dict()}
        if (frame0, frame1) != (Frame(), Frame()):
            xy0, xy1 = frame0.to_original(xy0), frame1.to_original(xy1)
            if stages is not None:
                stages = stages_to_original(stages, frame0, frame1)
        inliers = model = kind = None
        if config.ransac != "none":
            backend, _, kind = config.ransac.rpartition("-")
            with timer("ransac"):
                geometry = estimate_geometry(xy0, xy1, kind, backend=backend or "slime",
                                             threshold=config.threshold, seed=config.seed)
            inliers, model, kind = geometry.inliers, geometry.model, geometry.kind
            counts["inliers"] = int(np.sum(inliers))
        counts["matches"] = len(xy0)
        summary = {
            "slime_match_version": __version__,
            "method": config.method,
            "config": config.to_dict(),
            "pipeline": self.pipeline.describe(),
            "device": str(self.device),
            "image_sizes": {"image0": list(original0.shape[1::-1]), "image1": list(original1.shape[1::-1])},
            "working_sizes": {"image0": list(array0.shape[1::-1]), "image1": list(working1)},
            "working_factors": {"image0": list(frame0.factor), "image1": list(frame1.factor)},
            "side_limits": {"min_side": min_side, "max_side": max_side},
            "counts": counts,
            # numba_compile: seconds of the call spent compiling loops, within the stages or between them (a
            # first run; ``slime warmup`` compiles ahead)
            "seconds": {**timer.as_dict(), "numba_compile": round(compiled.compile_seconds() - compiling, 4),
                        "total": round(time.perf_counter() - start, 4)},
            "warnings": warnings,
        }
        if config.auto_choice:
            decisions = {"method": config.auto_choice, **decisions}
        if decisions:
            summary["decisions"] = decisions
        return MatchResult(xy0, xy1, scores, inliers, kind, model, summary, stages,
                           image_sizes=(_size(original0), _size(original1)),
                           working_sizes=(_size(array0), working1))

    def _run_base(self, array0: np.ndarray, array1: np.ndarray, timer: StageTimer):
        pipeline = self.pipeline
        with timer("features"):
            features0 = pipeline.extract(array0)
            features1 = pipeline.extract(array1)
        with timer("matching"):
            matches = pipeline.match(features0, features1, array0.shape[:2], array1.shape[:2])
        xy0 = features0.xy.detach().cpu().numpy().astype(np.float64)[matches.idx0]
        xy1 = features1.xy.detach().cpu().numpy().astype(np.float64)[matches.idx1]
        with timer("views"):
            xy0, xy1, scores, views = match_views(pipeline, array0, array1, features0, features1, xy0, xy1,
                                                  matches.scores, self.config.views, self.config.seed)
        counts = {"keypoints0": len(features0), "keypoints1": len(features1), "views": views.views}
        return xy0, xy1, scores, counts, views


def _level_cache(megabytes: float) -> LevelCache | None:
    """A features cache of ``megabytes`` MiB, or None for 0."""
    return LevelCache(int(megabytes * 2**20)) if megabytes > 0 else None


def _working_image(image: np.ndarray, factor: float, max_side: int | None) -> tuple[np.ndarray, Frame]:
    """The (H, W, 3) image resized by ``factor`` (:func:`pair_factors`, :func:`resize_image`) and its frame."""
    working, frame = resize_image(image, factor=factor)
    height, width = working.shape[:2]
    if min(height, width) < MIN_IMAGE_SIDE:
        raise ImageError(f"a {image.shape[1]}x{image.shape[0]} px image shrunk to max_side {max_side} would be "
                         f"{width}x{height} px, smaller than {MIN_IMAGE_SIDE} px on a side: raise max_side")
    return working, frame


def _size(image: np.ndarray) -> tuple[int, int]:
    """(W, H) of an (H, W[, C]) image."""
    return int(image.shape[1]), int(image.shape[0])


def match(image0: ImageLike, image1: ImageLike, method: str | MatchConfig = "auto", **options: Any) -> MatchResult:
    """Match two images.

    Args:
        image0, image1: paths, (H, W[, C]) numpy arrays or torch tensors (grey, RGB or RGBA; 8/16-bit or float).
        method: "auto" (default: the best preset whose weights are available, :mod:`slime_match.auto_method`),
            a preset of :data:`slime_match.config.PRESETS`: "slime", "slime-aliked", "slime-upright",
            "slime-rootsift", "slime-fast", "slime-fine", "hz+", "hz+-upright", "rootsift", "rootsift-upright"...
            or a MatchConfig (from :func:`slime_match.config.make_config`), used as it is.
        **options: flat overrides, e.g. ``descriptor="tfeat"``, ``ransac="fundamental"``, ``threshold=3``,
            ``base="rootsift"``, ``device="cuda"``, ``seed=1``, ``max_side=1600``, ``min_side=0`` (see
            :func:`slime_match.config.make_config`).

    Returns:
        MatchResult with (K, 2) keypoints in original-image pixels, (K,) scores and a summary.

    Raises:
        ConfigError: an unknown preset or option, or options given together with a MatchConfig.
    """
    if isinstance(method, MatchConfig):
        if options:
            raise ConfigError(f"options {', '.join(sorted(options))} given with a MatchConfig: set them in "
                              "make_config(preset, ...) instead")
        return Matcher(method)(image0, image1)
    return Matcher(make_config(method, **options))(image0, image1)
