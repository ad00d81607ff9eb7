"""The tilt of a set of matches (ours): how many times more their robust global affine map stretches one
direction than the other, the foreshortening of an oblique view where the matches lie.

Two stages read it: the global DTM's frame (:mod:`.dtm_frame`: above a tilt, image 0 is compared in image 1's
frame) and the views' trigger (:mod:`.view_step`: too few consistent matches that show no tilt are not a tilt's
doing, and views would not add any).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["AFFINE_TOLERANCE", "MatchTilt", "match_tilt"]

AFFINE_TOLERANCE = 0.02  # RANSAC inlier distance of the global affine fit, as a fraction of image 1's diagonal


@dataclass(frozen=True)
class MatchTilt:
    """The robust global affine map of (K) matches and its tilt.

    Attributes:
        affine: (2, 3) map image 0 px -> image 1 px; None without a fit (fewer than 3 matches, or none fits).
        inliers: (K,) bool, the matches within ``AFFINE_TOLERANCE`` of it (all False without a fit).
        tilt: the larger over the smaller singular value of its linear part (>= 1; nan without a fit).
    """

    affine: np.ndarray | None
    inliers: np.ndarray
    tilt: float

    @property
    def support(self) -> int:
        """How many matches the map holds."""
        return int(self.inliers.sum())


def match_tilt(xy0: np.ndarray, xy1: np.ndarray, size1: tuple[int, int]) -> MatchTilt:
    """The tilt of the (K, 2), (K, 2) matches between image 0 and an image 1 of (H, W) ``size1``: OpenCV's RANSAC
    affine fit (deterministic) with inliers within ``AFFINE_TOLERANCE`` of image 1's diagonal. A global affine
    map only approximates the scene; it has to measure the stretch, not to align every match."""
    xy0, xy1 = np.asarray(xy0, np.float64).reshape(-1, 2), np.asarray(xy1, np.float64).reshape(-1, 2)
    none = MatchTilt(None, np.zeros(len(xy0), bool), float("nan"))
    if len(xy0) < 3:
        return none
    tolerance = AFFINE_TOLERANCE * float(np.hypot(*size1))
    affine, inliers = cv2.estimateAffine2D(xy0, xy1, method=cv2.RANSAC, ransacReprojThreshold=tolerance,
                                           maxIters=2000, confidence=0.999)
    if affine is None:
        return none
    singular = np.linalg.svd(affine[:, :2], compute_uv=False)
    tilt = float(singular[0] / singular[1]) if singular[1] > 0 else float("inf")
    return MatchTilt(affine, inliers.ravel() > 0, tilt)
