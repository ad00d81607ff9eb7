"""Slime's post-processing fundamental matrix RANSAC with plane + parallax completion (paper SM "RANSAC
implementations"): batched 8-point models, degenerate samples as homographies, then F = [e']_x H."""

from __future__ import annotations

import numpy as np

from slime_match.geometry.fundamental import (
    epipolar_distance_batch,
    fundamental_8point,
    fundamental_8point_batch,
    fundamental_from_homography_and_parallax_batch,
)
from slime_match.geometry.homography import homography_dlt_batch
from slime_match.geometry.ransac import (
    FundamentalRansacConfig,
    HomographyRansacConfig,
    _consistent_side,
    _finish_homography,
    _homography_inliers,
    _iteration_bound,
    make_config,
)
from slime_match.geometry.ransac_kernels import inlier_counts
from slime_match.geometry.sampling import sample_subsets
from slime_match.types import GeometryResult


def _best_first(counts: np.ndarray) -> int:
    return int(np.argmax(counts))  # argmax returns the first maximum: the earliest drawn model


def _epipolar_counts(
    f: np.ndarray, x0: np.ndarray, x1: np.ndarray, t: float, max_elements: int
) -> np.ndarray:
    """(M,) inlier counts of M fundamental matrices on all correspondences."""
    chunk = max(1, max_elements // max(len(x0), 1))
    return np.concatenate(
        [(epipolar_distance_batch(f[s : s + chunk], x0, x1) < t).sum(axis=1) for s in range(0, len(f), chunk)]
        or [np.zeros(0, dtype=np.int64)]
    )


def _homography_counts(h: np.ndarray, side: np.ndarray, x0: np.ndarray, x1: np.ndarray, t: float) -> np.ndarray:
    """(M,) inlier counts of M homographies (two-sided error and plane side) on all (K, 2) correspondences."""
    start, n = np.zeros(len(h), dtype=np.int64), np.full(len(h), len(x0), dtype=np.int64)
    return inlier_counts(np.ascontiguousarray(h), side, np.hstack([x0, x1]), start, n, float(t))


def _refine_fundamental(
    f: np.ndarray, x0: np.ndarray, x1: np.ndarray, cfg: FundamentalRansacConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares 8-point refit on the inliers of f, kept only if no inlier is lost."""
    inl = epipolar_distance_batch(f[None], x0, x1)[0] < cfg.threshold
    if cfg.refine and inl.sum() > 8:
        f2, _ = fundamental_8point(x0[inl], x1[inl])
        inl2 = epipolar_distance_batch(f2[None], x0, x1)[0] < cfg.threshold
        if inl2.sum() >= inl.sum():
            return f2, inl2
    return f, inl


def ransac_fundamental(
    x0: np.ndarray,
    x1: np.ndarray,
    config: FundamentalRansacConfig | dict | None = None,
    seed: int | None = 0,
) -> GeometryResult:
    """Fundamental matrix RANSAC with plane + parallax completion (paper SM).

    8-point samples are drawn in batches; a degenerate 8-point sample (2nd smallest singular value
    below ``degeneracy_threshold``) yields a least-squares DLT homography of the same 8 points instead
    (skipped if degenerate too). The best F and the best H are tracked separately and the adaptive
    bound (sample size 8) follows the best of both. Afterwards a second RANSAC samples two
    correspondences outside the best H's inliers and builds ``F = [e']_x H`` (plane + parallax). The
    best 8-point F and the best plane + parallax F are refined by least-squares 8-point on their
    inliers and the one with more inliers wins.

    Args:
        x0: (K, 2) points in image 0, pixels.
        x1: (K, 2) corresponding points in image 1, pixels.
        config: options (dataclass, dict or None for the defaults).
        seed: random seed (None: nondeterministic).

    Returns:
        GeometryResult of kind "fundamental" with ``x1^T F x0 = 0`` (unit norm). Its kind is
        "homography" (the refined best H, as in :func:`ransac_homography`) when no F has at least as
        many inliers as the best homography, e.g. when no correspondence lies off the plane. model is
        None with no inliers when neither model can be fitted (fewer than 8 matches, degenerate data).
        ``info["source"]`` tells "8-point", "plane+parallax" or "homography".
    """
    cfg = make_config(FundamentalRansacConfig, config)
    rng = np.random.default_rng(seed)
    x0 = np.asarray(x0, dtype=np.float64).reshape(-1, 2)
    x1 = np.asarray(x1, dtype=np.float64).reshape(-1, 2)
    if x0.shape != x1.shape:
        raise ValueError(f"x0 and x1 must have the same shape, got {x0.shape} and {x1.shape}")
    n = len(x0)
    info: dict = {"backend": "slime", "threshold": cfg.threshold}
    if n < 8:
        info["reason"] = f"{n} correspondences, fewer than 8"
        return GeometryResult("fundamental", None, np.zeros(n, dtype=bool), info)
    best_f, best_f_count = None, 0
    best_h, best_h_side, best_h_count = None, 0.0, 0
    iters, bound = 0, cfg.max_iterations
    while iters < max(cfg.min_iterations, bound):
        cnt = min(max(cfg.min_iterations, bound) - iters, cfg.batch)
        iters += cnt
        idx = sample_subsets(rng, n, 8, cnt)
        s0, s1 = x0[idx], x1[idx]
        f, sigma_f = fundamental_8point_batch(s0, s1)
        degenerate = sigma_f < cfg.degeneracy_threshold
        f = f[~degenerate]
        if len(f):
            counts = _epipolar_counts(f, x0, x1, cfg.threshold, cfg.max_elements)
            b = _best_first(counts)
            if counts[b] > best_f_count:
                best_f, best_f_count = f[b], int(counts[b])
        if degenerate.any():
            h, sigma_h = homography_dlt_batch(s0[degenerate], s1[degenerate])
            side = _consistent_side(h, s0[degenerate])
            ok = (sigma_h >= cfg.degeneracy_threshold) & (side != 0)
            h, side = h[ok], side[ok]
            if len(h):
                counts = _homography_counts(h, side, x0, x1, cfg.threshold)
                b = _best_first(counts)
                if counts[b] > best_h_count:
                    best_h, best_h_side, best_h_count = h[b], float(side[b]), int(counts[b])
        top = max(best_f_count, best_h_count)
        bound = (
            int(_iteration_bound(np.array([top]), np.array([n]), 8, cfg)[0]) if top else cfg.max_iterations
        )
    info["iterations"] = iters
    candidates: list[tuple[np.ndarray, str]] = []
    if best_f is not None:
        candidates.append((best_f, "8-point"))
    if best_h is not None:
        pp, pp_iters = _plane_parallax(best_h, best_h_side, x0, x1, cfg, rng)
        info["parallax_iterations"] = pp_iters
        if pp is not None:
            candidates.append((pp, "plane+parallax"))
    refined = [(*_refine_fundamental(f, x0, x1, cfg), source) for f, source in candidates]
    hom = None
    if best_h is not None:
        hom_cfg = HomographyRansacConfig(
            threshold=cfg.threshold, degeneracy_threshold=cfg.degeneracy_threshold, refine=cfg.refine
        )
        hom = _finish_homography(best_h, best_h_side, x0, x1, hom_cfg, dict(info))
        info["homography_inliers"] = int(hom.inliers.sum())
    if refined:
        f, inl, source = max(refined, key=lambda r: int(r[1].sum()))  # first of equals: 8-point
        if hom is None or inl.sum() > hom.inliers.sum():
            info.update(source=source, num_inliers=int(inl.sum()))
            return GeometryResult("fundamental", f, inl, info)
    if hom is not None:
        hom.info.update(source="homography", homography_inliers=int(hom.inliers.sum()))
        return hom
    info["reason"] = "every sample was degenerate"
    return GeometryResult("fundamental", None, np.zeros(n, dtype=bool), info)


def _plane_parallax(
    h: np.ndarray,
    side: float,
    x0: np.ndarray,
    x1: np.ndarray,
    cfg: FundamentalRansacConfig,
    rng: np.random.Generator,
) -> tuple[np.ndarray | None, int]:
    """RANSAC over pairs of off-plane correspondences completing the plane h into F = [e']_x h.

    Returns:
        The best F (None if fewer than 2 off-plane matches or all pairs degenerate) and the models drawn.
    """
    on_plane = _homography_inliers(h, side, x0, x1, cfg.threshold)
    off = np.flatnonzero(~on_plane)
    if len(off) < 2:
        return None, 0
    best_f, best_count, iters, bound = None, 0, 0, cfg.max_iterations
    n_on = int(on_plane.sum())
    while iters < max(cfg.min_iterations, bound):
        cnt = min(max(cfg.min_iterations, bound) - iters, cfg.batch)
        iters += cnt
        idx = off[sample_subsets(rng, len(off), 2, cnt)]
        f, ok = fundamental_from_homography_and_parallax_batch(h, x0[idx], x1[idx])
        f = f[ok]
        if len(f):
            counts = _epipolar_counts(f, x0, x1, cfg.threshold, cfg.max_elements)
            b = _best_first(counts)
            if counts[b] > best_count:
                best_f, best_count = f[b], int(counts[b])
                off_inliers = np.array([max(best_count - n_on, 0)])
                bound = int(_iteration_bound(off_inliers, np.array([len(off)]), 2, cfg)[0])
    return best_f, iters
