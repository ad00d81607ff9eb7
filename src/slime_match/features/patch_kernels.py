"""Compiled per-patch loops (numba) of the weight-free feature path on CPU tensors.

The torch versions (:mod:`~slime_match.features.laf`, :mod:`~slime_match.features.gradients`,
:mod:`~slime_match.features.shape`) run a dozen whole-batch operations per stage, each writing an
(N, P, P) or (N, bins, P, P) temporary; on CPU their memory traffic and call overhead dominate. Here each
patch is one pass over its pixels, and only the per-patch results are written: bilinear patch sampling, the
Gaussian-weighted gradient second moments of Baumberg's shape step, the orientation histogram and the SIFT
cell histograms. Pixel arithmetic is float32 as in torch (same formulas, same order where it matters);
sums are accumulated in float64, so results agree with the torch versions to float rounding.

Conventions: patches are (N, P, P) float32, row ``i`` = patch y, column ``j`` = patch x; gradients use
replicated borders (kornia's ``spatial_gradient``); angles are ``atan2(gy, gx)`` in patch pixel
coordinates.
"""

from __future__ import annotations

import math

import numpy as np
from numba import types
from numba.extending import intrinsic

from .._runtime.compiled import vector_kernel


@intrinsic
def _fma(typingctx, a, b, c):
    """float32 ``a * b + c`` rounded once (LLVM's fma intrinsic)."""
    sig = types.float32(types.float32, types.float32, types.float32)
    return sig, lambda context, builder, signature, args: builder.fma(*args)


@vector_kernel
def sample_patches(flat, offset, height, width, affine, level, unit):
    """Bilinear patches (``grid_sample``, align_corners=True, border padding) from a flattened pyramid.

    Each patch row is two passes: its sample positions, corners and weights, then the gathers of the four
    corners. The sums are fused multiply-adds where torch's CPU kernels (the GEMM of the sample grid, the
    vectorised ``grid_sample``) fuse them, so the patches equal ``extract``'s torch path bit for bit on x86
    CPUs with FMA. A non-finite position reads the level's first pixel (never out of bounds).

    Args:
        flat: (T,) float32 pyramid levels, row-major, one after the other.
        offset, height, width: (L,) int64 start in ``flat`` and size of each level.
        affine: (N, 2, 3) float32 maps from unit patch coordinates ``(u, v, 1)`` to the level's normalised
            coordinates in [-1, 1] (x, y), as ``grid_sample`` reads them.
        level: (N,) int64 level of each patch.
        unit: (P,) float32 unit coordinates of the patch columns (and rows).

    Returns:
        (N, P, P) float32 patches.
    """
    n, p = affine.shape[0], unit.shape[0]
    out = np.empty((n, p, p), np.float32)
    one, zero = np.float32(1.0), np.float32(0.0)
    corner, step_x, step_y = np.empty(p, np.int64), np.empty(p, np.int64), np.empty(p, np.int64)
    fx, fy = np.empty(p, np.float32), np.empty(p, np.float32)
    for k in range(n):
        lv = level[k]
        base, h, w = offset[lv], height[lv], width[lv]
        half_w, half_h = np.float32((w - 1) / 2), np.float32((h - 1) / 2)
        max_x, max_y = np.float32(w - 1), np.float32(h - 1)
        a00, a01, a02 = affine[k, 0, 0], affine[k, 0, 1], affine[k, 0, 2]
        a10, a11, a12 = affine[k, 1, 0], affine[k, 1, 1], affine[k, 1, 2]
        for i in range(p):
            v = unit[i]
            for j in range(p):
                u = unit[j]
                x = (_fma(a01, v, a00 * u) + a02 + one) * half_w
                y = (_fma(a11, v, a10 * u) + a12 + one) * half_h
                x = min(x if x > zero else zero, max_x)  # noqa: FURB136 (NaN -> 0, unlike max)
                y = min(y if y > zero else zero, max_y)  # noqa: FURB136
                x0, y0 = np.floor(x), np.floor(y)
                fx[j], fy[j] = x - x0, y - y0
                ix, iy = int(x0), int(y0)
                corner[j] = base + iy * w + ix
                step_x[j] = 1 if ix + 1 < w else 0
                step_y[j] = w if iy + 1 < h else 0
            for j in range(p):
                c00 = corner[j]
                c10 = c00 + step_y[j]
                ex, ey = one - fx[j], one - fy[j]
                acc = _fma(flat[c00 + step_x[j]], fx[j] * ey, flat[c00] * (ex * ey))
                acc = _fma(flat[c10], ex * fy[j], acc)
                out[k, i, j] = _fma(flat[c10 + step_x[j]], fx[j] * fy[j], acc)
    return out


