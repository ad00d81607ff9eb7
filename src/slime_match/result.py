"""MatchResult: what ``slime_match.match`` returns and ``slime match`` writes."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .io import load_npz, save_json, save_npz
from .types import GeometryResult


@dataclass
class MatchResult:
    """Correspondences between two images, in original-image pixel coordinates.

    Attributes:
        keypoints0: (K, 2) float64 (x, y) in image 0; the centre of the top-left pixel is (0, 0).
        keypoints1: (K, 2) float64 (x, y) in image 1.
        scores: (K,) float64 match dissimilarity (lower is better).
        inliers: (K,) bool mask of the post-processing RANSAC, or None when it did not run.
        geometry_kind: "homography" / "fundamental" for ``model``, or None.
        model: (3, 3) H (image 0 -> 1) or F (x1^T F x0 = 0) from the post-processing RANSAC, or None.
        summary: method, every parameter used, counts, per-stage seconds, warnings.
        stages: optional per-stage arrays (Slime's intermediate sets, for ``slime viz``).
        image_sizes: ((W, H), (W, H)) px of the original images, or None when unknown.
        working_sizes: ((w, h), (w, h)) px of the images as matched (``MatchConfig.min_side`` / ``max_side``
            resize them; the keypoints are mapped back to the original pixels), or None when unknown.
    """

    keypoints0: np.ndarray
    keypoints1: np.ndarray
    scores: np.ndarray
    inliers: np.ndarray | None = None
    geometry_kind: str | None = None
    model: np.ndarray | None = None
    summary: dict[str, Any] = field(default_factory=dict)
    stages: dict[str, np.ndarray] | None = None
    image_sizes: tuple[tuple[int, int], tuple[int, int]] | None = None
    working_sizes: tuple[tuple[int, int], tuple[int, int]] | None = None

    def __post_init__(self) -> None:
        self.keypoints0 = np.asarray(self.keypoints0, dtype=np.float64).reshape(-1, 2)
        self.keypoints1 = np.asarray(self.keypoints1, dtype=np.float64).reshape(-1, 2)
        self.scores = np.asarray(self.scores, dtype=np.float64).reshape(-1)
        if not (len(self.keypoints0) == len(self.keypoints1) == len(self.scores)):
            raise ValueError("keypoints0, keypoints1 and scores must have the same length")

    @property
    def working_factors(self) -> tuple[tuple[float, float], tuple[float, float]] | None:
        """((fx, fy), (fx, fy)): working px per original px of each image, per axis (None when unknown)."""
        if self.image_sizes is None or self.working_sizes is None:
            return None
        return tuple((w / W, h / H) for (w, h), (W, H) in zip(self.working_sizes, self.image_sizes, strict=True))

    def __len__(self) -> int:
        return int(self.keypoints0.shape[0])

    def __repr__(self) -> str:
        """One line (the arrays and the summary are attributes): counts, method, model, seconds."""
        parts = [f"{len(self)} matches"]
        if "method" in self.summary:
            parts.append(f"method={self.summary['method']!r}")
        if self.inliers is not None:
            parts.append(f"{int(np.sum(self.inliers))} inliers ({self.geometry_kind})")
        seconds = self.summary.get("seconds", {}).get("total")
        if seconds is not None:
            parts.append(f"{seconds:.2f} s")
        if self.summary.get("warnings"):
            parts.append(f"{len(self.summary['warnings'])} warning(s)")
        return f"MatchResult({', '.join(parts)})"

    def geometry(
        self, kind: str = "fundamental", backend: str = "slime", threshold: float = 3.0, seed: int = 0
    ) -> GeometryResult:
        """Robust two-view model of these matches (see ``slime_match.geometry.backends``)."""
        from .geometry.backends import estimate_geometry

        return estimate_geometry(self.keypoints0, self.keypoints1, kind, backend=backend, threshold=threshold,
                                 seed=seed)

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays of ``matches.npz``: keypoints0/1, scores, and inliers + H or F when RANSAC ran."""
        out = {"keypoints0": self.keypoints0, "keypoints1": self.keypoints1, "scores": self.scores}
        if self.inliers is not None:
            out["inliers"] = np.asarray(self.inliers, dtype=bool)
            if self.model is not None:
                out["H" if self.geometry_kind == "homography" else "F"] = np.asarray(self.model, np.float64)
        return out

    def save(self, path: str | os.PathLike) -> None:
        """Write the arrays to an .npz (atomically) and the summary next to it as ``<stem>.json``."""
        path = Path(path)
        save_npz(path, **self.arrays())
        if self.summary:
            save_json(path.with_suffix(".json"), self.summary)

    @classmethod
    def load(cls, path: str | os.PathLike) -> MatchResult:
        """Read a ``matches.npz`` written by :meth:`save` or by ``slime match``, with the summary beside it
        (``<stem>.json`` from :meth:`save`, else the folder's ``summary.json``) when there is one.

        Raises:
            SlimeMatchError: the file is missing, unreadable or not a matches file.
        """
        path = Path(path)
        data = load_npz(path, "matches file", ("keypoints0", "keypoints1", "scores"))
        kind = "homography" if "H" in data else "fundamental" if "F" in data else None
        model = data["H"] if "H" in data else data.get("F", None)
        arrays = (data["keypoints0"], data["keypoints1"], data["scores"], data.get("inliers", None), kind, model)
        summary_file = next((f for f in (path.with_suffix(".json"), path.parent / "summary.json") if f.is_file()),
                            None)
        summary = json.loads(summary_file.read_text()) if summary_file else {}
        sizes = [_pair_sizes(summary.get(key)) for key in ("image_sizes", "working_sizes")]
        return cls(*arrays, summary=summary, image_sizes=sizes[0], working_sizes=sizes[1])


def _pair_sizes(recorded: Any) -> tuple[tuple[int, int], tuple[int, int]] | None:
    """((W, H), (W, H)) from a summary's ``{"image0": [W, H], "image1": [W, H]}`` (None when absent)."""
    try:
        return tuple((int(recorded[k][0]), int(recorded[k][1])) for k in ("image0", "image1"))
    except (TypeError, KeyError, IndexError, ValueError):
        return None
