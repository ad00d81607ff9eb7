"""Relative pose, LoFTR protocol: essential-matrix RANSAC in normalised coordinates, angular errors, AUC."""

from __future__ import annotations

import math

import cv2
import numpy as np

from slime_match.eval.metrics.config import DEFAULTS


def _angle_deg(cos: float) -> float:
    return math.degrees(math.acos(float(np.clip(cos, -1.0, 1.0))))


def relative_pose_error(
    R_gt: np.ndarray,
    t_gt: np.ndarray,
    R: np.ndarray | None,
    t: np.ndarray | None,
    ignore_gt_t_thr: float = 0.0,
) -> tuple[float, float]:
    """Rotation and translation angular errors in degrees.

    The rotation error is the angle of ``R^T R_gt``; the translation error is the angle between ``t`` and
    ``t_gt`` up to sign (``min(e, 180 - e)``), and 0 when ``|t_gt| < ignore_gt_t_thr``. (inf, inf) when
    no pose was estimated.
    """
    if R is None or t is None:
        return math.inf, math.inf
    R_gt, R = np.asarray(R_gt, np.float64), np.asarray(R, np.float64)
    t_gt, t = np.asarray(t_gt, np.float64).reshape(3), np.asarray(t, np.float64).reshape(3)
    rot = _angle_deg((np.trace(R.T @ R_gt) - 1.0) / 2.0)
    n_gt, n = np.linalg.norm(t_gt), np.linalg.norm(t)
    if n_gt < ignore_gt_t_thr:
        return rot, 0.0
    if n_gt == 0 or n == 0:
        return rot, math.inf
    e = _angle_deg(t @ t_gt / (n * n_gt))
    return rot, min(e, 180.0 - e)


def _normalise(x: np.ndarray, K: np.ndarray) -> np.ndarray:
    x = np.asarray(x, np.float64).reshape(-1, 2)
    return (np.concatenate([x, np.ones((len(x), 1))], 1) @ np.linalg.inv(K).T)[:, :2]


def estimate_pose_essential(
    x0: np.ndarray,
    x1: np.ndarray,
    K0: np.ndarray,
    K1: np.ndarray,
    threshold: float = 0.5,
    conf: float = 0.99999,
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Relative pose by cv2.findEssentialMat (RANSAC) + cv2.recoverPose, as in the LoFTR protocol.

    Points are normalised by the intrinsics and the pixel ``threshold`` is divided by the mean focal
    length; among the returned essential matrices the one with most cheirality inliers wins.

    Returns:
        (R (3, 3), t (3,) unit vector, inliers (K,) bool of the RANSAC), or None with fewer than 5
        matches or when no essential matrix is found (OpenCV's assertion on a degenerate sample included).
    """
    if len(x0) < 5:
        return None
    p0, p1 = _normalise(x0, K0), _normalise(x1, K1)
    f_mean = np.mean([K0[0, 0], K0[1, 1], K1[0, 0], K1[1, 1]])
    try:
        E, mask = cv2.findEssentialMat(
            p0, p1, np.eye(3), method=cv2.RANSAC, prob=conf, threshold=threshold / f_mean
        )
    except cv2.error:  # OpenCV's five-point solver asserts on some degenerate samples instead of skipping them
        return None
    if E is None:
        return None
    best = None
    for Ei in np.split(E, len(E) // 3):
        n, R, t, _, _ = cv2.recoverPose(Ei, p0, p1, np.eye(3), distanceThresh=1e9, mask=mask.copy())
        if best is None or n > best[0]:
            best = (n, R, t.reshape(3))
    return best[1], best[2], mask.ravel() > 0


def pose_errors_sweep(
    x0: np.ndarray,
    x1: np.ndarray,
    K0: np.ndarray,
    K1: np.ndarray,
    R_gt: np.ndarray,
    t_gt: np.ndarray,
    thresholds: tuple[float, ...] = (0.5, 1.0, 1.5, 2.0, 3.0),
) -> dict[float, float]:
    """Pose error ``max(rot, trans)`` in degrees for each essential-RANSAC pixel threshold.

    The protocol picks one threshold per method over a whole dataset (the best AUC), never per pair.
    """
    out = {}
    for th in thresholds:
        est = estimate_pose_essential(x0, x1, K0, K1, threshold=th)
        out[th] = max(relative_pose_error(R_gt, t_gt, *(est[:2] if est else (None, None))))
    return out


def pose_from_fundamental(
    F: np.ndarray, K0: np.ndarray, K1: np.ndarray, x0: np.ndarray, x1: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Relative pose from a fundamental matrix: ``E = K1^T F K0`` decomposed by cv2.recoverPose.

    Returns:
        (R (3, 3), t (3,) unit vector, (K,) bool cheirality inliers), or None with fewer than 5 matches.
    """
    if F is None or len(x0) < 5:
        return None
    E = K1.T @ np.asarray(F, np.float64) @ K0
    p0, p1 = _normalise(x0, K0), _normalise(x1, K1)
    _, R, t, mask, _ = cv2.recoverPose(E, p0, p1, np.eye(3), distanceThresh=1e9)
    return R, t.reshape(3), mask.ravel() > 0


def pose_auc(
    errors: np.ndarray, thresholds: tuple[float, ...] = DEFAULTS.pose_thresholds
) -> dict[float, float]:
    """Area under the recall-vs-error curve up to each threshold, normalised to [0, 1].

    The curve starts at (0, 0), rises linearly between the sorted errors (recall i/N at the i-th) and stays
    flat from the last error below the threshold up to the threshold (standard SuperGlue/LoFTR AUC).
    """
    e = np.sort(np.nan_to_num(np.asarray(errors, np.float64).reshape(-1), nan=np.inf))
    n = len(e)
    if n == 0:
        return {th: 0.0 for th in thresholds}
    ex = np.concatenate([[0.0], e])
    rec = np.arange(n + 1) / n
    out = {}
    for th in thresholds:
        m = int(np.searchsorted(ex, th))  # curve points with error < th
        xs = np.concatenate([ex[:m], [th]])
        ys = np.concatenate([rec[:m], [rec[m - 1]]])
        out[th] = float(np.trapezoid(ys, xs) / th)
    return out
