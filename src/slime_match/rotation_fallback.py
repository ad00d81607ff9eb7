"""Slime on a rotation-invariant base where Slime on a base upright by design finds no match.

ALIKED (n16, n32), DISK and XFeat describe every keypoint upright. The quarter-turn check
(:mod:`slime_match.quarter_turns`) turns image 1 back by a multiple of 90 degrees, but a roll between the images
in between (a hand-held camera tilted sideways, 30-70 degrees) leaves such a base with no consistent matches
at all: no plane passes the epipolar vote and Slime returns nothing. Hz+ estimates each keypoint's orientation,
so the same pair gives it matches to read planes from (and its affine-shaped patches follow a plane seen nearly
edge-on, which leaves ALIKED nothing either). When Slime on an upright base ends with no match, the
matcher therefore runs Slime once more on :data:`FALLBACK_BASE` (its own default options, ``descriptor``
"auto") on the same working images, and returns that run's matches when its F^theta holds
``views.min_support`` matches, the consistent geometry by which Slime needs no views; a pair that shares nothing
keeps its empty result, after both runs. ``summary.json``'s ``decisions["rotation_fallback"]`` records the
decision and the other run's counts, decisions and warnings, and a warning gives the decision;
``rotation_fallback="off"`` keeps the first run's empty result without the second run.
"""

from __future__ import annotations

import dataclasses
import logging
from typing import Any

import numpy as np
import torch

from ._runtime.timing import StageTimer
from .pipelines import BaseConfig, BasePipeline, make_base_pipeline, resolve_auto_descriptor
from .slime.level_cache import LevelCache
from .slime.pipeline import SlimeConfig, SlimeOutput, run_slime
from .views import ViewConfig

logger = logging.getLogger("slime_match")

FALLBACK_BASE = "hz+"  # orientation estimated per keypoint (OriNet), descriptor "auto"


class RotationFallback:
    """The rotation-invariant base of a matcher, built on first use (its weights load only when a pair needs
    it) with a features cache of its own."""

    def __init__(self, device: torch.device, weights_dir: str | None, level_cache: LevelCache | None) -> None:
        self.device, self.weights_dir, self.level_cache = device, weights_dir, level_cache
        self.pipeline: BasePipeline | None = None
        self.warnings: list[str] = []  # what building the pipeline chose (the descriptor "auto" took)

    def _pipeline(self) -> BasePipeline:
        if self.pipeline is None:
            base = BaseConfig(name=FALLBACK_BASE, weights_dir=self.weights_dir)
            if warning := resolve_auto_descriptor(base):
                logger.warning(warning)
                self.warnings.append(warning)
            self.pipeline = make_base_pipeline(base, self.device)
        return self.pipeline

    def run(self, first: SlimeOutput, first_base: str, image0: np.ndarray, image1: np.ndarray, config: SlimeConfig,
            seed: int, views: ViewConfig) -> tuple[SlimeOutput, dict[str, Any]]:
        """Slime on :data:`FALLBACK_BASE` for the (H, W, 3) float working images that Slime on ``first_base``
        matched into the empty ``first``, with ``config`` less the first base's own choices (its pooled base,
        detection and block matching). Its matches are taken when its F^theta holds ``views.min_support``
        matches (the consistent geometry by which Slime needs no views); below that they are mostly wrong
        (two ScanNet images of different scenes reach 15 and 21) and the empty result stands.

        Returns:
            (the output taken, with a warning that gives the decision; the record for
            ``decisions["rotation_fallback"]``: the bases, whether the fallback was kept and why, and the other
            run's counts, decisions and warnings).
        """
        pipeline = self._pipeline()
        logger.warning("Slime on %s found no match: running Slime on %s (orientation estimated)", first_base,
                       FALLBACK_BASE)
        own = dataclasses.replace(config, pool=None, detection=None, block_matching=None)
        second = run_slime(pipeline, image0, image1, own, StageTimer(), seed=seed, level_cache=self.level_cache,
                           views=views)
        second.warnings[:0] = self.warnings
        support = second.counts["ftheta_matches"]
        kept = support >= views.min_support
        reason = (f"Slime on {first_base} (upright by design) found no match; Slime on {FALLBACK_BASE}, which "
                  f"estimates each keypoint's orientation, holds {support} matches in F^theta ")
        if kept:
            reason += f"(>= views.min_support {views.min_support}): its {len(second.xy0)} matches are returned"
            taken, other, other_base = second, first, first_base
            taken.warnings.insert(len(self.warnings), reason)
        else:
            reason += f"(< views.min_support {views.min_support}, too little consistent geometry): no match"
            taken, other, other_base = first, second, FALLBACK_BASE
            taken.warnings.append(reason)
        logger.info("Rotation fallback: %s", reason)
        record = {"base": FALLBACK_BASE, "first_base": first_base, "kept": kept, "reason": reason,
                  "pipeline": pipeline.describe(),
                  "other_run": {"base": other_base, "counts": other.counts, "decisions": other.decisions,
                                "warnings": other.warnings}}
        return taken, record
