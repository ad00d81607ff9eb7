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


def confidence_of(scores: np.ndarray) -> np.ndarray:
    """Confidences in (0, 1], higher is better, from dissimilarity scores d (lower is better): ``1 / (1 + d)``
    for d >= 0 (negative d count as 0). Strictly decreasing in d, so it ranks the matches exactly as the scores
    do: 1 for d = 0, 0.5 for d = 1. The matching scores of ``slime hloc`` are these values too.

    Args:
        scores: (K,) dissimilarities.

    Returns:
        (K,) float64 confidences.
    """
    return 1.0 / (1.0 + np.maximum(np.asarray(scores, dtype=np.float64), 0.0))


@dataclass
class MatchResult:
    """Correspondences between two images, in original-image pixel coordinates.

    Attributes:
        keypoints0: (K, 2) float64 (x, y) in image 0; the centre of the top-left pixel is (0, 0).
        keypoints1: (K, 2) float64 (x, y) in image 1.
        scores: (K,) float64 match dissimilarity (lower is better); :attr:`confidence` is the same ranking as
            a confidence (higher is better).
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

    @property
    def confidence(self) -> np.ndarray:
        """(K,) float64 confidences in (0, 1], higher is better: ``1 / (1 + scores)`` (:func:`confidence_of`)."""
        return confidence_of(self.scores)

    @property
    def num_inliers(self) -> int | None:
        """How many matches the post-processing RANSAC kept, or None when it did not run."""
        return None if self.inliers is None else int(np.count_nonzero(self.inliers))

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict with the keys of other matching libraries (kornia, vismatch), numpy arrays:

        - ``keypoints0``, ``keypoints1`` (K, 2) and their aliases ``matched_kpts0``, ``matched_kpts1``: the
          matched keypoints, original pixels, top-left pixel centre (0, 0); ``num_matches``: K;
        - ``confidence`` (K,), higher is better; ``scores`` (K,), the dissimilarities (lower is better);
        - ``inliers`` (K,) bool, ``inlier_kpts0``, ``inlier_kpts1`` (N, 2), ``num_inliers`` N: the matches the
          post-processing RANSAC kept, each None when no RANSAC ran;
        - ``H`` (image 0 -> 1) or ``F`` (x1^T F x0 = 0), 3x3, when that RANSAC estimated one, else None;
        - ``image_sizes``: ((W, H), (W, H)) or None.
        """
        model = None if self.model is None else np.asarray(self.model, dtype=np.float64)
        inliers = None if self.inliers is None else np.asarray(self.inliers, dtype=bool)
        return {
            "keypoints0": self.keypoints0,
            "keypoints1": self.keypoints1,
            "matched_kpts0": self.keypoints0,
            "matched_kpts1": self.keypoints1,
            "num_matches": len(self),
            "confidence": self.confidence,
            "scores": self.scores,
            "inliers": inliers,
            "inlier_kpts0": None if inliers is None else self.keypoints0[inliers],
            "inlier_kpts1": None if inliers is None else self.keypoints1[inliers],
            "num_inliers": self.num_inliers,
            "H": model if self.geometry_kind == "homography" else None,
            "F": model if self.geometry_kind == "fundamental" else None,
            "image_sizes": self.image_sizes,
        }

    def indexed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-image keypoints and the matches as index pairs, as detector + matcher libraries give them.

        A keypoint may take part in several matches (Slime matches overlapping blocks and tiles); each distinct
        position appears once, in lexicographic (x, y) order.

        Returns:
            keypoints0 (N0, 2) and keypoints1 (N1, 2) float64, the distinct matched positions of each image, and
            matches (K, 2) int64: for match k, ``keypoints0[matches[k, 0]] == self.keypoints0[k]`` and
            ``keypoints1[matches[k, 1]] == self.keypoints1[k]`` (match order kept).
        """
        unique0, index0 = np.unique(self.keypoints0, axis=0, return_inverse=True)
        unique1, index1 = np.unique(self.keypoints1, axis=0, return_inverse=True)
        matches = np.stack([index0.reshape(-1), index1.reshape(-1)], axis=1).astype(np.int64)
        return unique0.reshape(-1, 2), unique1.reshape(-1, 2), matches

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