# atan(t) / t ~ polynomial in t^2 on |t| <= tan(pi / 8): least-squares minimax fit, max abs error of
# atan 7e-9 (float32 evaluation: 4e-8, ~1 ulp).
_ATAN_COEFFS = (0.999999983, -0.333328082, 0.199747311, -0.138545108, 0.079937824)
_C0, _C1, _C2, _C3, _C4 = (np.float32(c) for c in _ATAN_COEFFS)
_TAN_PI_8 = np.float32(math.tan(math.pi / 8))
_PI, _HALF_PI, _QUARTER_PI = np.float32(math.pi), np.float32(math.pi / 2), np.float32(math.pi / 4)


@vector_kernel
def _atan2(y, x):
    """float32 ``atan2(y, x)`` in (-pi, pi], branch-free (so that loops calling it vectorise); ~1 ulp."""
    ax, ay = abs(x), abs(y)
    hi, lo = max(ax, ay), min(ax, ay)
    t = lo / max(hi, np.float32(1e-37))  # in [0, 1]
    big = t > _TAN_PI_8
    t = (t - np.float32(1.0)) / (t + np.float32(1.0)) if big else t  # atan(t) = pi/4 + atan((t-1)/(t+1))
    s = t * t
    r = t * ((((_C4 * s + _C3) * s + _C2) * s + _C1) * s + _C0)
    r = r + _QUARTER_PI if big else r
    r = _HALF_PI - r if ay > ax else r
    r = _PI - r if x < 0 else r
    return -r if y < 0 else r


@vector_kernel
def _replicate_pad(patch, out):
    """Copy a (P, P) patch into the centre of ``out`` (P + 2, P + 2) with its borders replicated."""
    p = patch.shape[0]
    for i in range(p + 2):
        r = min(max(i - 1, 0), p - 1)
        out[i, 0] = patch[r, 0]
        for j in range(p):
            out[i, j + 1] = patch[r, j]
        out[i, p + 1] = patch[r, p - 1]


@vector_kernel
def _sobel(padded, gx, gy):
    """Normalised 3x3 Sobel gradients (sum of |weights| = 1) of a replicate-padded patch (P + 2, P + 2)
    into gx, gy (P * P,), in the operation order of the torch version."""
    p = padded.shape[0] - 2
    two, eighth = np.float32(2.0), np.float32(0.125)
    for i in range(p):
        for j in range(p):
            dx = (padded[i, j + 2] - padded[i, j]) + (padded[i + 2, j + 2] - padded[i + 2, j])
            gx[i * p + j] = (dx + two * (padded[i + 1, j + 2] - padded[i + 1, j])) * eighth
            dy = (padded[i + 2, j] - padded[i, j]) + (padded[i + 2, j + 2] - padded[i, j + 2])
            gy[i * p + j] = (dy + two * (padded[i + 2, j + 1] - padded[i, j + 1])) * eighth


@vector_kernel
def _central(padded, gx, gy):
    """Central differences / 2 of a replicate-padded patch (P + 2, P + 2) into gx, gy (P * P,)."""
    p = padded.shape[0] - 2
    half = np.float32(0.5)
    for i in range(p):
        for j in range(p):
            gx[i * p + j] = (padded[i + 1, j + 2] - padded[i + 1, j]) * half
            gy[i * p + j] = (padded[i + 2, j + 1] - padded[i, j + 1]) * half


@vector_kernel
def _votes(gx, gy, bins, eps, offset, b0, b1, w0, w1):
    """Linear votes of each gradient into its two nearest of ``bins`` orientation bins (kornia's binning).

    Args:
        gx, gy: (M,) float32 gradients.
        bins: bins over 2 pi.
        eps: float32 guard of the magnitude and of ``atan2``; zero (and non-finite) gradients vote nothing.
        offset: float32 radians added to the angle before binning, in [-pi, 3 pi).
        b0, b1: (M,) int64 outputs, the two bins; w0, w1: (M,) float32 outputs, their votes.
    """
    scale = np.float32(bins / (2.0 * math.pi))
    two_pi = np.float32(2.0 * math.pi)
    for k in range(gx.shape[0]):
        x, y = gx[k], gy[k]
        sq = x * x + y * y
        nonzero = np.float32(0.0) < sq < np.float32(np.inf)
        mag = np.sqrt(sq + eps) if nonzero else np.float32(0.0)
        ori = _atan2(y, x + eps) + two_pi if nonzero else two_pi
        o = (ori + offset) * scale
        b = np.floor(o)
        w1[k] = (o - b) * mag
        w0[k] = mag - w1[k]
        # o is in [0, 3 bins]: two conditional wraps replace the modulo.
        i = int(b)
        i = i - bins if i >= bins else i
        i = i - bins if i >= bins else i
        b0[k] = i
        b1[k] = 0 if i + 1 == bins else i + 1


