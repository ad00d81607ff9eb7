"""Evaluation metrics of the paper (Sec. "Error metrics") and of the standard pose benchmarks.

* correct matches: planar (two-sided reprojection error), non-planar (max epipolar distance plus local
  consistency with the hand-taken GT correspondences), rectified stereo (disparity);
* coverage: dilated area of the correct keypoints over the valid area, minimum of the two images;
* accuracy: mean error of the estimated model over the valid pixels (homography reprojection, or the
  area between estimated and GT epipolar lines over the image diagonal), aggregated by mAA (Eq. acc_formula);
* pose: LoFTR protocol (essential matrix RANSAC in normalised coordinates, angular errors, AUC@5/10/20).

All coordinates are pixels ``(x, y)`` with the centre of the top-left pixel at ``(0, 0)``; image shapes are
``(height, width)``; masks are boolean, ``valid`` masks True = usable, ``mask0/mask1`` True = excluded.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

from slime_match.geometry.fundamental import epipolar_distance
from slime_match.geometry.homography import project, two_sided_error
from slime_match.options import config_from_dict

logger = logging.getLogger("slime_match")


@dataclass
class MetricConfig:
    """Metric parameters (paper defaults).

    Attributes:
        t_perp: correctness / coverage / mAA threshold in px (paper: 15).
        gt_radius: radius in px of the GT-correspondence neighbourhood checked by the non-planar test.
        gt_neighbours: number of nearest GT correspondences used for the local affine flow model.
        gt_flow_neighbours: nearest GT correspondences whose flow alone may vouch for a match.
        accuracy_step: grid step in px of the valid points sampled by the epipolar accuracy.
        accuracy_col_step: strip width in px of the line-area integration of the epipolar accuracy.
        pose_thresholds: AUC thresholds in degrees (LoFTR protocol).
    """

    t_perp: float = 15.0
    gt_radius: float = 50.0
    gt_neighbours: int = 8
    gt_flow_neighbours: int = 2
    accuracy_step: int = 8
    accuracy_col_step: int = 4
    pose_thresholds: tuple[float, ...] = (5.0, 10.0, 20.0)

    @classmethod
    def from_options(cls, **options: object) -> MetricConfig:
        """Config with some fields overridden; unknown names raise ConfigError."""
        return config_from_dict(cls, options)


DEFAULTS = MetricConfig()


# ----------------------------------------------------------------------------------------------------------
# correct matches


def _pixel_index(xy: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    row, col, inside = _pixel_index(xy, mask.shape)
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
    row, col, inside = _pixel_index(x0, disparity.shape)
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


# ----------------------------------------------------------------------------------------------------------
# coverage


def dilated_mask(points: np.ndarray, shape: tuple[int, int], t: float = DEFAULTS.t_perp) -> np.ndarray:
    """(H, W) bool: pixels within distance ``t`` of the nearest pixel of any (N, 2) point (disk dilation);
    points outside the image are ignored."""
    points = np.asarray(points, np.float64).reshape(-1, 2)
    seeds = np.full(shape, 255, np.uint8)
    row, col, inside = _pixel_index(points, shape)
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
        row, col, inside = _pixel_index(np.where(np.isfinite(y), y, -1.0), sb[:2])
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


# ----------------------------------------------------------------------------------------------------------
# accuracy


def _grid_points(valid: np.ndarray, step: int) -> np.ndarray:
    """(N, 2) pixel coordinates of the valid pixels on a grid of spacing ``step``."""
    sub = valid[::step, ::step]
    rows, cols = np.nonzero(sub)
    return np.stack([cols * step, rows * step], 1).astype(np.float64)


def homography_accuracy_error(
    H_est: np.ndarray | None, H_gt: np.ndarray, valid0: np.ndarray, valid1: np.ndarray, step: int = 1
) -> float:
    """Planar accuracy error ``max(E12, E21)`` in px: E12 is the mean ``|H_est x - H_gt x|`` over the valid
    pixels of image 0 (every ``step`` px), E21 the same with the inverses over the valid pixels of image 1.

    Returns:
        error in px; inf when ``H_est`` is None or singular, or maps a valid pixel to infinity.
    """
    if H_est is None or not np.all(np.isfinite(H_est)) or abs(np.linalg.det(H_est)) < 1e-15:
        return math.inf
    H_est, H_gt = np.asarray(H_est, np.float64), np.asarray(H_gt, np.float64)
    errs = []
    for Ha, Hb, valid in ((H_est, H_gt, valid0), (np.linalg.inv(H_est), np.linalg.inv(H_gt), valid1)):
        pts = _grid_points(valid, step)
        if len(pts) == 0:
            raise ValueError("homography_accuracy_error: empty valid area")
        with np.errstate(invalid="ignore", over="ignore"):
            e = np.linalg.norm(project(Ha, pts)[0] - project(Hb, pts)[0], axis=1)
        errs.append(float(np.mean(np.where(np.isnan(e), np.inf, e))))
    return max(errs)


def _band_area(
    l_a: np.ndarray, l_b: np.ndarray, width: int, height: int, col_step: int, chunk: int = 1024
) -> np.ndarray:
    """Area in px^2 of the smaller double wedge between line pairs inside a ``width x height`` image.

    Two lines split the image into the region where their half-planes disagree and the one where they
    agree (each a pair of opposite wedges); since line signs are arbitrary, the smaller of the two is the
    area enclosed by the lines. The image is cut into vertical strips ``col_step`` px wide: the length
    along y is exact at each strip centre and the strips are summed (midpoint rule, exact where the
    length is linear in x, i.e. away from the few kinks where a line leaves the image or the lines cross).

    Args:
        l_a, l_b: (N, 3) lines ``a x + b y + c = 0``.

    Returns:
        (N,) areas.
    """
    edges = np.append(np.arange(-0.5, width - 0.5, col_step), width - 0.5)
    xs, widths = (edges[:-1] + edges[1:]) / 2, np.diff(edges)
    y_lo, y_hi = -0.5, height - 0.5
    out = np.empty(len(l_a))
    for s in range(0, len(l_a), chunk):
        ivs = []
        for ln in (l_a[s : s + chunk], l_b[s : s + chunk]):
            a, b, c = (ln[:, i : i + 1] for i in range(3))
            v = a * xs + c  # (n, strips): half-plane is b y > -v
            with np.errstate(divide="ignore", invalid="ignore"):
                y0 = np.clip(-v / b, y_lo, y_hi)
            full = np.where(v > 0, y_hi, y_lo)  # b == 0: whole strip or nothing
            lo = np.where(b > 0, y0, y_lo)
            hi = np.where(b > 0, y_hi, np.where(b < 0, y0, full))
            ivs.append((lo, hi))
        (lo1, hi1), (lo2, hi2) = ivs
        inter = np.maximum(np.minimum(hi1, hi2) - np.maximum(lo1, lo2), 0.0)
        disagree = ((hi1 - lo1) + (hi2 - lo2) - 2 * inter) @ widths
        out[s : s + chunk] = np.minimum(disagree, width * height - disagree)
    return out


def epipolar_line_area(
    l_est: np.ndarray, l_gt: np.ndarray, shape: tuple[int, int], col_step: int = 1
) -> np.ndarray:
    """(N,) area in px^2 enclosed by estimated and GT epipolar lines (N, 3) inside an image of ``shape``.

    Pairs whose GT line is closer to vertical are integrated along rows (x and y swapped) so that the
    strip-wise integration stays accurate; ``col_step`` is the strip width in px (1: every pixel column).
    """
    h, w = shape[:2]
    vertical = np.abs(l_gt[:, 0]) > np.abs(l_gt[:, 1])
    area = np.empty(len(l_gt))
    area[~vertical] = _band_area(l_est[~vertical], l_gt[~vertical], w, h, col_step)
    swap = [1, 0, 2]
    area[vertical] = _band_area(l_est[vertical][:, swap], l_gt[vertical][:, swap], h, w, col_step)
    return area


def fundamental_accuracy_error(
    F_est: np.ndarray | None,
    F_gt: np.ndarray,
    valid0: np.ndarray,
    valid1: np.ndarray,
    step: int = DEFAULTS.accuracy_step,
    col_step: int = DEFAULTS.accuracy_col_step,
) -> float:
    """Non-planar accuracy error ``max(E12, E21)`` in px (paper Sec. "Accuracy", after the no-RANSAC
    fundamental-matrix metric).

    E12: for the valid pixels x of image 0 on a grid of spacing ``step``, the area inside image 1 enclosed
    by the epipolar lines ``F_est x`` and ``F_gt x`` (the smaller double wedge between them, integrated
    over strips ``col_step`` px wide, see :func:`epipolar_line_area`), divided by the diagonal of image 1 and averaged; E21 likewise with ``F^T`` and the
    valid pixels of image 1 measured inside image 0. The image shapes are those of ``valid0``/``valid1``.

    Returns:
        error in px; inf when ``F_est`` is None or not finite.
    """
    if F_est is None or not np.all(np.isfinite(F_est)):
        return math.inf
    F_est, F_gt = np.asarray(F_est, np.float64), np.asarray(F_gt, np.float64)
    errs = []
    for Fa, Fb, valid_src, valid_dst in ((F_est, F_gt, valid0, valid1), (F_est.T, F_gt.T, valid1, valid0)):
        pts = _grid_points(valid_src, step)
        if len(pts) == 0:
            raise ValueError("fundamental_accuracy_error: empty valid area")
        ph = np.concatenate([pts, np.ones((len(pts), 1))], 1)
        area = epipolar_line_area(ph @ Fa.T, ph @ Fb.T, valid_dst.shape, col_step)
        errs.append(float(area.mean() / math.hypot(*valid_dst.shape[:2])))
    return max(errs)


def mean_average_accuracy(errors: np.ndarray, max_threshold: int = int(DEFAULTS.t_perp)) -> float:
    """Paper Eq. acc_formula: mean over thresholds t = 1..max_threshold px of the fraction of pairs with
    error < t (NaN counts as a failure)."""
    e = np.asarray(errors, np.float64).reshape(-1)
    if len(e) == 0:
        return 0.0
    th = np.arange(1, max_threshold + 1, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return float((e[None, :] < th[:, None]).mean())


def failure_counts(n_matches: np.ndarray, n_correct: np.ndarray) -> dict[str, int]:
    """Pairs with no matches at all, and pairs with matches but none correct (per-pair counts (N,))."""
    n_matches, n_correct = np.asarray(n_matches), np.asarray(n_correct)
    return {
        "no_matches": int((n_matches == 0).sum()),
        "only_wrong": int(((n_matches > 0) & (n_correct == 0)).sum()),
    }


# ----------------------------------------------------------------------------------------------------------
# pose (LoFTR protocol)


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
        matches or when no essential matrix is found.
    """
    if len(x0) < 5:
        return None
    p0, p1 = _normalise(x0, K0), _normalise(x1, K1)
    f_mean = np.mean([K0[0, 0], K0[1, 1], K1[0, 0], K1[1, 1]])
    E, mask = cv2.findEssentialMat(
        p0, p1, np.eye(3), method=cv2.RANSAC, prob=conf, threshold=threshold / f_mean
    )
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
