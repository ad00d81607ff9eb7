"""Coverage: dilated area of the correct keypoints over the valid area (planar: GT overlap, non-planar:
union of all methods' correct keypoints and the GT correspondences), minimum of the two images."""

from __future__ import annotations

import cv2
import numpy as np

from slime_match.eval.metrics.config import DEFAULTS
from slime_match.eval.metrics.correctness import pixel_index
from slime_match.geometry.homography import project


def dilated_mask(points: np.ndarray, shape: tuple[int, int], t: float = DEFAULTS.t_perp) -> np.ndarray:
    """(H, W) bool: pixels within distance ``t`` of the nearest pixel of any (N, 2) point (disk dilation);
    points outside the image are ignored."""
    points = np.asarray(points, np.float64).reshape(-1, 2)
    seeds = np.full(shape, 255, np.uint8)
    row, col, inside = pixel_index(points, shape)
    if not inside.any():
        return np.zeros(shape, bool)
    seeds[row[inside], col[inside]] = 0
    return cv2.distanceTransform(seeds, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) <= t


def coverage(
    x0_correct: np.ndarray,
    x1_correct: np.ndarray,
    shape0: tuple[int, int],
    shape1: tuple[int, int],
    valid0: np.ndarray | None = None,
    valid1: np.ndarray | None = None,
    t: float = DEFAULTS.t_perp,
) -> float:
    """Paper coverage: per image, area of the correct keypoints dilated by a disk of radius ``t`` and
    restricted to the valid area, over the valid area; the minimum of the two images.

    Args:
        x0_correct, x1_correct: (N, 2) keypoints of the correct matches in image 0 / 1, px.
        shape0, shape1: (H, W) image shapes.
        valid0, valid1: (H, W) bool valid areas (None: whole image).
        t: disk radius in px.

    Returns:
        coverage in [0, 1] (0 when a valid area is empty).
    """
    ratios = []
    for pts, shape, valid in ((x0_correct, shape0, valid0), (x1_correct, shape1, valid1)):
        shape = tuple(shape[:2])
        valid = np.ones(shape, bool) if valid is None else valid
        area = valid.sum()
        ratios.append(0.0 if area == 0 else float((dilated_mask(pts, shape, t) & valid).sum() / area))
    return min(ratios)


def valid_area_homography(
    H_gt: np.ndarray,
    shape0: tuple[int, int],
    shape1: tuple[int, int],
    mask0: np.ndarray | None = None,
    mask1: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Valid pixels of a planar pair: those whose GT reprojection lands inside the other image, on the
    visible side of the plane (third homogeneous coordinate with the sign it has at the image centre),
    outside both exclusion masks.

    Returns:
        (H0, W0) and (H1, W1) bool masks.
    """
    H = np.asarray(H_gt, np.float64)
    out = []
    for Hm, sa, sb, ma, mb in (
        (H, shape0, shape1, mask0, mask1),
        (np.linalg.inv(H), shape1, shape0, mask1, mask0),
    ):
        h, w = sa[:2]
        ys, xs = np.mgrid[0:h, 0:w]
        pts = np.stack([xs.ravel(), ys.ravel()], 1).astype(np.float64)
        y, wz = project(Hm, pts)
        _, wc = project(Hm, np.array([[(w - 1) / 2, (h - 1) / 2]]))
        row, col, inside = pixel_index(np.where(np.isfinite(y), y, -1.0), sb[:2])
        ok = inside & (np.sign(wz) == np.sign(wc[0]))
        if mb is not None:
            ok &= ~mb[row, col]
        ok = ok.reshape(h, w)
        out.append(ok if ma is None else ok & ~ma)
    return out[0], out[1]


def valid_area_nonplanar(
    correct0: list[np.ndarray],
    correct1: list[np.ndarray],
    shape0: tuple[int, int],
    shape1: tuple[int, int],
    gt_corrs: np.ndarray | None = None,
    t: float = DEFAULTS.t_perp,
) -> tuple[np.ndarray, np.ndarray]:
    """Coverage normaliser of a non-planar pair: dilated union of the correct keypoints of all evaluated
    methods plus the GT correspondences (SM "Coverage").

    Args:
        correct0, correct1: per method, (N_m, 2) keypoints of its correct matches in image 0 / 1.
        shape0, shape1: (H, W) image shapes.
        gt_corrs: optional (M, 4) GT correspondences ``x0 y0 x1 y1``.
        t: disk radius in px.

    Returns:
        (H0, W0) and (H1, W1) bool valid masks.
    """
    g = np.zeros((0, 4)) if gt_corrs is None else np.asarray(gt_corrs, np.float64).reshape(-1, 4)
    p0 = np.concatenate([np.asarray(p, np.float64).reshape(-1, 2) for p in correct0] + [g[:, :2]])
    p1 = np.concatenate([np.asarray(p, np.float64).reshape(-1, 2) for p in correct1] + [g[:, 2:]])
    return dilated_mask(p0, tuple(shape0[:2]), t), dilated_mask(p1, tuple(shape1[:2]), t)