@vector_kernel
def _vote_buffers(m):
    """Scratch arrays of ``_votes`` for m pixels: gx, gy (float32), b0, b1 (int64), w0, w1 (float32).

    Separate allocations, so that numba types them contiguous (rows of one 2D array are not, and their
    loops do not vectorise).
    """
    f32, i64 = np.float32, np.int64
    return np.empty(m, f32), np.empty(m, f32), np.empty(m, i64), np.empty(m, i64), np.empty(m, f32), np.empty(m, f32)


@vector_kernel
def second_moments(patches, window):
    """Gaussian-weighted Sobel gradient second moments of patches.

    Args:
        patches: (N, P, P) float32.
        window: (P, P) float32 weights.

    Returns:
        (N, 3) float64 sums of ``w gx^2``, ``w gx gy``, ``w gy^2``.
    """
    n, p = patches.shape[0], patches.shape[1]
    out = np.empty((n, 3))
    w = window.ravel()
    padded = np.empty((p + 2, p + 2), np.float32)
    gx, gy = np.empty(p * p, np.float32), np.empty(p * p, np.float32)
    xx, xy, yy = np.empty(p), np.empty(p), np.empty(p)  # per-column partial sums: independent chains
    for k in range(n):
        _replicate_pad(patches[k], padded)
        _sobel(padded, gx, gy)
        xx[:], xy[:], yy[:] = 0.0, 0.0, 0.0
        for i in range(p):
            for j in range(p):
                m = i * p + j
                wgx = gx[m] * w[m]
                xx[j] += wgx * gx[m]
                xy[j] += wgx * gy[m]
                yy[j] += gy[m] * gy[m] * w[m]
        out[k, 0], out[k, 1], out[k, 2] = xx.sum(), xy.sum(), yy.sum()
    return out


@vector_kernel
def orientation_histograms(patches, window, bins, eps, offset):
    """Window-weighted histograms of Sobel gradient directions with linear votes.

    Args:
        patches: (N, P, P) float32.
        window: (P, P) float32 vote weights.
        bins: histogram bins over 2 pi; eps, offset: see ``_votes`` (float32).

    Returns:
        (N, bins) float32 histograms.
    """
    n, p = patches.shape[0], patches.shape[1]
    out = np.empty((n, bins), np.float32)
    w = window.ravel()
    hist = np.empty(bins)
    padded = np.empty((p + 2, p + 2), np.float32)
    gx, gy, b0, b1, w0, w1 = _vote_buffers(p * p)
    for k in range(n):
        _replicate_pad(patches[k], padded)
        _sobel(padded, gx, gy)
        _votes(gx, gy, bins, eps, offset, b0, b1, w0, w1)
        hist[:] = 0.0
        for m in range(p * p):
            hist[b0[m]] += w0[m] * w[m]
            hist[b1[m]] += w1[m] * w[m]
        out[k] = hist
    return out


@vector_kernel
def sift_histograms(patches, cell, weight, cells, bins, eps):
    """SIFT histograms: central-difference gradient votes pooled into spatial cells.

    The separable pooling gives pixel row ``i`` the weight ``weight[i, a]`` in cell row ``cell[i, a]``
    (columns alike), so each pixel feeds at most ``K^2`` cells instead of a dense (P^2, cells^2) product:
    each pixel row is pooled over columns first, then added to its cell rows.

    Args:
        patches: (N, P, P) float32.
        cell: (P, K) int64 cells of each pixel row / column.
        weight: (P, K) float64 pooling weights (zero for unused slots).
        cells: cells per side S.
        bins: orientation bins; eps: guard of ``_votes`` (float32).

    Returns:
        (N, bins * S * S) float32 histograms, entry ``b * S^2 + r * S + c`` (bin, cell row, cell column).
    """
    n, p, kk = patches.shape[0], patches.shape[1], cell.shape[1]
    out = np.empty((n, bins * cells * cells), np.float32)
    hist, row = np.empty((bins, cells, cells)), np.empty((bins, cells))
    padded = np.empty((p + 2, p + 2), np.float32)
    gx, gy, b0, b1, w0, w1 = _vote_buffers(p * p)
    for k in range(n):
        _replicate_pad(patches[k], padded)
        _central(padded, gx, gy)
        _votes(gx, gy, bins, eps, np.float32(0.0), b0, b1, w0, w1)
        hist[:] = 0.0
        for i in range(p):
            row[:] = 0.0
            for j in range(p):
                m = i * p + j
                for c in range(kk):
                    row[b0[m], cell[j, c]] += w0[m] * weight[j, c]
                    row[b1[m], cell[j, c]] += w1[m] * weight[j, c]
            for a in range(kk):
                r, wr = cell[i, a], weight[i, a]
                for b in range(bins):
                    for c in range(cells):
                        hist[b, r, c] += wr * row[b, c]
        out[k] = hist.ravel()
    return out
