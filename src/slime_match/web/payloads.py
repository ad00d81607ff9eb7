"""What the viewer draws, as JSON: a pair's matches (``matches.npz`` + ``summary.json``) and Slime's stage
layers (``stages.npz``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..io import load_npz
from ..result import MatchResult

# the stage layers, in the order of the method, with the stages.npz arrays each reads
STAGE_LAYERS = {
    "blocks": "blocks and their scales (cores)",
    "tiles": "full-resolution tiles",
    "planes": "block-pair planes M_l (colour = plane)",
    "superset": "superset H of each tile pair",
    "fbar": "F-bar: epipolar-consistent sets",
    "ftheta": "F^theta: fused, orientation-filtered sets",
    "tile_matches": "tile matches at full resolution",
    "final": "final matches (after the global DTM)",
}


def _points(array: np.ndarray) -> list[list[float]]:
    return np.round(np.asarray(array, np.float64).reshape(-1, 2), 2).tolist()


def matches_payload(folder: Path) -> dict[str, Any]:
    """The matches of a pair folder (``matches.npz`` and its ``summary.json``) for the viewer."""
    result = MatchResult.load(folder / "matches.npz")
    summary = result.summary
    payload: dict[str, Any] = {
        "count": len(result),
        "keypoints0": _points(result.keypoints0),
        "keypoints1": _points(result.keypoints1),
        "scores": np.round(result.scores, 5).tolist(),
        "confidence": np.round(result.confidence, 5).tolist(),
        "inliers": None if result.inliers is None else np.asarray(result.inliers, bool).astype(int).tolist(),
        "kind": result.geometry_kind,
        "model": None if result.model is None else np.asarray(result.model, np.float64).tolist(),
        "counts": summary.get("counts", {}),
        "seconds": summary.get("seconds", {}),
        "method": summary.get("method"),
        "image_sizes": summary.get("image_sizes"),
        "warnings": summary.get("warnings", []),
        "has_stages": (folder / "stages.npz").is_file(),
    }
    return payload


def _boxes(boxes: np.ndarray) -> list[list[float]]:
    return np.round(np.asarray(boxes, np.float64).reshape(-1, 5), 2).tolist()


def _sets(data: dict[str, np.ndarray], name: str) -> dict[str, Any]:
    """A saved TileSets: its entries' points and, per entry, the set; per set its plane and tile pair."""
    indptr, rows = data[f"{name}_indptr"], data[f"{name}_indices"]
    set_of = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    layer = {"xy0": _points(data["table_xy0"][rows]), "xy1": _points(data["table_xy1"][rows]),
             "label": set_of.tolist(), "sets": int(len(indptr) - 1)}
    if f"{name}_plane" in data:
        layer["set_plane"] = np.asarray(data[f"{name}_plane"]).astype(int).tolist()
    if f"{name}_tile0" in data and f"{name}_tile1" in data:
        layer["set_tiles"] = np.stack([data[f"{name}_tile0"], data[f"{name}_tile1"]], 1).astype(int).tolist()
    return layer


def stages_payload(folder: Path) -> dict[str, Any]:
    """Slime's stages of a pair folder (``stages.npz``, with the counts and seconds of ``summary.json``) as
    layers: boxes (blocks, tiles) or labelled matches (the others); ``planes`` also holds each plane's
    homography and block pair, and where the stages have them its image-0 block's corners and the (tilt,
    angle) of the simulated view that block belongs to, for the viewer's hover."""
    data = load_npz(folder / "stages.npz", "stages file", ("blocks0", "blocks1", "tiles0", "tiles1"),
                    hint="; it is written by a Slime match with stages kept")
    layers: dict[str, Any] = {}
    for name in ("blocks", "tiles"):
        layers[name] = {"boxes0": _boxes(data[f"{name}0"]), "boxes1": _boxes(data[f"{name}1"])}
    if "block_matches_xy0" in data:
        layers["planes"] = {"xy0": _points(data["block_matches_xy0"]), "xy1": _points(data["block_matches_xy1"]),
                            "label": np.asarray(data["block_matches_plane"]).astype(int).tolist(),
                            "H": np.asarray(data["planes_H"], np.float64).tolist(),
                            "block_pairs": np.asarray(data["planes_pairs"]).astype(int).tolist()}
        if "planes_corners0" in data and "planes_view" in data:  # image 0's block: its outline, its view
            layers["planes"]["corners0"] = np.round(np.asarray(data["planes_corners0"], np.float64), 2).tolist()
            layers["planes"]["views"] = np.asarray(data["planes_view"], np.float64).tolist()
    for name in ("superset", "fbar", "ftheta"):
        if f"{name}_indptr" in data and "table_xy0" in data:
            layers[name] = _sets(data, name)
    for name in ("tile_matches", "final"):
        if f"{name}_xy0" in data:
            layers[name] = {"xy0": _points(data[f"{name}_xy0"]), "xy1": _points(data[f"{name}_xy1"])}
    summary_file = folder / "summary.json"
    summary = json.loads(summary_file.read_text()) if summary_file.is_file() else {}
    return {"layers": layers, "titles": {k: v for k, v in STAGE_LAYERS.items() if k in layers},
            "counts": summary.get("counts", {}), "seconds": summary.get("seconds", {})}
