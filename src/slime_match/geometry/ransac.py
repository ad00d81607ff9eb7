"""Slime's RANSACs (paper SM "RANSAC implementations"): planar homography and fundamental matrix.

Hypotheses are drawn and scored in vectorised batches (``config.batch`` models at a time, all
problems of :func:`ransac_homography_many` together). The adaptive iteration bound
``log(1 - p) / log(1 - w^s)`` is updated after each batch instead of after each model, so a run may
draw up to one batch more models than a strictly sequential RANSAC would.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from slime_match.errors import ConfigError
from slime_match.geometry.fundamental import (
    epipolar_distance_batch,
    fundamental_8point,
    fundamental_8point_batch,
    fundamental_from_homography_and_parallax_batch,
)
from slime_match.geometry.homography import homography_dlt, homography_dlt_batch
from slime_match.geometry.ransac_kernels import far_samples, inlier_counts, inlier_mask, minimal_homographies
from slime_match.geometry.sampling import sample_subsets, sample_subsets_varying
from slime_match.options import config_from_dict
from slime_match.types import GeometryResult

logger = logging.getLogger("slime_match")


@dataclass
class HomographyRansacConfig:
    """Planar homography RANSAC used inside Slime (paper SM).

    Attributes:
        threshold: inlier bound on the two-sided reprojection error, pixels (t_perp).
        min_iterations: models always drawn.
        max_iterations: hard cap on drawn models.
        confidence: probability p of drawing at least one outlier-free sample (adaptive bound).
        min_sample_distance: samples with two points closer than this (pixels, in either image) are rejected.
        degeneracy_threshold: samples whose normalised DLT matrix has 2nd smallest singular value below
            this are degenerate.
        batch: models drawn and scored together per problem and round.
        refine: refit the best model by least-squares DLT on its inliers (kept only if no inlier is lost).
    """

    threshold: float = 15.0
    min_iterations: int = 100
    max_iterations: int = 10_000
    confidence: float = 0.9
    min_sample_distance: float = 15.0
    degeneracy_threshold: float = 0.05
    batch: int = 100
    refine: bool = True


@dataclass
class FundamentalRansacConfig:
    """Post-processing fundamental matrix RANSAC (paper SM).

    Attributes:
        threshold: inlier bound in pixels on the max epipolar distance (and on the two-sided error of
            the homography models); the paper's best post-processing values are 2-3 px.
        min_iterations: 8-point models always drawn (and plane + parallax models).
        max_iterations: hard cap on drawn models per stage.
        confidence: probability p of drawing at least one outlier-free sample (adaptive bound).
        degeneracy_threshold: 8-point (and DLT) samples whose normalised matrix has 2nd smallest singular
            value below this are degenerate; a degenerate 8-point sample yields a homography instead.
        batch: models drawn and scored together per round.
        refine: refit the winners on their inliers (kept only if no inlier is lost).
        max_elements: bound on models x points scored at once (memory).
    """

    threshold: float = 3.0
    min_iterations: int = 200
    max_iterations: int = 10_000
    confidence: float = 0.9
    degeneracy_threshold: float = 0.05
    batch: int = 200
    refine: bool = True
    max_elements: int = 2_000_000


_C = TypeVar("_C", HomographyRansacConfig, FundamentalRansacConfig)


def make_config(cls: type[_C], config: _C | dict | None) -> _C:
    """Build and validate a RANSAC config from None (defaults), a dict of options, or an instance.

    Raises:
        ConfigError: unknown option names or invalid values.
    """
    if config is None:
        config = cls()
    elif isinstance(config, dict):
        config = config_from_dict(cls, config)
    elif not isinstance(config, cls):
        raise ConfigError(f"expected {cls.__name__}, a dict or None, got {type(config).__name__}")
    if not config.threshold > 0:
        raise ConfigError(f"threshold must be > 0, got {config.threshold}")
    if not 1 <= config.min_iterations <= config.max_iterations:
        raise ConfigError("need 1 <= min_iterations <= max_iterations")
    if not 0 < config.confidence < 1:
        raise ConfigError(f"confidence must be in (0, 1), got {config.confidence}")
    if config.batch < 1:
        raise ConfigError(f"batch must be >= 1, got {config.batch}")
    if isinstance(config, FundamentalRansacConfig) and config.max_elements < 1:
        raise ConfigError(f"max_elements must be >= 1, got {config.max_elements}")
    return config


def _iteration_bound(inliers: np.ndarray, n: np.ndarray, sample_size: int, cfg: _C) -> np.ndarray:
    """(P,) adaptive RANSAC bound clamped to [min_iterations, max_iterations]."""
    w = np.clip(inliers / np.maximum(n, 1), 0.0, 1.0) ** sample_size
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = np.log(1.0 - cfg.confidence) / np.log1p(-w)
    bound = np.where(w >= 1.0, 0.0, np.where(w <= 0.0, np.inf, bound))
    return np.clip(np.ceil(bound), cfg.min_iterations, cfg.max_iterations).astype(np.int64)


def _pair_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...) distance between correspondences a and b (..., 4) = (x0, y0, x1, y1): the smaller of both images."""
    d = a - b
    d *= d
    return np.sqrt(np.minimum(d[..., 0] + d[..., 1], d[..., 2] + d[..., 3]))


