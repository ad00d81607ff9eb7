"""Correct matches: planar (two-sided reprojection error), non-planar (max epipolar distance plus local
consistency with the hand-taken GT correspondences), rectified stereo (disparity); exclusion masks."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from slime_match.eval.metrics.config import DEFAULTS
from slime_match.geometry.fundamental import epipolar_distance
from slime_match.geometry.homography import two_sided_error


def pixel_index(xy: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest pixel (row, col) of (K, 2) points and a (K,) mask of points inside the image."""
    col = np.rint(xy[:, 0]).astype(np.int64)
    row = np.rint(xy[:, 1]).astype(np.int64)
    inside = (col >= 0) & (col < shape[1]) & (row >= 0) & (row < shape[0])
    return np.clip(row, 0, shape[0] - 1), np.clip(col, 0, shape[1] - 1), inside


def in_mask(xy: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """(K,) bool: the nearest pixel of each (K, 2) point is excluded by ``mask`` (True = excluded) or the
    point lies outside the mask's image; all False when ``mask`` is None."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if mask is None:
        return np.zeros(len(xy), bool)
    row, col, inside = pixel_index(xy, mask.shape)
    return mask[row, col] | ~inside


def correct_matches_homography(
    x0: np.ndarray,
    x1: np.ndarray,
    H_gt: np.ndarray,
    t: float = DEFAULTS.t_perp,
    mask0: np.ndarray | None = None,
    mask1: np.ndarray | None = None,
) -> np.ndarray:
    """Correct matches of a planar pair: two-sided reprojection error ``max(|x1 - Hx0|, |x0 - H^-1 x1|) < t``.

    A match whose keypoint lies in an excluded (masked, e.g. out-of-plane) region of either image cannot
    be checked against the plane and is reported as not correct: as in the paper, "a match is correct if it
    lies on the plane and its error is below t". It still counts in the precision denominator.

    Args:
        x0, x1: (K, 2) matched keypoints in image 0 / 1, px.
        H_gt: (3, 3) GT homography image 0 -> image 1.
        t: threshold in px.
        mask0, mask1: optional (H, W) bool exclusion masks (True = excluded).

    Returns:
        (K,) bool.
    """
    x0 = np.asarray(x0, np.float64).reshape(-1, 2)
    x1 = np.asarray(x1, np.float64).reshape(-1, 2)
    if len(x0) == 0:
        return np.zeros(0, bool)
    ok = two_sided_error(np.asarray(H_gt, np.float64), x0, x1) < t
    return ok & ~in_mask(x0, mask0) & ~in_mask(x1, mask1)


def _locally_consistent(
    q: np.ndarray,
    target: np.ndarray,
    g_src: np.ndarray,
    g_dst: np.ndarray,
    t: float,
    radius: float,
    k: int,
    k_flow: int,
) -> np.ndarray:
    """Whether correspondences ``q -> target`` agree with the flow of nearby GT correspondences.

    Among the GT correspondences ``g_src -> g_dst`` within ``radius`` px of ``q``, the ``k`` nearest fit a
    least-squares local affine flow (translation when fewer than 3 or collinear) that must predict
    ``target`` within ``t``; alternatively one of the ``k_flow`` nearest, carried to ``q`` by the linear
    part of that model, must land within ``t`` (so that a match next to a depth discontinuity, where the
    fit mixes two surfaces, is judged by the GT point on its own side). Points without GT neighbours are
    not checked (True).

    Args:
        q, target: (K, 2) points, px.
        g_src, g_dst: (M, 2) GT correspondences, px.

    Returns:
        (K,) bool.
    """
    k = min(k, len(g_src))
    dist, idx = cKDTree(g_src).query(q, k=k, distance_upper_bound=radius)
    dist, idx = dist.reshape(len(q), k), idx.reshape(len(q), k)
    near = np.isfinite(dist)  # (K, k), sorted by distance
    idx = np.where(near, idx, 0)
    src, dst = g_src[idx], g_dst[idx]  # (K, k, 2)
    w = near.astype(np.float64)
    n = w.sum(1)
    pred = q + np.einsum("nk,nkj->nj", w, dst - src) / np.maximum(n, 1)[:, None]
    lin = np.tile(np.eye(2), (len(q), 1, 1))  # linear part of the local map (identity: translation only)
    X = np.concatenate([np.ones_like(src[..., :1]), (src - q[:, None]) / radius], axis=-1)  # (K, k, 3)
    M = np.einsum("nki,nk,nkj->nij", X, w, X)
    eig = np.linalg.eigvalsh(M)
    affine = (n >= 3) & (eig[:, 0] > 1e-6 * np.maximum(eig[:, -1], 1e-12))
    if affine.any():
        b = np.einsum("nki,nk,nkj->nij", X[affine], w[affine], dst[affine])  # (K', 3, 2)
        sol = np.linalg.solve(M[affine], b)
        pred[affine] = sol[:, 0]
        lin[affine] = np.swapaxes(sol[:, 1:], 1, 2) / radius
    ok = np.linalg.norm(pred - target, axis=1) < t
    kf = min(k_flow, k)
    # each of the kf nearest carried to q by the local linear model: g_dst + L (q - g_src)
    carried = dst[:, :kf] + np.einsum("nij,nkj->nki", lin, q[:, None] - src[:, :kf])
    ok |= ((np.linalg.norm(carried - target[:, None], axis=2) < t) & near[:, :kf]).any(1)
    return ok | (n == 0)


def correct_matches_fundamental(
    x0: np.ndarray,
    x1: np.ndarray,
    F_gt: np.ndarray,
    t: float = DEFAULTS.t_perp,
    gt_corrs: np.ndarray | None = None,
    radius: float = DEFAULTS.gt_radius,
    neighbours: int = DEFAULTS.gt_neighbours,
    flow_neighbours: int = DEFAULTS.gt_flow_neighbours,
) -> np.ndarray:
    """Correct matches of a non-planar pair.

    A match is correct when its maximum epipolar distance w.r.t. ``F_gt`` is below ``t`` and, where GT
    correspondences are given, it agrees with their local flow in both directions (image 0 -> 1 around
    ``x0`` and image 1 -> 0 around ``x1``): the local affine flow fitted to the ``neighbours`` nearest GT
    correspondences within ``radius`` px predicts the other point within ``t``, or the flow of one of the
    ``flow_neighbours`` nearest agrees within ``t``. A direction without any GT correspondence within
    ``radius`` is not checked (no local evidence there).

    Args:
        x0, x1: (K, 2) matched keypoints, px.
        F_gt: (3, 3) GT fundamental matrix, ``x1^T F x0 = 0``.
        t: threshold in px.
        gt_corrs: optional (M, 4) GT correspondences ``x0 y0 x1 y1``.
        radius: neighbourhood radius in px.
        neighbours: neighbours used by the local affine model.
        flow_neighbours: nearest neighbours whose flow alone may vouch for the match.

    Returns:
        (K,) bool.
    """
    x0 = np.asarray(x0, np.float64).reshape(-1, 2)
    x1 = np.asarray(x1, np.float64).reshape(-1, 2)
    if len(x0) == 0:
        return np.zeros(0, bool)
    ok = epipolar_distance(np.asarray(F_gt, np.float64), x0, x1) < t
    if gt_corrs is None or len(gt_corrs) == 0:
        return ok
    g = np.asarray(gt_corrs, np.float64).reshape(-1, 4)
    for q, target, src, dst in ((x0, x1, g[:, :2], g[:, 2:]), (x1, x0, g[:, 2:], g[:, :2])):
        ok &= _locally_consistent(q, target, src, dst, t, radius, neighbours, flow_neighbours)
    return ok


def disparity_error(x0: np.ndarray, x1: np.ndarray, disparity: np.ndarray) -> np.ndarray:
    """(K,) distance in px between ``x1`` and the GT right position ``(x0 - d, y0)`` of a rectified pair.

    ``d`` is read at the nearest pixel of ``x0`` in the left disparity map; NaN where it is unknown
    (inf/nan in the map, or ``x0`` outside the image).
    """
    x0 = np.asarray(x0, np.float64).reshape(-1, 2)
    x1 = np.asarray(x1, np.float64).reshape(-1, 2)
    row, col, inside = pixel_index(x0, disparity.shape)
    d = np.where(inside, disparity[row, col].astype(np.float64), np.nan)
    d[~np.isfinite(d)] = np.nan
    return np.hypot(x1[:, 0] - (x0[:, 0] - d), x1[:, 1] - x0[:, 1])


def correct_matches_disparity(
    x0: np.ndarray, x1: np.ndarray, disparity: np.ndarray, t: float = DEFAULTS.t_perp
) -> np.ndarray:
    """(K,) bool: ``disparity_error < t``; matches with unknown disparity are False (exclude them from a
    precision by ``np.isfinite(disparity_error(...))``)."""
    with np.errstate(invalid="ignore"):
        return disparity_error(x0, x1, disparity) < t

