"""Correspondence sets of many RANSAC problems stored flat, and the exact test of whether a small problem has any
4-point sample passing the sample distance test."""

from __future__ import annotations

import numpy as np


def _pair_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...) distance between correspondences a and b (..., 4) = (x0, y0, x1, y1): the smaller of both images."""
    d = a - b
    d *= d
    return np.sqrt(np.minimum(d[..., 0] + d[..., 1], d[..., 2] + d[..., 3]))


def _has_far_quadruple(x: np.ndarray, t: float) -> bool:
    """Whether some 4 of the (n, 4) correspondences pass the sample distance test (``far_samples``).

    Such a sample is a 4-clique of the graph joining the pairs farther than t apart: an edge (i, j) whose
    common neighbours hold an edge. Memory and time grow as n^3 and n^4: meant for small n.
    """
    far = (_pair_gap(x[:, None], x[None]) > t).astype(np.float64)  # (n, n), zero diagonal
    common = far[:, None, :] * far[None, :, :]  # (n, n, n): k joined to both i and j
    return bool((((common @ far) * common).sum(axis=2) * far).any())


class _Stack:
    """Correspondence sets of many problems stored flat: problem p is rows ``offset[p]`` to ``offset[p] + n[p] - 1``
    of the (N, 4) rows (x0, y0, x1, y1), pixels."""

    def __init__(self, problems: list[tuple[np.ndarray, np.ndarray]]) -> None:
        xs0, xs1 = [], []
        for a, b in problems:
            a = np.asarray(a, dtype=np.float64).reshape(-1, 2)
            b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
            if a.shape != b.shape:
                raise ValueError(f"x0 and x1 must have the same shape, got {a.shape} and {b.shape}")
            xs0.append(a)
            xs1.append(b)
        self.x0s, self.x1s = xs0, xs1
        self.n = np.array([len(a) for a in xs0], dtype=np.int64)
        self.offset = np.concatenate([[0], np.cumsum(self.n)[:-1]]).astype(np.int64)
        empty = [np.zeros((0, 2))]
        self.rows = np.hstack([np.concatenate(xs0 + empty), np.concatenate(xs1 + empty)])  # (N, 4): x0 y0 x1 y1

    def without_far_sample(self, t: float, candidates: np.ndarray, max_n: int = 64) -> np.ndarray:
        """(P,) True for the candidate problems (4 <= n <= max_n) proven to hold no 4 correspondences pairwise
        farther than t: every sample of theirs fails the distance test."""
        check = np.flatnonzero(candidates & (self.n >= 4) & (self.n <= max_n))
        out = np.zeros(len(self.n), dtype=bool)
        out[check] = [not _has_far_quadruple(self.rows[self.offset[p]:self.offset[p] + self.n[p]], t) for p in check]
        return out
