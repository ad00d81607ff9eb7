"""Random k-subset sampling for RANSAC (Floyd's algorithm on all rows, a compiled loop)."""

from __future__ import annotations

import numpy as np

from slime_match.geometry.ransac_kernels import floyd_subsets


def sample_subsets_varying(rng: np.random.Generator, n: np.ndarray, k: int) -> np.ndarray:
    """Draw one uniform random k-subset of ``range(n[r])`` for every row r.

    Floyd's algorithm: for j = n-k, ..., n-1 draw t uniform in [0, j]; take t unless already taken,
    else take j. Each row is a uniformly distributed k-subset (the order inside a row is not random).

    Args:
        rng: numpy random generator.
        n: (R,) int population sizes, each >= k.
        k: subset size, >= 1.

    Returns:
        (R, k) int64 distinct indices per row, row r in ``[0, n[r])``.
    """
    n = np.asarray(n, dtype=np.int64)
    if k < 1 or np.any(n < k):
        raise ValueError(f"cannot draw {k} distinct indices from populations of size {n.min(initial=0)}")
    return floyd_subsets(rng.random((k, n.shape[0])), n)  # row i of the uniforms: step i of every subset


def sample_subsets(rng: np.random.Generator, n: int, k: int, count: int) -> np.ndarray:
    """Draw ``count`` uniform random k-subsets of ``range(n)`` at once.

    Args:
        rng: numpy random generator.
        n: population size, >= k.
        k: subset size, >= 1.
        count: number of subsets.

    Returns:
        (count, k) int64 indices, distinct within each row, in ``[0, n)``.
    """
    return sample_subsets_varying(rng, np.full(count, n, dtype=np.int64), k)
