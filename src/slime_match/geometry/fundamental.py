"""Fundamental matrix primitives: normalised 8-point (single and batched), epipolar distance,
plane + parallax construction.

Convention: ``x1^T F x0 = 0`` for corresponding pixel points ``x0`` (image 0) and ``x1`` (image 1).
"""

from __future__ import annotations

import numpy as np

from slime_match.geometry.homography import _EPS, _apply, _normalization, _null_vector


def _homogeneous(x: np.ndarray) -> np.ndarray:
    return np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1)


def fundamental_8point_batch(x0: np.ndarray, x1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised 8-point algorithm for a batch of correspondence sets, rank 2 enforced.

    Args:
        x0: (B, K, 2) points in image 0, pixels, K >= 8.
        x1: (B, K, 2) corresponding points in image 1.

    Returns:
        (B, 3, 3) unit-Frobenius-norm rank-2 fundamental matrices and (B,) second smallest singular
        values of the normalised 8-point matrices (small for degenerate samples, e.g. all points
        on one plane).
    """
    x0 = np.asarray(x0, dtype=np.float64)
    x1 = np.asarray(x1, dtype=np.float64)
    if x0.shape != x1.shape or x0.ndim != 3 or x0.shape[-1] != 2:
        raise ValueError(f"expected two (B, K, 2) arrays, got {x0.shape} and {x1.shape}")
    if x0.shape[1] < 8:
        raise ValueError(f"the 8-point algorithm needs at least 8 correspondences, got {x0.shape[1]}")
    t0, t1 = _normalization(x0), _normalization(x1)
    p0, p1 = _homogeneous(_apply(t0, x0)), _homogeneous(_apply(t1, x1))
    a = (p1[..., :, None] * p0[..., None, :]).reshape(x0.shape[0], x0.shape[1], 9)
    f, sigma2 = _null_vector(a)
    u, s, vt = np.linalg.svd(f.reshape(-1, 3, 3))
    s[:, 2] = 0.0
    fn = u @ (s[:, :, None] * vt)
    fund = t1.swapaxes(1, 2) @ fn @ t0
    fund /= np.maximum(np.linalg.norm(fund, axis=(1, 2), keepdims=True), _EPS)
    return fund, sigma2


def fundamental_8point(x0: np.ndarray, x1: np.ndarray) -> tuple[np.ndarray, float]:
    """Normalised 8-point fundamental matrix from K >= 8 correspondences (least squares for K > 8).

    Args:
        x0: (K, 2) points in image 0, pixels.
        x1: (K, 2) corresponding points in image 1, pixels.

    Returns:
        (3, 3) rank-2 F with ``x1^T F x0 = 0`` and unit Frobenius norm, and the second smallest
        singular value of the normalised 8-point matrix.
    """
    fund, sigma2 = fundamental_8point_batch(np.asarray(x0)[None], np.asarray(x1)[None])
    return fund[0], float(sigma2[0])


def epipolar_distance_batch(f: np.ndarray, x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """Maximum point-to-epipolar-line distance for many fundamental matrices.

    Args:
        f: (B, 3, 3) fundamental matrices.
        x0: (B, K, 2) or (K, 2) points in image 0, pixels.
        x1: (B, K, 2) or (K, 2) points in image 1, pixels.

    Returns:
        (B, K) ``max(d(x1, F x0), d(x0, F^T x1))`` in pixels (inf for undefined lines).
    """
    x0 = np.broadcast_to(x0, (f.shape[0],) + x0.shape[-2:])
    x1 = np.broadcast_to(x1, (f.shape[0],) + x1.shape[-2:])
    ff = f[:, :, :, None]
    u0, v0, u1, v1 = x0[:, None, :, 0], x0[:, None, :, 1], x1[:, None, :, 0], x1[:, None, :, 1]
    l1 = ff[:, :, 0] * u0 + ff[:, :, 1] * v0 + ff[:, :, 2]  # (B, 3, K) epipolar lines in image 1
    l0 = ff[:, 0] * u1 + ff[:, 1] * v1 + ff[:, 2]  # (B, 3, K) epipolar lines in image 0
    alg = np.abs(l1[:, 0] * u1[:, 0] + l1[:, 1] * v1[:, 0] + l1[:, 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        d1 = alg / np.hypot(l1[:, 0], l1[:, 1])
        d0 = alg / np.hypot(l0[:, 0], l0[:, 1])
    d = np.maximum(d0, d1)
    d[~np.isfinite(d)] = np.inf
    return d


def epipolar_distance(f: np.ndarray, x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """Maximum of the two point-to-epipolar-line distances (paper Eq. max_epi_error, true distances).

    Args:
        f: (3, 3) fundamental matrix with ``x1^T F x0 = 0``.
        x0: (K, 2) points in image 0, pixels.
        x1: (K, 2) points in image 1, pixels.

    Returns:
        (K,) distances in pixels: ``max(|x1^T F x0| / |(F x0)_{1,2}|, |x1^T F x0| / |(F^T x1)_{1,2}|)``.
    """
    x0 = np.asarray(x0, dtype=np.float64)
    x1 = np.asarray(x1, dtype=np.float64)
    return epipolar_distance_batch(np.asarray(f, dtype=np.float64)[None], x0, x1)[0]


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) cross-product matrices of (..., 3) vectors."""
    z = np.zeros(v.shape[:-1])
    return np.stack(
        [
            np.stack([z, -v[..., 2], v[..., 1]], axis=-1),
            np.stack([v[..., 2], z, -v[..., 0]], axis=-1),
            np.stack([-v[..., 1], v[..., 0], z], axis=-1),
        ],
        axis=-2,
    )


def fundamental_from_homography_and_parallax_batch(
    h: np.ndarray, x0: np.ndarray, x1: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Plane + parallax: F = [e']_x H with the epipole from two off-plane correspondences.

    Each off-plane correspondence ``(x0, x1)`` gives the epipolar line ``(H x0) x x1`` through e';
    the two lines meet at e'.

    Args:
        h: (3, 3) or (B, 3, 3) homographies mapping image 0 -> image 1 (the plane).
        x0: (B, 2, 2) two off-plane points in image 0 per model, pixels.
        x1: (B, 2, 2) the corresponding points in image 1.

    Returns:
        (B, 3, 3) unit-norm F and a (B,) bool mask, False where the construction is degenerate
        (a point on the plane, or both points on the same epipolar line).
    """
    p0, p1 = _homogeneous(np.asarray(x0, dtype=np.float64)), _homogeneous(np.asarray(x1, dtype=np.float64))
    h = np.broadcast_to(h, (p0.shape[0], 3, 3))
    hx = np.einsum("bij,bkj->bki", h, p0)
    hx = hx / np.maximum(np.linalg.norm(hx, axis=-1, keepdims=True), _EPS)
    p1 = p1 / np.linalg.norm(p1, axis=-1, keepdims=True)
    lines = np.cross(hx, p1)  # (B, 2, 3)
    lnorm = np.linalg.norm(lines, axis=-1)
    lines = lines / np.maximum(lnorm, _EPS)[..., None]
    e1 = np.cross(lines[:, 0], lines[:, 1])
    enorm = np.linalg.norm(e1, axis=-1)
    valid = (lnorm.min(axis=1) > 1e-9) & (enorm > 1e-9)
    fund = _skew(e1 / np.maximum(enorm, _EPS)[:, None]) @ h
    fund /= np.maximum(np.linalg.norm(fund, axis=(1, 2), keepdims=True), _EPS)
    return fund, valid


def fundamental_from_homography_and_parallax(h: np.ndarray, x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """Plane + parallax F = [e']_x H from a homography and two off-plane correspondences.

    Args:
        h: (3, 3) homography of a scene plane, image 0 -> image 1.
        x0: (2, 2) two off-plane points in image 0, pixels.
        x1: (2, 2) the corresponding points in image 1.

    Returns:
        (3, 3) unit-norm fundamental matrix with ``x1^T F x0 = 0``.

    Raises:
        ValueError: when a point lies on the plane or both lie on the same epipolar line.
    """
    fund, valid = fundamental_from_homography_and_parallax_batch(
        np.asarray(h, dtype=np.float64), np.asarray(x0)[None], np.asarray(x1)[None]
    )
    if not valid[0]:
        raise ValueError("degenerate plane + parallax configuration: the epipole is undefined")
    return fund[0]
