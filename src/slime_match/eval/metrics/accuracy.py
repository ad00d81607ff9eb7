"""Accuracy: mean error of the estimated model over the valid pixels (homography reprojection, or the area
between estimated and GT epipolar lines over the image diagonal), mAA (Eq. acc_formula) and failure counts."""

from __future__ import annotations

import math

import numpy as np

from slime_match.eval.metrics.config import DEFAULTS
from slime_match.geometry.homography import project


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