def _has_far_quadruple(x: np.ndarray, t: float) -> bool:
    """Whether some 4 of the (n, 4) correspondences pass the sample distance test (``far_samples``).

    Such a sample is a 4-clique of the graph joining the pairs farther than t apart: an edge (i, j) whose
    common neighbours hold an edge. Memory and time grow as n^3 and n^4: meant for small n.
    """
    far = (_pair_gap(x[:, None], x[None]) > t).astype(np.float64)  # (n, n), zero diagonal
    common = far[:, None, :] * far[None, :, :]  # (n, n, n): k joined to both i and j
    return bool((((common @ far) * common).sum(axis=2) * far).any())


def _consistent_side(h: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """(M,) side (+1/-1) of each (M, k, 2) sample under its homography, 0 when the points disagree."""
    w = np.einsum("mij,mkj->mki", h[:, 2:3, :2], xs)[..., 0] + h[:, 2:3, 2]
    s = np.sign(w)
    return np.where((s == s[:, :1]).all(axis=1), s[:, 0], 0.0)


def _homography_inliers(h: np.ndarray, side: float, x0: np.ndarray, x1: np.ndarray, t: float) -> np.ndarray:
    """(K,) inliers of one homography on (K, 2) correspondences: two-sided error < t pixels and the plane side
    (``side * w > 0`` for ``w`` the third coordinate of ``H [x0; 1]``)."""
    return inlier_mask(np.ascontiguousarray(h, dtype=np.float64), float(side), np.hstack([x0, x1]), float(t))


class _Stack:
    """Correspondence sets of many problems stored flat: problem p is rows ``offset[p]`` to ``offset[p] + n[p] - 1``
    of the (N, 4) rows (x0, y0, x1, y1), pixels."""

    def __init__(self, problems: list[tuple[np.ndarray, np.ndarray]]) -> None:
        xs0, xs1 = [], []
        for a, b in problems:
            a = np.asarray(a, dtype=np.float64).reshape(-1, 2)
            b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
            if a.shape != b.shape:
                raise ValueError(f"x0 and x1 must have the same shape, got {a.shape} and {b.shape}")
            xs0.append(a)
            xs1.append(b)
        self.x0s, self.x1s = xs0, xs1
        self.n = np.array([len(a) for a in xs0], dtype=np.int64)
        self.offset = np.concatenate([[0], np.cumsum(self.n)[:-1]]).astype(np.int64)
        empty = [np.zeros((0, 2))]
        self.rows = np.hstack([np.concatenate(xs0 + empty), np.concatenate(xs1 + empty)])  # (N, 4): x0 y0 x1 y1

    def without_far_sample(self, t: float, candidates: np.ndarray, max_n: int = 64) -> np.ndarray:
        """(P,) True for the candidate problems (4 <= n <= max_n) proven to hold no 4 correspondences pairwise
        farther than t: every sample of theirs fails the distance test."""
        check = np.flatnonzero(candidates & (self.n >= 4) & (self.n <= max_n))
        out = np.zeros(len(self.n), dtype=bool)
        out[check] = [not _has_far_quadruple(self.rows[self.offset[p]:self.offset[p] + self.n[p]], t) for p in check]
        return out


def _finish_homography(
    h: np.ndarray | None, side: float, x0: np.ndarray, x1: np.ndarray, cfg: HomographyRansacConfig, info: dict
) -> GeometryResult:
    """Refit by least-squares DLT on the inliers (kept if no inlier is lost) and package the result."""
    if h is None:
        return GeometryResult("homography", None, np.zeros(len(x0), dtype=bool), info)
    inl = _homography_inliers(h, side, x0, x1, cfg.threshold)
    info["refined"] = False
    if cfg.refine and inl.sum() > 4:
        h2, sigma2 = homography_dlt(x0[inl], x1[inl])
        if sigma2 >= cfg.degeneracy_threshold:
            w = x0[inl] @ h2[2, :2] + h2[2, 2]
            side2 = 1.0 if w.sum() >= 0 else -1.0
            inl2 = _homography_inliers(h2, side2, x0, x1, cfg.threshold)
            if inl2.sum() >= inl.sum():
                h, side, inl, info["refined"] = h2, side2, inl2, True
    h = h * side  # inliers lie on the positive side: w > 0
    if h[2, 2] > 1e-12 * np.linalg.norm(h):
        h = h / h[2, 2]
    info["num_inliers"] = int(inl.sum())
    return GeometryResult("homography", h, inl, info)


def ransac_homography_many(
    problems: list[tuple[np.ndarray, np.ndarray]],
    config: HomographyRansacConfig | dict | None = None,
    seed: int | Sequence[int] | None = 0,
) -> list[GeometryResult]:
    """Planar homography RANSAC on many independent problems at once (Slime's block pairs).

    Each round draws up to ``config.batch`` 4-point samples for every unfinished problem, fits them
    all with one batched DLT and scores them together, so hundreds of small problems cost about as
    much as a few large ones. Small problems without any 4 correspondences pairwise farther apart than
    ``min_sample_distance`` (checked exactly after the first round) skip the work on their samples, which
    would all be rejected: their samples are still drawn while other problems run (same random stream,
    same results) and the loop ends once only they are left.

    Args:
        problems: list of (x0 (K_i, 2), x1 (K_i, 2)) pixel correspondences.
        config: options (dataclass, dict or None for the paper defaults).
        seed: seed (or seed sequence) of the numpy generator shared by all problems (None: nondeterministic).

    Returns:
        One GeometryResult per problem (kind "homography"; model None and no inliers when no
        non-degenerate sample exists, e.g. fewer than 4 matches, collinear or duplicated points).
        The model maps image 0 to image 1, its inliers have a positive third coordinate and it is
        scaled to H[2, 2] = 1 when that entry is positive.
    """
    cfg = make_config(HomographyRansacConfig, config)
    rng = np.random.default_rng(seed)
    data = _Stack(problems)
    num = len(data.n)
    best_count = np.zeros(num, dtype=np.int64)
    best_h = np.zeros((num, 3, 3))
    best_side = np.zeros(num)
    iters = np.zeros(num, dtype=np.int64)
    bound = np.full(num, cfg.max_iterations, dtype=np.int64)
    hopeless = np.zeros(num, dtype=bool)  # problems that only draw rejected samples (known after one round)
    active = data.n >= 4
    while (active & ~hopeless).any():
        first_round = not iters.any()
        act = np.flatnonzero(active)
        cnt = np.minimum(np.maximum(cfg.min_iterations, bound[act]) - iters[act], cfg.batch)
        iters[act] += cnt
        own = np.repeat(act, cnt)
        index = sample_subsets_varying(rng, data.n[own], 4)  # drawn for all: the random stream is kept
        drawn = ~hopeless[own]
        own, index = own[drawn], index[drawn]
        ok = far_samples(data.rows, data.offset[own], index, float(cfg.min_sample_distance))
        if first_round:  # the small problems none of whose samples passed: is any sample possible at all?
            hopeless = data.without_far_sample(cfg.min_sample_distance, np.bincount(own[ok], minlength=num) == 0)
        own, index = own[ok], index[ok]
        h, ok = minimal_homographies(data.rows, data.offset[own], index, float(cfg.degeneracy_threshold))
        own, h, index = own[ok], h[ok], index[ok]
        side = _consistent_side(h, data.rows[data.offset[own, None] + index, :2])
        ok = side != 0
        own, h, side = own[ok], h[ok], side[ok]
        if len(own):
            counts = inlier_counts(h, side, data.rows, data.offset[own], data.n[own], float(cfg.threshold))
            order = np.lexsort((np.arange(len(own)), -counts, own))  # per problem: best, then first drawn
            _, first = np.unique(own[order], return_index=True)
            top = order[first]
            better = counts[top] > best_count[own[top]]
            top = top[better]
            p = own[top]
            best_count[p], best_h[p], best_side[p] = counts[top], h[top], side[top]
            bound[p] = _iteration_bound(best_count[p], data.n[p], 4, cfg)
        active = (data.n >= 4) & (iters < np.maximum(cfg.min_iterations, bound))
    iters[active] = cfg.max_iterations  # the hopeless problems left: they would only draw rejected samples
    results = []
    for i in range(num):  # per-problem least-squares refit: a loop over problems, not points
        info = {"backend": "slime", "iterations": int(iters[i]), "threshold": cfg.threshold}
        h = best_h[i] if best_count[i] >= 4 else None
        results.append(_finish_homography(h, best_side[i], data.x0s[i], data.x1s[i], cfg, info))
    return results


def ransac_homography(
    x0: np.ndarray,
    x1: np.ndarray,
    config: HomographyRansacConfig | dict | None = None,
    seed: int | None = 0,
) -> GeometryResult:
    """Planar homography RANSAC (paper SM): two-sided error, plane side, adaptive bound, LS refit.

    Args:
        x0: (K, 2) points in image 0, pixels.
        x1: (K, 2) corresponding points in image 1, pixels.
        config: options (dataclass, dict or None for the paper defaults: 15 px, 100..10,000 models).
        seed: random seed (None: nondeterministic).

    Returns:
        GeometryResult of kind "homography" (model None and no inliers when no model can be fitted).
    """
    return ransac_homography_many([(x0, x1)], config, seed)[0]


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
