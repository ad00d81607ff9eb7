"""Scoring the predictions on one pair: its ground truth, correct matches, the RANSAC post-processing, the coverage
normalisers and the metrics of every method and threshold (correct matches, precision, coverage, accuracy
error, pose errors), and the standard protocol of the hard sets on the raw matches."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from slime_match.eval import metrics as M
from slime_match.eval.bench_config import BenchConfig
from slime_match.eval.datasets import Pair
from slime_match.eval.metrics import protocols as P
from slime_match.geometry.backends import estimate_geometry
from slime_match.geometry.fundamental import fundamental_8point
from slime_match.geometry.homography import homography_dlt

PLANAR_KINDS = ("homography",)
DISPARITY_GT_STEP = 8  # px grid of the disparity map used as GT correspondences (coverage normaliser)


@dataclass
class PairGT:
    """Ground truth of a pair in the form the metrics need (shapes are (H, W))."""

    pair: Pair
    shape0: tuple[int, int]
    shape1: tuple[int, int]
    gt_corrs: np.ndarray | None = None

    @property
    def planar(self) -> bool:
        return self.pair.kind in PLANAR_KINDS


def pair_gt(pair: Pair, images: tuple[np.ndarray, np.ndarray]) -> PairGT:
    """Shapes and GT correspondences (given ones, or a grid of the disparity map for stereo pairs)."""
    corrs = pair.corrs
    if pair.kind == "disparity":
        d = pair.disparity
        rows, cols = np.mgrid[0 : d.shape[0] : DISPARITY_GT_STEP, 0 : d.shape[1] : DISPARITY_GT_STEP]
        dv = d[rows, cols]
        ok = np.isfinite(dv) & (cols - dv >= 0)
        corrs = np.stack([cols[ok], rows[ok], cols[ok] - dv[ok], rows[ok]], 1).astype(np.float64)
    return PairGT(pair, images[0].shape[:2], images[1].shape[:2], corrs)


def correct_mask(gt: PairGT, x0: np.ndarray, x1: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """(K,) correct matches and (K,) matches with a GT verdict (False only for unknown disparity)."""
    p = gt.pair
    if p.kind == "homography":
        return M.correct_matches_homography(x0, x1, p.H, t, p.mask0, p.mask1), np.ones(len(x0), bool)
    if p.kind == "disparity":
        err = M.disparity_error(x0, x1, p.disparity)
        with np.errstate(invalid="ignore"):
            return err < t, np.isfinite(err)
    return M.correct_matches_fundamental(x0, x1, p.F, t, gt.gt_corrs), np.ones(len(x0), bool)


def filter_matches(
    x0: np.ndarray, x1: np.ndarray, threshold: str, kind: str, backend: str, seed: int
) -> tuple[np.ndarray, np.ndarray | None, str]:
    """Post-processing: (K,) kept mask, the (3, 3) model fitted to the kept matches (None if impossible)
    and its kind. "none" keeps all and fits least squares (normalised DLT / 8-point) to all of them."""
    keep = np.ones(len(x0), bool)
    model, model_kind = None, kind
    if threshold != "none":
        geo = estimate_geometry(x0, x1, kind, backend=backend, threshold=float(threshold), seed=seed)
        keep, model, model_kind = np.asarray(geo.inliers, bool), geo.model, geo.kind
    if kind == "fundamental" and model_kind != "fundamental":
        model = None  # planar degeneracy of a fundamental RANSAC: refit F below
    if model is None:
        n_min = 4 if kind == "homography" else 8
        if keep.sum() >= n_min:
            fit = homography_dlt if kind == "homography" else fundamental_8point
            model = fit(x0[keep], x1[keep])[0]
    return keep, model, kind


def _accuracy_error(gt: PairGT, model: np.ndarray | None, valid, step: int) -> float:
    if model is None:
        return math.inf
    if gt.planar:
        return M.homography_accuracy_error(model, gt.pair.H, valid[0], valid[1], step)
    return M.fundamental_accuracy_error(model, gt.pair.F, valid[0], valid[1])


def valid_areas(gt: PairGT, raw: dict[str, tuple[np.ndarray, np.ndarray]], t: float):
    """Coverage normalisers: planar = GT-mappable pixels; non-planar = dilated union of every method's
    correct raw matches plus the GT correspondences (whole images when that union is empty)."""
    p = gt.pair
    if gt.planar:
        return M.valid_area_homography(p.H, gt.shape0, gt.shape1, p.mask0, p.mask1)
    c0, c1 = [], []
    for x0, x1 in raw.values():
        ok = correct_mask(gt, x0, x1, t)[0]
        c0.append(x0[ok])
        c1.append(x1[ok])
    v0, v1 = M.valid_area_nonplanar(c0, c1, gt.shape0, gt.shape1, gt.gt_corrs, t)
    if not v0.any() or not v1.any():
        v0, v1 = np.ones(gt.shape0, bool), np.ones(gt.shape1, bool)
    return v0, v1


def evaluate_pair(
    gt: PairGT, raw: dict[str, tuple[np.ndarray, np.ndarray]], config: BenchConfig
) -> tuple[dict[str, dict[str, dict[str, Any]]], dict[str, Any]]:
    """Metrics of every method and threshold on one pair.

    Args:
        gt: the pair's ground truth.
        raw: method label -> (keypoints0 (K, 2), keypoints1 (K, 2)) raw matches, original frame.

    Returns:
        method -> threshold -> metrics dict, and the per-pair extras the maps need (valid areas, and per
        method and threshold the kept matches, correct mask and model).
    """
    t = config.t_perp
    valid = valid_areas(gt, raw, t)
    kind = "homography" if gt.planar else "fundamental"
    out: dict[str, dict[str, dict[str, Any]]] = {}
    extras: dict[str, Any] = {"valid": valid, "kept": {}}
    for label, (x0, x1) in raw.items():
        out[label] = {}
        for th in config.thresholds:
            keep, model, _ = filter_matches(x0, x1, th, kind, config.ransac_backend, config.seed)
            k0, k1 = x0[keep], x1[keep]
            ok, known = correct_mask(gt, k0, k1, t)
            n_known = int(known.sum())
            rec = {
                "n_matches": len(k0),
                "n_correct": int(ok.sum()),
                "precision": float(ok.sum() / n_known) if n_known else 0.0,
                "coverage": M.coverage(k0[ok], k1[ok], gt.shape0, gt.shape1, valid[0], valid[1], t),
                "error": _accuracy_error(gt, model, valid, config.homography_step),
                "model": None if model is None else np.asarray(model).tolist(),
            }
            if gt.pair.kind == "pose":
                sweep = M.pose_errors_sweep(
                    k0, k1, gt.pair.K0, gt.pair.K1, gt.pair.R, gt.pair.t, tuple(config.essential_thresholds)
                )
                rec["pose_errors"] = {f"{k:g}": v for k, v in sweep.items()}
            out[label][th] = rec
            extras["kept"][(label, th)] = (k0, k1, ok, model)
    return out, extras


def pair_protocol(dataset: str, gt: PairGT, config: BenchConfig) -> str | None:
    """The standard protocol of a pair of dataset spec ``dataset``: "evd" (homography GT) or "wxbs" (GT
    correspondences) when the dataset's name is in ``config.protocol_datasets``, else None."""
    if dataset.split(":")[0].strip().lower() not in config.protocol_datasets:
        return None
    if gt.pair.kind == "homography":
        return "evd"
    if gt.pair.kind == "fundamental" and gt.pair.corrs is not None:
        return "wxbs"
    return None


def evaluate_protocol(
    protocol: str, gt: PairGT, raw: dict[str, tuple[np.ndarray, np.ndarray]], config: BenchConfig
) -> dict[str, dict[str, Any]]:
    """Method label -> the protocol's result on its raw matches (:func:`~slime_match.eval.metrics.protocols.
    evd_protocol` or :func:`~slime_match.eval.metrics.protocols.wxbs_protocol`)."""
    out = {}
    for label, (x0, x1) in raw.items():
        if protocol == "evd":
            out[label] = P.evd_protocol(
                x0, x1, gt.pair.H, gt.shape0, gt.shape1, config.protocol_h_threshold, config.protocol_max_iters,
                config.homography_step, config.protocol_orders,
            )
        else:
            out[label] = P.wxbs_protocol(
                x0, x1, gt.pair.corrs, config.protocol_f_threshold, config.protocol_max_iters, config.protocol_orders
            )
    return out
