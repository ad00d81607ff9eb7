"""One interface over the robust two-view estimators: Slime's RANSAC, OpenCV MAGSAC++ and PoseLib."""

from __future__ import annotations

import cv2
import numpy as np

from slime_match.choices import RANSAC_BACKENDS as BACKENDS
from slime_match.choices import RANSAC_KINDS as KINDS
from slime_match.errors import ConfigError
from slime_match.geometry.fundamental_ransac import ransac_fundamental
from slime_match.geometry.ransac import FundamentalRansacConfig, HomographyRansacConfig, ransac_homography
from slime_match.types import GeometryResult

_MIN_SAMPLE = {"homography": 4, "fundamental": 8}
_MAX_ITERATIONS = 10_000
_CONFIDENCE = 0.999


def _magsac(
    x0: np.ndarray, x1: np.ndarray, kind: str, threshold: float
) -> tuple[np.ndarray | None, np.ndarray]:
    """OpenCV USAC_MAGSAC (MAGSAC++); OpenCV seeds its USAC generator itself (deterministic). No model where
    OpenCV finds none, including where its USAC asserts instead (some small sets of repeated points)."""
    try:
        if kind == "homography":
            model, mask = cv2.findHomography(
                x0, x1, cv2.USAC_MAGSAC, threshold, maxIters=_MAX_ITERATIONS, confidence=_CONFIDENCE
            )
        else:
            model, mask = cv2.findFundamentalMat(x0, x1, cv2.USAC_MAGSAC, threshold, _CONFIDENCE, _MAX_ITERATIONS)
    except cv2.error:
        return None, np.zeros(len(x0), dtype=bool)
    if model is None or model.shape != (3, 3) or mask is None:
        return None, np.zeros(len(x0), dtype=bool)
    return model.astype(np.float64), mask.reshape(-1).astype(bool)


def _poselib(
    x0: np.ndarray, x1: np.ndarray, kind: str, threshold: float, seed: int
) -> tuple[np.ndarray | None, np.ndarray]:
    """PoseLib LO-RANSAC + non-linear refinement (H: one-sided error in image 1; F: Sampson error)."""
    try:
        import poselib  # an optional dependency: the package's "poselib" extra
    except ImportError as error:
        raise ConfigError("the poselib RANSAC backends need PoseLib: pip install 'slime-match[poselib]' (or "
                          "poselib), or choose --ransac homography|fundamental|magsac-...") from error
    opt = {"seed": int(seed), "max_iterations": _MAX_ITERATIONS}
    if kind == "homography":
        model, info = poselib.estimate_homography(x0, x1, {**opt, "max_reproj_error": threshold}, {})
    else:
        model, info = poselib.estimate_fundamental(x0, x1, {**opt, "max_epipolar_error": threshold}, {})
    inliers = np.asarray(info.get("inliers", []), dtype=bool).reshape(-1)
    model = np.asarray(model, dtype=np.float64)
    if inliers.shape != (len(x0),) or not inliers.any() or not np.isfinite(model).all():
        return None, np.zeros(len(x0), dtype=bool)
    return model, inliers


def estimate_geometry(
    x0: np.ndarray,
    x1: np.ndarray,
    kind: str = "fundamental",
    backend: str = "slime",
    threshold: float | None = None,
    seed: int = 0,
) -> GeometryResult:
    """Robustly estimate a homography or a fundamental matrix with the chosen backend.

    Args:
        x0: (K, 2) points in image 0, pixels.
        x1: (K, 2) corresponding points in image 1, pixels.
        kind: "homography" (x1 ~ H x0) or "fundamental" (x1^T F x0 = 0).
        backend: "slime" (the paper's RANSACs), "magsac" (OpenCV USAC_MAGSAC, i.e. MAGSAC++) or
            "poselib" (PoseLib's LO-RANSAC with refinement).
        threshold: inlier threshold in pixels; None uses Slime's defaults (15 px for H, 3 px for F).
            Each backend applies it to its own error (Slime: two-sided / max epipolar distance;
            MAGSAC++: the sigma bound; PoseLib: one-sided reprojection / Sampson error).
        seed: random seed (Slime and PoseLib; OpenCV seeds MAGSAC++ itself).

    Returns:
        GeometryResult; with fewer correspondences than the minimal sample (4 for H, 8 for F) or when
        the backend finds no model, model is None and no correspondence is an inlier.

    Raises:
        ConfigError: unknown kind or backend, or a non-positive threshold.
    """
    if kind not in KINDS:
        raise ConfigError(f"unknown geometry kind {kind!r}; choose one of {KINDS}")
    if backend not in BACKENDS:
        raise ConfigError(f"unknown RANSAC backend {backend!r}; choose one of {BACKENDS}")
    if threshold is None:
        cfg_cls = HomographyRansacConfig if kind == "homography" else FundamentalRansacConfig
        threshold = cfg_cls.threshold
    if not threshold > 0:
        raise ConfigError(f"threshold must be > 0, got {threshold}")
    x0 = np.ascontiguousarray(np.asarray(x0, dtype=np.float64).reshape(-1, 2))
    x1 = np.ascontiguousarray(np.asarray(x1, dtype=np.float64).reshape(-1, 2))
    if x0.shape != x1.shape:
        raise ValueError(f"x0 and x1 must have the same shape, got {x0.shape} and {x1.shape}")
    info = {"backend": backend, "threshold": float(threshold)}
    if len(x0) < _MIN_SAMPLE[kind]:
        info["reason"] = f"{len(x0)} correspondences, fewer than {_MIN_SAMPLE[kind]}"
        return GeometryResult(kind, None, np.zeros(len(x0), dtype=bool), info)
    if backend == "slime":
        if kind == "homography":
            return ransac_homography(x0, x1, {"threshold": threshold}, seed)
        return ransac_fundamental(x0, x1, {"threshold": threshold}, seed)
    if backend == "magsac":
        model, inliers = _magsac(x0, x1, kind, threshold)
    else:
        model, inliers = _poselib(x0, x1, kind, threshold, seed)
    if model is not None:
        scale = model[2, 2] if kind == "homography" and abs(model[2, 2]) > 1e-12 else np.linalg.norm(model)
        model = model / scale
    info["num_inliers"] = int(inliers.sum())
    return GeometryResult(kind, model, inliers, info)
