"""The annotation tool's models: a homography per set of clicked pairs and a fundamental matrix of them all,
each refused with the reason when the pairs do not determine it (too few, on a line, or, for F, on one plane),
and every pair's residual to each model."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from ..errors import ConfigError
from ..eval.datasets.pair import fundamental_from_corrs

MIN_H, MIN_F = 4, 8  # pairs for a homography, for a fundamental matrix
LINE_PX = 1.0  # points whose spread across their best line is under this (px, RMS) lie on a line
PLANE_PX = 2.0  # pairs that one homography maps within this (px) lie on one plane
OFF_PLANE_F = 2  # pairs off the dominant plane that F needs: with fewer, its epipole is free


def corrs_array(pairs: list[dict[str, Any]], group: int | None = None) -> np.ndarray:
    """(M, 4) ``x0 y0 x1 y1`` of the visible pairs (of one set when ``group`` is given)."""
    rows = [[p["x0"], p["y0"], p["x1"], p["y1"]] for p in pairs
            if not p["occluded"] and (group is None or p["set"] == group)]
    return np.asarray(rows, np.float64).reshape(-1, 4)


def _on_a_line(points: np.ndarray) -> bool:
    """Whether (M, 2) points lie within :data:`LINE_PX` (RMS) of one line."""
    centred = points - points.mean(0)
    return float(np.linalg.svd(centred, compute_uv=False)[-1]) / np.sqrt(len(points)) < LINE_PX


def homography_check(corrs: np.ndarray) -> tuple[np.ndarray | None, str | None]:
    """(H image 0 -> 1 of all the correspondences by least squares, None) or (None, why it is undetermined)."""
    if len(corrs) < MIN_H:
        return None, f"H needs {MIN_H} pairs, there are {len(corrs)}"
    if _on_a_line(corrs[:, :2]) or _on_a_line(corrs[:, 2:]):
        return None, "H is undetermined: the points lie on a line"
    H, _ = cv2.findHomography(corrs[:, :2], corrs[:, 2:], 0)
    if H is None or not np.all(np.isfinite(H)) or abs(H[2, 2]) < 1e-12:
        return None, "H is undetermined: three of the points lie on a line"
    return H / H[2, 2], None


def fundamental_check(corrs: np.ndarray) -> tuple[np.ndarray | None, str | None]:
    """(F with ``x1^T F x0 = 0`` by the normalised 8-point algorithm that ``slime bench`` applies to a WxBS
    ``corrs.txt``, None) or (None, why the pairs do not determine it)."""
    if len(corrs) < MIN_F:
        return None, f"F needs {MIN_F} pairs, there are {len(corrs)}"
    if _on_a_line(corrs[:, :2]) or _on_a_line(corrs[:, 2:]):
        return None, "F refused: the points lie on a line"
    _, mask = cv2.findHomography(corrs[:, :2], corrs[:, 2:], cv2.RANSAC, PLANE_PX, maxIters=2000,
                                 confidence=0.999)
    on_plane = int(mask.sum()) if mask is not None else 0
    if len(corrs) - on_plane < OFF_PLANE_F:
        return None, (f"F refused: {on_plane} of the {len(corrs)} pairs lie on one plane (one homography maps "
                      f"them within {PLANE_PX:g} px), which leaves F undetermined; add at least {OFF_PLANE_F} "
                      "pairs off that plane (New set)")
    try:
        return fundamental_from_corrs(corrs), None
    except ConfigError as error:
        return None, f"F refused: {error}"


def transfer_errors(H: np.ndarray, corrs: np.ndarray) -> np.ndarray:
    """|H x0 - x1| in px of each correspondence."""
    x0 = np.c_[corrs[:, :2], np.ones(len(corrs))] @ H.T
    return np.linalg.norm(x0[:, :2] / x0[:, 2:3] - corrs[:, 2:], axis=1)


def epipolar_errors(F: np.ndarray, corrs: np.ndarray) -> np.ndarray:
    """Distance in px of each x1 to the epipolar line F x0 (in image 1)."""
    x0 = np.c_[corrs[:, :2], np.ones(len(corrs))]
    x1 = np.c_[corrs[:, 2:], np.ones(len(corrs))]
    lines = x0 @ F.T
    return np.abs(np.sum(lines * x1, axis=1)) / np.maximum(np.hypot(lines[:, 0], lines[:, 1]), 1e-12)


def fit(pairs: list[dict[str, Any]]) -> dict[str, Any]:
    """Each set's H, H and F of all visible pairs, why a model is missing (``why``: {"H", "F"}, and
    ``set_why`` per set), and every pair's residuals in px: to its set's H and to F (None where there is no
    model or the pair is occluded)."""
    sets = sorted({p["set"] for p in pairs})
    set_fits = {g: homography_check(corrs_array(pairs, g)) for g in sets}
    everything = corrs_array(pairs)
    (H, why_H), (F, why_F) = homography_check(everything), fundamental_check(everything)
    residual_H, residual_F = [], []
    for p in pairs:
        own = set_fits.get(p["set"], (None, None))[0]
        row = None if p["occluded"] else np.array([[p["x0"], p["y0"], p["x1"], p["y1"]]])
        residual_H.append(None if row is None or own is None else round(float(transfer_errors(own, row)[0]), 3))
        residual_F.append(None if row is None or F is None else round(float(epipolar_errors(F, row)[0]), 3))
    return {"visible": len(everything),
            "set_H": {str(g): None if h is None else h.tolist() for g, (h, _) in set_fits.items()},
            "set_why": {str(g): why for g, (_, why) in set_fits.items()},
            "H": None if H is None else H.tolist(), "F": None if F is None else F.tolist(),
            "why": {"H": why_H, "F": why_F},
            "residual_H": residual_H, "residual_F": residual_F,
            "min_pairs": {"H": MIN_H, "F": MIN_F}}
