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
        "decisions": decision_lines(summary.get("decisions", {})),
        "has_stages": (folder / "stages.npz").is_file(),
    }
    return payload


def decision_lines(decisions: dict[str, Any]) -> list[str]:
    """``summary.json``'s ``decisions`` in words, one line each: the method ``auto`` took, the quarter turn,
    the rotation fallback, the simulated views (the decision and why, then each step tried), Slime's epipolar
    vote, its block detection and matching, the planes of a pooled second base, and the frame of its final DTM."""
    lines = []
    if "method" in decisions:
        lines.append(f"method: {decisions['method']}")
    if "quarter_turns" in decisions:
        lines.append(f"quarter turns: {decisions['quarter_turns']['reason']}")
    if "rotation_fallback" in decisions:
        lines.append(f"rotation fallback: {decisions['rotation_fallback']['reason']}")
    views = decisions.get("views")
    if views:
        lines.append(f"simulated views ({views['mode']}, of {_VIEWED[views.get('images', 'image0')]}): "
                     f"{views.get('decision', '')}{': ' if views.get('decision') else ''}{views['reason']}")
        for step in views.get("tried", []):
            line = f"  image {step['image']}, tilt {step['tilt']:g}: {step['views']} views"
            if step.get("screens") or step.get("probes"):  # matches of a view's finest level consistent with one F
                found = [f"best {name} {count} consistent matches at {angle} deg" for name, counts in
                         (("screen", step.get("screens")), ("probe", step.get("probes"))) if counts
                         for angle, count in [max(counts.items(), key=lambda item: item[1])]]
                line += f" ({step['paired']} paired after their probes; {', '.join(found)})"
            if "planes" in step:
                angles = ", ".join(f"{count} at {angle} deg" for angle, count in step["ftheta_by_angle"].items())
                line += f", {step['planes']} planes"
                if "support" in step:  # F^theta of the image's branch once the step joined it
                    line += f", F^theta with them {step['support']}"
                    if step.get("on_views") is not None:
                        line += f" ({step['on_views']} on the views' planes)"
                line += f", {step['ftheta_matches']} matches kept in F^theta" + (f" ({angles})" if angles else "")
            lines.append(line)
    if "vote" in decisions:
        lines.append(f"epipolar vote: {decisions['vote']} ({decisions['vote_reason']})")
    if "detection" in decisions:
        lines.append(f"blocks: {decisions['detection']} detection, matched by {decisions['block_matching']}")
    if "pool" in decisions:
        lines.append(f"pooled base: {decisions['pool']}")
    if "global_dtm" in decisions:
        lines.append(f"final DTM: {decisions['global_dtm']}")
    return lines


_VIEWED = {"image0": "image 0", "image1": "image 1", "both": "both images"}


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
    homography and block pair, and where the stages have them its blocks' corners in each image and the (tilt,
    angle) of the simulated view each block belongs to, for the viewer's hover."""
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
        for image in (0, 1):  # each image's block: its outline, its view (stages of earlier versions: image 0's)
            view = data.get(f"planes_view{image}", data.get("planes_view") if image == 0 else None)
            if f"planes_corners{image}" in data and view is not None:
                corners = np.round(np.asarray(data[f"planes_corners{image}"], np.float64), 2).tolist()
                layers["planes"][f"corners{image}"] = corners
                layers["planes"][f"views{image}"] = np.asarray(view, np.float64).tolist()
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
