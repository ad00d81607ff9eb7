"""The routes of ``slime web`` for the geometry of the shown matches: RANSAC run again on a match's matches
(another method or threshold, only the matches above a confidence) without matching again, and image 0
warped by a homography into image 1's frame, for the page's overlay."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from fastapi import FastAPI, Request
from fastapi.responses import Response

from ..choices import RANSAC_CHOICES
from ..io import load_image
from ..result import MatchResult
from .api_errors import ApiError, body_object, json_body
from .image_checks import DECODING, image_size
from .state import WebState


def add_geometry_routes(app: FastAPI, state: WebState) -> None:
    @app.post("/api/ransac")
    async def ransac(request: Request):
        body = body_object(await json_body(request), "source", "method")
        return rerun_ransac(_source_folder(state, body["source"]) / "matches.npz", body["method"],
                            body.get("threshold"), body.get("min_confidence", 0.0))

    @app.post("/api/warp")
    async def warp(request: Request):
        body = body_object(await json_body(request), "image0", "image1", "H")
        path0, path1 = state.checked_image(body["image0"]), state.checked_image(body["image1"])
        H = _matrix(body["H"])
        width, height = image_size(path1, "image 1", state.max_pixels)
        with DECODING:
            image = np.clip(load_image(path0) * 255.0 + 0.5, 0, 255).astype(np.uint8)
            alpha = np.full(image.shape[:2], 255, np.uint8)
            rgba = np.dstack([image[:, :, ::-1], alpha])  # BGRA for OpenCV
            warped = cv2.warpPerspective(rgba, H, (width, height), flags=cv2.INTER_LINEAR,
                                         borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0, 0))
            ok, data = cv2.imencode(".png", warped)
        if not ok:
            raise ApiError("cannot encode the warped image", 500)
        return Response(data.tobytes(), media_type="image/png", headers={"Cache-Control": "no-store"})


def _source_folder(state: WebState, source: Any):
    """The pair folder of ``{"job": id}`` or ``{"run": name, "index": i}``."""
    if isinstance(source, dict) and isinstance(source.get("job"), str):
        return state.job_folder(source["job"])
    if isinstance(source, dict) and isinstance(source.get("run"), str) and isinstance(source.get("index"), int):
        return state.run_pair(source["run"], source["index"])[1]
    raise ApiError('source must be {"job": id} or {"run": name, "index": pair number}')


def _matrix(value: Any) -> np.ndarray:
    try:
        H = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        H = None
    if H is None or H.shape != (3, 3) or not np.all(np.isfinite(H)) or abs(np.linalg.det(H)) < 1e-12:
        raise ApiError("H must be an invertible 3x3 matrix of finite numbers")
    return H


def rerun_ransac(matches_file, method: Any, threshold: Any, min_confidence: Any) -> dict[str, Any]:
    """RANSAC ``method`` (a ``--ransac`` choice) with ``threshold`` px (None: the method's default) on the
    matches of ``matches_file`` whose confidence is at least ``min_confidence``.

    Returns:
        ``{"kind", "model", "inliers", "used", "threshold"}``: inliers over all the matches (0 for those below
        the confidence), ``used`` the number of matches given to RANSAC.
    """
    from ..geometry.backends import estimate_geometry

    if method not in RANSAC_CHOICES or method == "none":
        raise ApiError(f"method must be one of {', '.join(c for c in RANSAC_CHOICES if c != 'none')}")
    try:
        threshold = None if threshold in (None, "") else float(threshold)
        min_confidence = float(min_confidence)
    except (TypeError, ValueError):
        raise ApiError("threshold (px) and min_confidence must be numbers") from None
    if threshold is not None and not threshold > 0 or not 0 <= min_confidence <= 1:
        raise ApiError("threshold must be > 0 px and min_confidence in [0, 1]")
    result = MatchResult.load(matches_file)
    used = result.confidence >= min_confidence
    backend, _, kind = method.rpartition("-")
    geometry = estimate_geometry(result.keypoints0[used], result.keypoints1[used], kind, backend=backend or "slime",
                                 threshold=threshold)
    inliers = np.zeros(len(result), bool)
    inliers[np.flatnonzero(used)] = geometry.inliers
    return {"kind": geometry.kind, "model": None if geometry.model is None else geometry.model.tolist(),
            "inliers": inliers.astype(int).tolist(), "used": int(used.sum()),
            "threshold": geometry.info.get("threshold", threshold)}
