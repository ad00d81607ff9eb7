"""Standard protocols of the hard sets, scored on a method's raw matches with OpenCV MAGSAC++.

* EVD (:func:`evd_protocol`): homography by ``cv2.findHomography(..., cv2.USAC_MAGSAC)``; its error is the
  mean transfer error against the GT homography over the common area of the two images, both directions
  (:func:`homography_transfer_error`); pair mAA = mean over t = 1..15 px of [error < t].
* WxBS (:func:`wxbs_protocol`): fundamental matrix by ``cv2.findFundamentalMat(..., cv2.USAC_MAGSAC)``;
  each GT correspondence gets its symmetric epipolar distance (:func:`symmetric_epipolar_distance`, the
  larger of its two point-to-line distances);
  recall at t = fraction of GT correspondences closer than t; pair mAA = mean recall over t = 1..20 px.

A pair without a model (too few matches, or MAGSAC++ finds none) scores mAA 0. OpenCV's USAC seeds its
own random generator with a fixed state, so the estimates are deterministic; but its samples are drawn by
index, so the estimate, and the pair's mAA, depend on the order in which a method lists its matches. With
``orders`` > 1 each protocol is also run on ``orders - 1`` random permutations of the matches (a fixed
generator) and reports the mean mAA over all orders (``maa_mean``, with ``maa_min`` and ``maa_max``): the
protocol's expected result over its RANSAC's sample sequences, where ``maa`` is one draw of it.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from slime_match.geometry.homography import project

EVD_THRESHOLDS = tuple(float(t) for t in range(1, 16))
WXBS_THRESHOLDS = tuple(float(t) for t in range(1, 21))
CONFIDENCE = 0.999


def magsac_homography(x0: np.ndarray, x1: np.ndarray, threshold: float, max_iters: int) -> np.ndarray | None:
    """(3, 3) homography x0 -> x1 of (K, 2) matches by MAGSAC++ (``threshold`` in px); None with K < 4 or
    when no model is found (OpenCV's assertion on a set it finds no model for included)."""
    if len(x0) < 4:
        return None
    try:
        H, _ = cv2.findHomography(
            np.float64(x0), np.float64(x1), cv2.USAC_MAGSAC, threshold, confidence=CONFIDENCE, maxIters=max_iters
        )
    except cv2.error:  # OpenCV's USAC asserts on some small sets instead of finding no model
        return None
    return None if H is None or H.shape != (3, 3) else H


def magsac_fundamental(x0: np.ndarray, x1: np.ndarray, threshold: float, max_iters: int) -> np.ndarray | None:
    """(3, 3) fundamental matrix (``x1^T F x0 = 0``) of (K, 2) matches by MAGSAC++ (``threshold`` in px);
    None with K < 8 or when no model is found (OpenCV's assertion on a set it finds no model for included)."""
    if len(x0) < 8:
        return None
    try:
        F, _ = cv2.findFundamentalMat(
            np.float64(x0), np.float64(x1), cv2.USAC_MAGSAC, threshold, CONFIDENCE, max_iters
        )
    except cv2.error:  # OpenCV's USAC asserts on some small sets instead of finding no model
        return None
    return None if F is None or F.shape != (3, 3) else F


def _grid(shape: tuple[int, int], step: int) -> np.ndarray:
    """(N, 2) pixel centres ``(x, y)`` of an (H, W) image every ``step`` px."""
    rows, cols = np.mgrid[0 : shape[0] : step, 0 : shape[1] : step]
    return np.stack([cols.ravel(), rows.ravel()], 1).astype(np.float64)


def _visible(H: np.ndarray, points: np.ndarray, src: tuple[int, int], dst: tuple[int, int]) -> np.ndarray:
    """(N,) points of an (H, W) image ``src`` that H maps onto the pixels of image ``dst``, on the visible
    side of the plane (third homogeneous coordinate with the sign it has at the centre of ``src``, as in
    :func:`~slime_match.eval.metrics.coverage.valid_area_homography`); also returns their images."""
    y, w = project(H, points)
    _, wc = project(H, np.array([[(src[1] - 1) / 2, (src[0] - 1) / 2]]))
    x, v = y[:, 0], y[:, 1]
    with np.errstate(invalid="ignore"):
        inside = (x >= -0.5) & (x < dst[1] - 0.5) & (v >= -0.5) & (v < dst[0] - 0.5)
    return inside & (np.sign(w) == np.sign(wc[0])), y


def homography_transfer_error(
    H_est: np.ndarray | None,
    H_gt: np.ndarray,
    shape0: tuple[int, int],
    shape1: tuple[int, int],
    step: int = 1,
) -> float:
    """EVD error in px: the mean of ``|H_est x - H_gt x|`` over the grid points x of image 0 that H_gt maps
    inside image 1 (on the visible side of the plane), and of ``|H_est^-1 y - H_gt^-1 y|`` over the grid
    points y of image 1 that H_gt^-1 maps inside image 0, pooled (one mean over both sets).

    Args:
        shape0, shape1: (H, W) image shapes.
        step: grid spacing in px.

    Returns:
        error in px; inf without ``H_est``, with a singular one, or when the images share no area.
    """
    if H_est is None or not np.all(np.isfinite(H_est)) or abs(np.linalg.det(H_est)) < 1e-15:
        return math.inf
    errors = []
    for Ha, Hb, src, dst in (
        (H_est, H_gt, shape0, shape1),
        (np.linalg.inv(H_est), np.linalg.inv(H_gt), shape1, shape0),
    ):
        pts = _grid(src, step)
        keep, gt = _visible(Hb, pts, src, dst)
        with np.errstate(invalid="ignore", over="ignore"):
            e = np.linalg.norm(project(Ha, pts[keep])[0] - gt[keep], axis=1)
        errors.append(np.where(np.isnan(e), np.inf, e))
    pooled = np.concatenate(errors)
    return float(pooled.mean()) if len(pooled) else math.inf


def match_orders(n: int, orders: int) -> list[np.ndarray]:
    """Index orders of n matches: the given order, then ``orders - 1`` random permutations (fixed seed)."""
    rng = np.random.default_rng(0)
    return [np.arange(n)] + [rng.permutation(n) for _ in range(orders - 1)]


def _spread(maa: list[float]) -> dict[str, float]:
    """{"maa": the first order's mAA, "maa_mean", "maa_min", "maa_max" over all orders}."""
    return {"maa": maa[0], "maa_mean": float(np.mean(maa)), "maa_min": min(maa), "maa_max": max(maa)}


def symmetric_epipolar_distance(F: np.ndarray, x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """(N,) symmetric epipolar distance in px of (N, 2) correspondences: the larger of the distance from x1 to
    the line ``F x0`` and from x0 to the line ``F^T x1`` (a correspondence is as far as its worse image)."""
    h0 = np.concatenate([x0, np.ones((len(x0), 1))], 1)
    h1 = np.concatenate([x1, np.ones((len(x1), 1))], 1)
    l1, l0 = h0 @ F.T, h1 @ F  # epipolar lines in image 1 and image 0
    algebraic = np.abs(np.sum(h1 * l1, 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        d1 = algebraic / np.hypot(l1[:, 0], l1[:, 1])
        d0 = algebraic / np.hypot(l0[:, 0], l0[:, 1])
    return np.nan_to_num(np.maximum(d0, d1), nan=np.inf)


def evd_protocol(
    x0: np.ndarray,
    x1: np.ndarray,
    H_gt: np.ndarray,
    shape0: tuple[int, int],
    shape1: tuple[int, int],
    threshold: float,
    max_iters: int,
    step: int = 1,
    orders: int = 1,
) -> dict[str, Any]:
    """EVD protocol of one pair's (K, 2) raw matches, in their given order and ``orders - 1`` others.

    Returns:
        {"maa": mean over :data:`EVD_THRESHOLDS` of [error < t] (the given order), "error": its px (inf
        without a model), "maa_mean" / "maa_min" / "maa_max": over the orders}.
    """
    errors = [
        homography_transfer_error(magsac_homography(x0[o], x1[o], threshold, max_iters), H_gt, shape0, shape1, step)
        for o in match_orders(len(x0), orders)
    ]
    return {**_spread([float(np.mean([e < t for t in EVD_THRESHOLDS])) for e in errors]), "error": errors[0]}


def wxbs_protocol(
    x0: np.ndarray, x1: np.ndarray, corrs: np.ndarray, threshold: float, max_iters: int, orders: int = 1
) -> dict[str, Any]:
    """WxBS protocol of one pair's (K, 2) raw matches against (M, 4) GT correspondences ``x0 y0 x1 y1``, in
    the matches' given order and ``orders - 1`` others.

    Returns:
        {"maa": mean recall over :data:`WXBS_THRESHOLDS` (the given order), "recall": its recall at each of
        them (all 0 without a model), "maa_mean" / "maa_min" / "maa_max": over the orders}.
    """
    recalls = []
    for o in match_orders(len(x0), orders):
        F = magsac_fundamental(x0[o], x1[o], threshold, max_iters)
        if F is None:
            recalls.append([0.0] * len(WXBS_THRESHOLDS))
        else:
            d = symmetric_epipolar_distance(F, corrs[:, :2], corrs[:, 2:])
            recalls.append([float(np.mean(d < t)) for t in WXBS_THRESHOLDS])
    return {**_spread([float(np.mean(r)) for r in recalls]), "recall": recalls[0]}
