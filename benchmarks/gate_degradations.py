"""A pytest plugin that degrades every match on purpose, to show that the quality gates catch it.

Loaded by ``benchmarks/gates_bite.py`` (``pytest -p gate_degradations``, this folder on ``PYTHONPATH``) with
``SLIME_DEGRADATION`` set to one of :data:`DEGRADATIONS`; each keeps the precision of what it keeps:

* ``thin``: every :class:`slime_match.Matcher` result keeps one match of every three (by index);
* ``half``: every result drops the matches whose image-0 keypoint lies in the left half of image 0;
* ``views-off``: every Matcher runs with ``views.mode = "off"`` (no simulated views).
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

DEGRADATIONS = ("thin", "half", "views-off")


def _keep(result, keep: np.ndarray):
    """``result`` with only the matches of the (K,) mask ``keep``."""
    picked = {name: getattr(result, name)[keep] for name in ("keypoints0", "keypoints1", "scores")}
    if result.inliers is not None:
        picked["inliers"] = result.inliers[keep]
    return dataclasses.replace(result, **picked)


def pytest_configure(config) -> None:
    from slime_match.matcher import Matcher

    degradation = os.environ.get("SLIME_DEGRADATION", "")
    if degradation not in DEGRADATIONS:
        raise SystemExit(f"SLIME_DEGRADATION must be one of {DEGRADATIONS}, got {degradation!r}")
    if degradation == "views-off":
        original_init = Matcher.__init__

        def init_without_views(self, *args, **kwargs):
            original_init(self, *args, **kwargs)
            self.config.views.mode = "off"

        Matcher.__init__ = init_without_views
        return
    original_call = Matcher.__call__

    def degraded_call(self, image0, image1, *args, **kwargs):
        result = original_call(self, image0, image1, *args, **kwargs)
        if degradation == "thin":
            return _keep(result, np.arange(len(result)) % 3 == 0)
        width = result.image_sizes[0][0]  # (W, H) of image 0 in original px
        return _keep(result, result.keypoints0[:, 0] >= width / 2)

    Matcher.__call__ = degraded_call
