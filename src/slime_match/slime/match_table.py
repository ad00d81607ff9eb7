"""The match table: all block-pair matches of one image pair in original-image pixels (Secs. 3.3-3.8).

Every block pair l that gives a plane (Secs. 3.2-3.3) adds its matches ``M_l``; the later stages select sets
of the table's rows (plane memberships ``P_l``, tile sets, F-bar, F^theta).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .orientations import wrap_angle

__all__ = ["MatchTable", "deduplicate"]


@dataclass
class MatchTable:
    """All block-pair matches of one image pair, in original-image coordinates.

    Attributes:
        xy0: (M, 2) float64 keypoints in image 1, px.
        xy1: (M, 2) float64 keypoints in image 2, px.
        angle0: (M,) float64 patch orientations theta in image 1, radians.
        angle1: (M,) float64 patch orientations theta' in image 2, radians.
        scale0: (M,) float64 patch scales sigma in image 1, px.
        scale1: (M,) float64 patch scales sigma' in image 2, px.
        weight: (M,) float64 multiplicity (number of merged exact duplicates, 1 otherwise).
        source: (M,) int64 index of the block pair (plane) the match came from.
        score: (M,) float64 match dissimilarity, lower is better.
    """

    xy0: np.ndarray
    xy1: np.ndarray
    angle0: np.ndarray
    angle1: np.ndarray
    scale0: np.ndarray
    scale1: np.ndarray
    weight: np.ndarray
    source: np.ndarray
    score: np.ndarray

    def __post_init__(self) -> None:
        self.xy0 = np.asarray(self.xy0, dtype=np.float64).reshape(-1, 2)
        self.xy1 = np.asarray(self.xy1, dtype=np.float64).reshape(-1, 2)
        for name in ("angle0", "angle1", "scale0", "scale1", "weight", "score"):
            setattr(self, name, np.asarray(getattr(self, name), dtype=np.float64).reshape(-1))
        self.source = np.asarray(self.source, dtype=np.int64).reshape(-1)
        m = len(self.xy0)
        if any(len(getattr(self, f.name)) != m for f in fields(self)):
            raise ValueError("MatchTable: all fields must have the same length")

    def __len__(self) -> int:
        return int(self.xy0.shape[0])

    def subset(self, index: np.ndarray) -> MatchTable:
        """Rows selected by a boolean mask or an index array."""
        return MatchTable(*(getattr(self, f.name)[index] for f in fields(self)))

    @classmethod
    def concatenate(cls, tables: list[MatchTable]) -> MatchTable:
        """The rows of ``tables``, one after another."""
        return cls(*(np.concatenate([getattr(t, f.name) for t in tables]) for f in fields(cls)))

    def swapped(self) -> MatchTable:
        """The same matches with the two images' roles exchanged (image 1's keypoints first)."""
        return MatchTable(self.xy1, self.xy0, self.angle1, self.angle0, self.scale1, self.scale0, self.weight,
                          self.source, self.score)

    @property
    def rho(self) -> np.ndarray:
        """(M,) relative orientations theta' - theta wrapped to (-pi, pi]."""
        return wrap_angle(self.angle1 - self.angle0)


def deduplicate(table: MatchTable, tol: float = 1e-6) -> tuple[MatchTable, np.ndarray]:
    """Merge exact duplicate matches (same xy0 and xy1 up to ``tol`` px) into one weighted row.

    The merged row keeps the attributes of the first occurrence, the best (lowest) score, and the sum of the
    weights.

    Args:
        table: (M rows) match table.
        tol: coordinate quantum in px.

    Returns:
        The (U rows) deduplicated table and (M,) int64 ``inverse`` with ``table row i -> new row inverse[i]``.
    """
    if len(table) == 0:
        return table, np.zeros(0, np.int64)
    key = np.round(np.hstack([table.xy0, table.xy1]) / tol).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    out = table.subset(first)
    out.weight = np.bincount(inverse, weights=table.weight, minlength=len(first))
    out.score = np.full(len(first), np.inf)
    np.minimum.at(out.score, inverse, table.score)
    return out, inverse
