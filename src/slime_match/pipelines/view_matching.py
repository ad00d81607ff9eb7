"""A base pipeline alone with simulated views (ASIFT tilts, :mod:`slime_match.views`).

Each view of an image is detected, described and matched against the other image's features (computed once);
its matches are mapped back to the viewed image through the view's affine map and pooled with the plain
matches. "auto" adds the views of one (image, tilt) after another only while the pooled matches have fewer
than ``min_inliers`` consistent with one fundamental matrix (OpenCV MAGSAC++, 3 px).
"""

from __future__ import annotations

import logging

import numpy as np

from ..geometry.backends import estimate_geometry
from ..types import Features
from ..views import ViewConfig, ViewRecord, ViewTry, simulate_view, views_of_tilt
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


def match_views(pipeline: BasePipeline, image0: np.ndarray, image1: np.ndarray, features0: Features,
                features1: Features, xy0: np.ndarray, xy1: np.ndarray, scores: np.ndarray, config: ViewConfig,
                seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, ViewRecord]:
    """The plain matches (``xy0``, ``xy1``, ``scores``) of two (H, W, 3) images, whose features are
    ``features0`` and ``features1``, with those of the views that ``config`` asks for.

    Returns:
        (K, 2), (K, 2) matches in image px and their (K,) scores, sorted by score (lower is better), and what
        was tried.
    """
    record = ViewRecord(config.mode, config.images)
    if config.mode == "off":
        return xy0, xy1, scores, record
    parts = [(xy0, xy1, scores)]
    images, features = (image0, image1), (features0, features1)
    keypoints = [f.xy.detach().cpu().numpy().astype(np.float64) for f in features]  # once for every view

    def support() -> tuple[bool, str]:
        """Whether the pooled matches need no more views, and their count in words."""
        count = consistent_matches(*(np.concatenate([p[k] for p in parts]) for k in (0, 1)), seed)
        enough = count >= config.min_inliers
        return enough, (f"{'enough' if enough else 'too few'} matches consistent with one epipolar geometry "
                        f"(a fundamental matrix F): {count} {'>=' if enough else '<'} {config.min_inliers}")

    for image, tilt in config.schedule():
        if config.mode == "auto":
            enough, record.reason = support()
            if enough:
                record.decision = "kept" if record.tried else "not needed"
                break
        other = 1 - image
        angles = views_of_tilt(tilt)
        for angle in angles:
            view_image, view = simulate_view(images[image], tilt, angle)
            found = pipeline.extract(view_image)
            if image == 0:
                matches = pipeline.match(found, features1, view_image.shape[:2], image1.shape[:2])
            else:
                matches = pipeline.match(features0, found, image0.shape[:2], view_image.shape[:2])
            idx = (matches.idx0, matches.idx1) if image == 0 else (matches.idx1, matches.idx0)  # viewed, other
            viewed = view.frame.to_original(found.xy.detach().cpu().numpy().astype(np.float64)[idx[0]])
            inside = view.inside(viewed)
            mine, theirs = viewed[inside], keypoints[other][idx[1]][inside]
            parts.append((*((mine, theirs) if image == 0 else (theirs, mine)), np.asarray(matches.scores)[inside]))
        record.tried.append(ViewTry(image, tilt, len(angles)))
        logger.info("Views of image %d at tilt %g: %d matches in all", image, tilt, sum(len(p[0]) for p in parts))
    else:
        record.decision, record.reason = "kept", "every view tried"
        if config.mode == "auto":
            enough, reason = support()
            record.reason = reason if enough else f"every view tried, and still {reason}"
    xy0, xy1, scores = (np.concatenate([p[k] for p in parts]) for k in range(3))
    order = np.argsort(scores, kind="stable")
    return xy0[order], xy1[order], scores[order], record
