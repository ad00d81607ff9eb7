"""A base pipeline alone with simulated views of image 0 (ASIFT tilts, :mod:`slime_match.views`).

Each view of image 0 is detected, described and matched against image 1's features (computed once); its
matches are mapped back to image 0 through the view's affine map and pooled with the plain matches. "auto"
adds the views of one tilt after another only while the pooled matches have fewer than ``min_inliers``
consistent with one fundamental matrix (OpenCV MAGSAC++, 3 px).
"""

from __future__ import annotations

import logging

import numpy as np

from ..geometry.backends import estimate_geometry
from ..types import Features
from ..views import ViewConfig, ViewRecord, simulate_view, views_of_tilt
from .base import BasePipeline

__all__ = ["CONSENSUS_THRESHOLD", "consistent_matches", "match_views"]

logger = logging.getLogger("slime_match")

CONSENSUS_THRESHOLD = 3.0  # px: the fundamental matrix threshold of the "auto" criterion


def consistent_matches(xy0: np.ndarray, xy1: np.ndarray, seed: int = 0) -> int:
    """The matches consistent with the best fundamental matrix (OpenCV MAGSAC++, ``CONSENSUS_THRESHOLD``)."""
    if len(xy0) < 8:
        return 0
    return int(np.sum(estimate_geometry(xy0, xy1, "fundamental", backend="magsac", threshold=CONSENSUS_THRESHOLD,
                                        seed=seed).inliers))


def match_views(pipeline: BasePipeline, image0: np.ndarray, image1: np.ndarray, features1: Features,
                xy0: np.ndarray, xy1: np.ndarray, scores: np.ndarray, config: ViewConfig, seed: int = 0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, ViewRecord]:
    """The plain matches (``xy0``, ``xy1``, ``scores``) of two (H, W, 3) images with those of the views of
    image 0 that ``config`` asks for.

    Returns:
        (K, 2), (K, 2) matches in image px and their (K,) scores, sorted by score (lower is better), and what
        was tried.
    """
    record = ViewRecord(config.mode)
    if config.mode == "off":
        return xy0, xy1, scores, record
    parts = [(xy0, xy1, scores)]
    keypoints1 = features1.xy.detach().cpu().numpy().astype(np.float64)  # image 1's, once for every view

    def support() -> tuple[bool, str]:
        """Whether the pooled matches need no more views, and their count in words."""
        count = consistent_matches(*(np.concatenate([p[k] for p in parts]) for k in (0, 1)), seed)
        enough = count >= config.min_inliers
        return enough, (f"{'enough' if enough else 'too few'} matches consistent with one epipolar geometry "
                        f"(a fundamental matrix F): {count} {'>=' if enough else '<'} {config.min_inliers}")

    for tilt in config.tilts:
        if config.mode == "auto":
            enough, record.reason = support()
            if enough:
                break
        for angle in views_of_tilt(tilt):
            view_image, view = simulate_view(image0, tilt, angle)
            features0 = pipeline.extract(view_image)
            matches = pipeline.match(features0, features1, view_image.shape[:2], image1.shape[:2])
            found0 = view.frame.to_original(features0.xy.detach().cpu().numpy().astype(np.float64)[matches.idx0])
            inside = view.inside(found0)
            found1 = keypoints1[matches.idx1]
            parts.append((found0[inside], found1[inside], np.asarray(matches.scores)[inside]))
            record.views += 1
        record.tilts.append(tilt)
        logger.info("Views of tilt %g: %d matches in all", tilt, sum(len(p[0]) for p in parts))
    else:
        record.reason = "every tilt tried"
        if config.mode == "auto":
            enough, reason = support()
            record.reason = reason if enough else f"every tilt tried, and still {reason}"
    xy0, xy1, scores = (np.concatenate([p[k] for p in parts]) for k in range(3))
    order = np.argsort(scores, kind="stable")
    return xy0[order], xy1[order], scores[order], record
