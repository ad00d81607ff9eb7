"""Slime's RANSAC options and adaptive stopping (paper SM "RANSAC implementations"), and its planar homography
RANSAC, on one problem or on many at once.

Hypotheses are drawn and scored in vectorised batches (``config.batch`` models at a time, all
problems of :func:`ransac_homography_many` together). The adaptive iteration bound
``log(1 - p) / log(1 - w^s)`` is updated after each batch instead of after each model, so a run may
draw up to one batch more models than a strictly sequential RANSAC would.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from slime_match._runtime.options import config_from_dict
from slime_match.errors import ConfigError
from slime_match.geometry.homography import homography_dlt
from slime_match.geometry.ransac_kernels import far_samples, inlier_counts, inlier_mask, minimal_homographies
from slime_match.geometry.ransac_problems import _Stack
from slime_match.geometry.sampling import sample_subsets_varying
from slime_match.types import GeometryResult


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


def _consistent_side(h: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """(M,) side (+1/-1) of each (M, k, 2) sample under its homography, 0 when the points disagree."""
    w = np.einsum("mij,mkj->mki", h[:, 2:3, :2], xs)[..., 0] + h[:, 2:3, 2]
    s = np.sign(w)
    return np.where((s == s[:, :1]).all(axis=1), s[:, 0], 0.0)


def _homography_inliers(h: np.ndarray, side: float, x0: np.ndarray, x1: np.ndarray, t: float) -> np.ndarray:
    """(K,) inliers of one homography on (K, 2) correspondences: two-sided error < t pixels and the plane side
    (``side * w > 0`` for ``w`` the third coordinate of ``H [x0; 1]``)."""
    return inlier_mask(np.ascontiguousarray(h, dtype=np.float64), float(side), np.hstack([x0, x1]), float(t))


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
