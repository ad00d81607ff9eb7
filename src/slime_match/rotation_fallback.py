"""Slime on Hz+ where Slime on a base upright by design is out of its reach: a roll between the images, or a
scene foreshortened beyond what the base follows.

ALIKED (n16, n32), DISK and XFeat describe every keypoint upright, on a patch of fixed shape. Two kinds of pair
leave such a base without the scene's geometry, and Slime on :data:`FALLBACK_BASE` (its own default options,
``descriptor`` "auto", on the same working images) is run as well:

- **no match** (trigger ``"no match"``): the quarter-turn check (:mod:`slime_match.quarter_turns`) turns image 1
  back by a multiple of 90 degrees, but a roll between the images in between (a hand-held camera tilted
  sideways, 30-70 degrees) leaves the base no consistent matches at all: no plane passes the epipolar vote and
  Slime returns nothing. Hz+ estimates each keypoint's orientation, so the same pair gives it matches to read
  planes from. Slime on Hz+ runs in full, views included.
- **no tilt** (trigger ``"no tilt"``, with ``rotation_fallback="edge-on"`` only): the base's views were kept
  (``views.mode`` "auto") but its plain F^theta shows no tilt (:class:`~slime_match.slime.view_step.PlainTilt`:
  not ``TILT_MATCHES`` matches on one affine map from ``TILT_PLANES`` planes): it saw no geometry of the scene
  before its views. On a plane seen nearly edge-on that is the base's limit, not the scene's: Hz+'s
  affine-shaped patches (AffNet or Baumberg) follow the foreshortening and the residual tilt a view leaves,
  where an upright, isotropic base's views keep chance matches or one band of the plane (where the base's views
  were dropped, what limits it is appearance or overlap, which Hz+'s views do not lift either). Slime on Hz+ runs
  first without views and tiles (its plain stage) and continues in full, its features reused, only where its
  own plain F^theta measures a tilt. That plain stage costs a 1000 x 750 pair about 10 s, more than half an
  easy pair's time, on every pair the trigger reaches, so it is not part of "auto": a real pair whose views the
  base keeps rightly (EVD girl) pays it for nothing.

The second run's matches are returned when its F^theta holds ``views.min_support`` matches (the consistent
geometry by which Slime needs no views; below that they are mostly wrong: two ScanNet images of different scenes
reach 15 and 21) and, counted at the base's density, more than the first run's F^theta: the first base's
``slime_view_gain`` times the second's count, since a learned base matches the same planes about three times
more sparsely. Otherwise the first run's result stands. ``summary.json``'s ``decisions["rotation_fallback"]``
records the trigger, the decision and the other run's counts, decisions and warnings; a warning gives the
decision when the second run's matches are returned or the result stays empty. ``rotation_fallback="off"``
never runs the second base.
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
from .slime.view_step import TILT_MATCHES, TILT_PLANES
from .views import ViewConfig

logger = logging.getLogger("slime_match")

FALLBACK_BASE = "hz+"  # orientation estimated per keypoint (OriNet), descriptor "auto"


class RotationFallback:
    """The fallback base of a matcher (Hz+: orientations estimated, patches shape-adapted), built on first use
    (its weights load only when a pair needs it) with a features cache of its own."""

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

    @staticmethod
    def trigger(first: SlimeOutput, mode: str = "auto") -> str | None:
        """Why Slime on :data:`FALLBACK_BASE` runs after ``first`` under ``rotation_fallback`` ``mode`` (the
        module's triggers: "no match"; "no tilt" under "edge-on" only), or None."""
        if mode == "off":
            return None
        if not len(first.xy0):
            return "no match"
        views = first.decisions.get("views", {})
        measured = first.plain_tilt is not None and first.plain_tilt.measured
        if mode == "edge-on" and views.get("mode") == "auto" and views.get("decision") == "kept" and not measured:
            return "no tilt"
        return None

    def run(self, first: SlimeOutput, trigger: str, first_base: str, gain: float, image0: np.ndarray,
            image1: np.ndarray, config: SlimeConfig, seed: int, views: ViewConfig
            ) -> tuple[SlimeOutput, dict[str, Any]]:
        """Slime on :data:`FALLBACK_BASE` for the (H, W, 3) float working images that Slime on ``first_base``
        matched into ``first``, with ``config`` less the first base's own choices (its pooled base, detection and
        block matching); on ``trigger`` "no tilt" its plain stage first, the rest only where that measures a
        tilt. ``gain``: the first base's ``slime_view_gain`` (its density of matches on a plane against Hz+'s).

        Returns:
            (the output taken, with a warning that gives the decision where the second run's matches are
            returned or the result stays empty; the record for ``decisions["rotation_fallback"]``: the trigger,
            the bases, whether the second run was kept and why, and the other run's counts, decisions and
            warnings).
        """
        pipeline = self._pipeline()
        own = dataclasses.replace(config, pool=None, detection=None, block_matching=None)
        first_support = first.counts["ftheta_matches"] if len(first.xy0) else 0
        if trigger == "no match":
            logger.warning("Slime on %s found no match: running Slime on %s (orientation estimated)", first_base,
                           FALLBACK_BASE)
            reason = (f"Slime on {first_base} (upright by design) found no match; Slime on {FALLBACK_BASE}, which "
                      "estimates each keypoint's orientation, ")
        else:
            logger.info("Slime on %s saw no geometry of the scene before its views: running Slime on %s "
                        "(affine-shaped patches)", first_base, FALLBACK_BASE)
            reason = (f"Slime on {first_base} kept views while its plain F^theta shows no tilt (not "
                      f"{TILT_MATCHES} matches on one affine map from {TILT_PLANES} planes); Slime on "
                      f"{FALLBACK_BASE}, whose affine-shaped patches follow a foreshortened plane, ")
            look = run_slime(pipeline, image0, image1, dataclasses.replace(own, refine_tiles=False, keep_stages=False),
                             StageTimer(), seed=seed, level_cache=self.level_cache, views=ViewConfig(mode="off"))
            if look.plain_tilt is None or not look.plain_tilt.measured:
                reason += f"shows none in its plain F^theta either: the first run's {len(first.xy0)} matches stand"
                return first, self._record(trigger, first_base, False, reason, pipeline, look, FALLBACK_BASE)
            reason += f"measures a tilt of {look.plain_tilt.tilt:.1f} in its plain F^theta and, with its views, "
        second = run_slime(pipeline, image0, image1, own, StageTimer(), seed=seed, level_cache=self.level_cache,
                           views=views)
        second.warnings[:0] = self.warnings
        support = second.counts["ftheta_matches"]
        kept = support >= views.min_support and gain * support > first_support
        reason += f"holds {support} matches in F^theta "
        if support < views.min_support:
            reason += f"(< views.min_support {views.min_support}, too little consistent geometry)"
        else:
            density = (f"{gain:g} x {support} = {gain * support:.0f} at {first_base}'s density "
                       f"{'>' if kept else '<='} its {first_support}")
            reason += f"(>= views.min_support {views.min_support}{'; ' + density if first_support else ''})"
        if kept:
            reason += f": its {len(second.xy0)} matches are returned"
            taken, other, other_base = second, first, first_base
            taken.warnings.insert(len(self.warnings), reason)
        else:
            reason += ": no match" if not len(first.xy0) else f": the first run's {len(first.xy0)} matches stand"
            taken, other, other_base = first, second, FALLBACK_BASE
            if not len(first.xy0):
                taken.warnings.append(reason)
        logger.info("Rotation fallback: %s", reason)
        return taken, self._record(trigger, first_base, kept, reason, pipeline, other, other_base)

    @staticmethod
    def _record(trigger: str, first_base: str, kept: bool, reason: str, pipeline: BasePipeline, other: SlimeOutput,
                other_base: str) -> dict[str, Any]:
        """``decisions["rotation_fallback"]``: the trigger, the bases, the decision and the run not taken."""
        return {"trigger": trigger, "base": FALLBACK_BASE, "first_base": first_base, "kept": kept, "reason": reason,
                "pipeline": pipeline.describe(),
                "other_run": {"base": other_base, "counts": other.counts, "decisions": other.decisions,
                              "warnings": other.warnings}}
