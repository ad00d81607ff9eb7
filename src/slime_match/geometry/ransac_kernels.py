"""Compiled loops of the RANSACs (numba): Floyd subset sampling, the sample distance test, minimal 4-point
homographies and the homography inlier test.

Slime runs the homography RANSAC on hundreds of small problems per image pair, millions of samples in all; in
numpy each step is many calls on arrays of a few thousand rows and the call overhead dominates. Here each step
is one pass.

Correspondences are (N, 4) rows ``(x0, y0, x1, y1)`` in pixels; sample or model r reads its points from the rows
starting at ``start[r]`` (the first row of its problem).
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from slime_match.geometry.homography import _EPS

from .._runtime.compiled import kernel


@kernel
def floyd_subsets(u, n):
    """(R, k) int64 Floyd k-subsets of ``range(n[r])`` (see ``sampling.sample_subsets_varying``), drawn from the
    (k, R) uniforms u in [0, 1): step i of row r takes ``t = floor(u[i, r] (j + 1))`` for ``j = n[r] - k + i``,
    or j when t is already taken."""
    k, count = u.shape
    out = np.empty((count, k), np.int64)
    for r in range(count):
        for i in range(k):
            j = n[r] - k + i
            t = min(np.int64(np.floor(u[i, r] * (j + 1))), j)
            for q in range(i):
                if out[r, q] == t:
                    t = j
                    break
            out[r, i] = t
    return out


@kernel
def far_samples(rows, start, index, t):
    """(R,) whether every two correspondences of sample r (rows ``start[r] + index[r]``) are farther than t
    pixels apart in both images."""
    out = np.empty(len(index), np.bool_)
    k = index.shape[1]
    for r in range(len(index)):
        far = True
        for a in range(k):
            p = rows[start[r] + index[r, a]]
            for b in range(a + 1, k):
                q = rows[start[r] + index[r, b]]
                d0 = (p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2
                d1 = (p[2] - q[2]) ** 2 + (p[3] - q[3]) ** 2
                far &= math.sqrt(min(d0, d1)) > t
        out[r] = far
    return out


@kernel
def _normalized(pts, col, out):
    """Hartley normalisation (as ``homography._normalization``) of the 4 points ``pts[:, col:col + 2]`` into
    out (4, 2): centroid at the origin, mean distance sqrt(2). Returns the centroid and the scale."""
    cx = (pts[0, col] + pts[1, col] + pts[2, col] + pts[3, col]) / 4
    cy = (pts[0, col + 1] + pts[1, col + 1] + pts[2, col + 1] + pts[3, col + 1]) / 4
    dist = 0.0
    for i in range(4):
        dist += math.sqrt((pts[i, col] - cx) ** 2 + (pts[i, col + 1] - cy) ** 2)
    dist /= 4
    scale = math.sqrt(2.0) / dist if dist > _EPS else 1.0
    for i in range(4):
        out[i, 0] = scale * (pts[i, col] - cx)
        out[i, 1] = scale * (pts[i, col + 1] - cy)
    return cx, cy, scale


@kernel
def _dlt_rows(p, q, a):
    """The (12, 9) DLT matrix a of ``q x (H p) = 0`` for (4, 2) normalised points p, q (the rows of
    ``homography._dlt_matrix``, grouped by kind): rows i, 4 + i, 8 + i of point i, the third being
    ``-(u row0 + v row1)`` for q = (u, v)."""
    a[:] = 0.0
    for i in range(4):
        x, y, u, v = p[i, 0], p[i, 1], q[i, 0], q[i, 1]
        for c, pc in enumerate((x, y, 1.0)):
            a[i, 3 + c] = -pc  # row0 = [0, -p, v p]
            a[i, 6 + c] = v * pc
            a[4 + i, c] = pc  # row1 = [p, 0, -u p]
            a[4 + i, 6 + c] = -u * pc
            a[8 + i, c] = -v * pc  # row2 = [-v p, u p, 0]
            a[8 + i, 3 + c] = u * pc


@kernel
def _dot(a, b, i, j, lo):
    """Sum over rows r >= lo of ``a[r, i] b[r, j]``."""
    s = 0.0
    for r in range(lo, a.shape[0]):
        s += a[r, i] * b[r, j]
    return s


@kernel
def _null_vector(a, b, h):
    """Unit null vector h (9,) of the first 8 rows of a (12, 9), of rank 8: the last column of Q in the
    Householder QR of their transpose. b (9, 9) is overwritten: rows j.. of column j with the reflector ``v_j``
    (j < 8), b[j, 8] with its factor ``2 / |v_j|^2``."""
    for i in range(9):
        for j in range(8):
            b[i, j] = a[j, i]
    for j in range(8):
        norm = math.sqrt(_dot(b, b, j, j, j))
        b[j, 8] = 0.0
        if norm == 0:
            continue
        b[j, j] -= (-norm if b[j, j] >= 0 else norm)  # v_j = x - alpha e_j, alpha = -sign(x_j) |x|
        b[j, 8] = 2.0 / _dot(b, b, j, j, j)
        for c in range(j + 1, 8):
            f = b[j, 8] * _dot(b, b, j, c, j)
            for r in range(j, 9):
                b[r, c] -= f * b[r, j]
    h[:] = 0.0
    h[8] = 1.0
    for j in range(7, -1, -1):  # h = Q e_8 = H_0 ... H_7 e_8
        f = 0.0
        for r in range(j, 9):
            f += b[r, j] * h[r]
        f *= b[j, 8]
        for r in range(j, 9):
            h[r] -= f * b[r, j]


@kernel
def _second_singular_at_least(a, h, t, m):
    """Whether the second smallest singular value of a (12, 9), whose smallest is 0 with unit singular vector h,
    is >= t: the Cholesky factorisation of ``a^T a + (1 + t^2) h h^T - t^2 I`` (m (9, 9) its workspace) succeeds."""
    if t <= 0:
        return True
    t2 = t * t
    for i in range(9):
        for j in range(i + 1):
            m[i, j] = _dot(a, a, i, j, 0) + (1 + t2) * h[i] * h[j]
        m[i, i] -= t2
    for j in range(9):  # in place, lower triangle
        d = m[j, j]
        for c in range(j):
            d -= m[j, c] * m[j, c]
        if not d > 0:
            return False
        m[j, j] = math.sqrt(d)
        for i in range(j + 1, 9):
            f = m[i, j]
            for c in range(j):
                f -= m[i, c] * m[j, c]
            m[i, j] = f / m[j, j]
    return True


@kernel
def minimal_homographies(rows, start, index, degeneracy):
    """Normalised DLT of each 4-point sample r (rows ``start[r] + index[r]``).

    Returns:
        (R, 3, 3) homographies mapping x0 -> x1 with unit Frobenius norm, and (R,) whether each sample is
        non-degenerate: the 2nd smallest singular value of its (12, 9) normalised DLT matrix is >= ``degeneracy``
        (the model is zero otherwise).
    """
    count = len(index)
    hom = np.zeros((count, 3, 3))
    ok = np.zeros(count, np.bool_)
    pts = np.empty((4, 4))
    p, q = np.empty((4, 2)), np.empty((4, 2))
    a, b, m, hn = np.empty((12, 9)), np.empty((9, 9)), np.empty((9, 9)), np.empty(9)
    for r in range(count):
        for i in range(4):
            pts[i] = rows[start[r] + index[r, i]]
        cx0, cy0, s0 = _normalized(pts, 0, p)
        cx1, cy1, s1 = _normalized(pts, 2, q)
        _dlt_rows(p, q, a)
        _null_vector(a, b, hn)
        if not _second_singular_at_least(a, hn, degeneracy, m):
            continue
        g = hom[r]  # T1^-1 Hn T0 for the similarities T = [[s, 0, -s cx], [0, s, -s cy], [0, 0, 1]]
        for i in range(3):
            g[i, 0] = s0 * hn[3 * i]
            g[i, 1] = s0 * hn[3 * i + 1]
            g[i, 2] = hn[3 * i + 2] - g[i, 0] * cx0 - g[i, 1] * cy0
        for c in range(3):
            g[0, c] = g[0, c] / s1 + cx1 * g[2, c]
            g[1, c] = g[1, c] / s1 + cy1 * g[2, c]
        norm = 0.0
        for i in range(3):
            for c in range(3):
                norm += g[i, c] * g[i, c]
        g /= max(math.sqrt(norm), _EPS)
        ok[r] = True
    return hom, ok


@kernel
def _inlier(h, g, side, x0, y0, x1, y1, t2):
    """Whether (x0, y0) -> (x1, y1) is an inlier of h with adjugate g: two-sided error below sqrt(t2), and
    ``side * w > 0`` for ``w`` the third coordinate of ``H [x0; 1]``. Without divisions nor square roots:
    ``|x1 - p / w| < t`` iff ``|x1 w - p|^2 < t^2 w^2`` for ``(p, w) = H [x0; 1]``, and likewise through g."""
    px = h[0, 0] * x0 + h[0, 1] * y0 + h[0, 2]
    py = h[1, 0] * x0 + h[1, 1] * y0 + h[1, 2]
    w = h[2, 0] * x0 + h[2, 1] * y0 + h[2, 2]
    ex = x1 * w - px
    ey = y1 * w - py
    if not (ex * ex + ey * ey < t2 * w * w and w * side > 0):
        return False
    px = g[0, 0] * x1 + g[0, 1] * y1 + g[0, 2]
    py = g[1, 0] * x1 + g[1, 1] * y1 + g[1, 2]
    w = g[2, 0] * x1 + g[2, 1] * y1 + g[2, 2]
    ex = x0 * w - px
    ey = y0 * w - py
    return ex * ex + ey * ey < t2 * w * w and w != 0


@kernel
def _adjugate(h, g):
    """g (3, 3) = adjugate of h (3, 3), an inverse up to scale: column i is ``h[i + 1] x h[i + 2]`` (rows mod 3)."""
    for i in range(3):
        a, b = h[(i + 1) % 3], h[(i + 2) % 3]
        g[0, i] = a[1] * b[2] - a[2] * b[1]
        g[1, i] = a[2] * b[0] - a[0] * b[2]
        g[2, i] = a[0] * b[1] - a[1] * b[0]


@kernel
def inlier_counts(h, side, rows, start, n, t):
    """(M,) int64 inliers (see ``_inlier``, t in pixels) of each homography h[m] (M, 3, 3) with side[m] (M,) among
    its n[m] rows from start[m]."""
    out = np.zeros(len(h), np.int64)
    g = np.empty((3, 3))
    for m in range(len(h)):
        _adjugate(h[m], g)
        for k in range(start[m], start[m] + n[m]):
            out[m] += _inlier(h[m], g, side[m], rows[k, 0], rows[k, 1], rows[k, 2], rows[k, 3], t * t)
    return out


@kernel
def inlier_mask(h, side, rows, t):
    """(K,) bool inliers (see ``_inlier``, t in pixels) of one homography h (3, 3) with side +1/-1 among rows."""
    out = np.empty(len(rows), np.bool_)
    g = np.empty((3, 3))
    _adjugate(h, g)
    for k in range(len(rows)):
        out[k] = _inlier(h, g, side, rows[k, 0], rows[k, 1], rows[k, 2], rows[k, 3], t * t)
    return out


@cache
def warm_up() -> None:
    """Load these compiled loops in this process, once (from numba's on-disk cache, or compiled on first use: a
    few seconds), with the argument types the RANSACs pass. Call it before forking workers that run RANSACs, or
    each of them pays it."""
    rows = np.random.default_rng(0).uniform(0, 100, (8, 4))
    start = np.zeros(3, np.int64)
    index = floyd_subsets(np.full((4, 3), 0.5), np.full(3, 8, np.int64))
    far_samples(rows, start, index, 1.0)
    h, _ = minimal_homographies(rows, start, index, 0.05)
    inlier_counts(h, np.ones(3), rows, start, np.full(3, 8, np.int64), 1.0)
    inlier_mask(h[0], 1.0, rows, 1.0)
