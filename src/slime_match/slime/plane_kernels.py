"""Compiled loop of plane expansion (paper Sec. 3.4, numba): every (plane, match) pair tested in one pass.

Slime tests a few hundred planes against ten thousand or more block-pair matches; in numpy the tests need
a pre-filter and large temporaries. Here each pair is tested in float64, the cheap tests first (plane side,
forward then backward error, then the neighbours' orientation and scale) and the backward neighbours only
when the forward ones do not already pass both.
"""

from __future__ import annotations

import math

import numpy as np

from .._runtime.compiled import vector_kernel

_STEPS = ((0, 1.0), (1, 1.0), (0, -1.0), (1, -1.0))  # neighbour n = x + sign e_j, in that order
_STEP_ANGLES = (0.0, math.pi / 2, math.pi, -math.pi / 2)  # the angle of n - x


@vector_kernel
def _wrap(a):
    """Angle wrapped to (-pi, pi] (the same formula as ``planes.wrap_angle``)."""
    return math.pi - np.mod(math.pi - a, 2.0 * math.pi)


@vector_kernel
def _local_ok(h, x, y, p0, p1, p2, rho, psi, inverse, t_theta, t_sigma):
    """Orientation and scale tests at the 4 neighbours of (x, y) under the (9,) homography h, with
    H [x, y, 1] = (p0, p1, p2): (some |wrap(rho - rho^H_n)| < t_theta, some psi^H_n / psi in [1/t, t]),
    psi^H_n * psi for the ``inverse`` homography."""
    q0, q1 = p0 / p2, p1 / p2
    rot = False
    scale = False
    for n in range(4):
        j, sign = _STEPS[n]
        d0 = (p0 + sign * h[j]) / (p2 + sign * h[6 + j]) - q0
        d1 = (p1 + sign * h[3 + j]) / (p2 + sign * h[6 + j]) - q1
        if not rot and abs(_wrap(rho - (math.atan2(d1, d0) - _STEP_ANGLES[n]))) < t_theta:
            rot = True
        if not scale:
            s = math.hypot(d0, d1) * psi if inverse else math.hypot(d0, d1) / psi
            scale = s >= 1.0 / t_sigma and s <= t_sigma
        if rot and scale:
            break
    return rot, scale


@vector_kernel
def expansion_pairs(h, hinv, side, xy0, xy1, rho, psi, t_perp, t_theta, t_sigma):
    """The (plane, match) pairs passing all tests of Sec. 3.4 (see ``planes.expand_planes``).

    Args:
        h, hinv: (L, 9) row-major homographies image 1 -> image 2 and their inverses.
        side: (L,) plane sides (+1/-1).
        xy0, xy1: (M, 2) float64 matched points, px.
        rho: (M,) relative orientations, radians; psi: (M,) scale ratios (1 for the "homography" mode).
        t_perp: px; t_theta: radians; t_sigma: ratio bound.

    Returns:
        (K,) int64 plane indices (ascending) and (K,) int64 match indices (ascending within a plane).
    """
    n_planes, n_matches = h.shape[0], xy0.shape[0]
    planes = np.empty(1024, np.int64)
    matches = np.empty(1024, np.int64)
    k = 0
    loose = (t_perp * (1.0 + 1e-6)) ** 2
    for pl in range(n_planes):
        a, b = h[pl], hinv[pl]
        for mi in range(n_matches):
            x, y = xy0[mi, 0], xy0[mi, 1]
            u, v = xy1[mi, 0], xy1[mi, 1]
            p2 = a[6] * x + a[7] * y + a[8]
            if not ((p2 > 0 and side[pl] > 0) or (p2 < 0 and side[pl] < 0)):
                continue
            p0 = a[0] * x + a[1] * y + a[2]
            p1 = a[3] * x + a[4] * y + a[5]
            ex, ey = p0 - u * p2, p1 - v * p2  # a division-free bound first: most pairs are far off
            if ex * ex + ey * ey > loose * p2 * p2 or not math.hypot(p0 / p2 - u, p1 / p2 - v) < t_perp:
                continue
            r0 = b[0] * u + b[1] * v + b[2]
            r1 = b[3] * u + b[4] * v + b[5]
            r2 = b[6] * u + b[7] * v + b[8]
            if not math.hypot(r0 / r2 - x, r1 / r2 - y) < t_perp:
                continue
            rot, scale = _local_ok(a, x, y, p0, p1, p2, rho[mi], psi[mi], False, t_theta, t_sigma)
            if not (rot and scale):
                rot1, scale1 = _local_ok(b, u, v, r0, r1, r2, -rho[mi], psi[mi], True, t_theta, t_sigma)
                rot, scale = rot or rot1, scale or scale1
            if rot and scale:
                if k == len(planes):
                    planes = np.concatenate((planes, np.empty(k, np.int64)))
                    matches = np.concatenate((matches, np.empty(k, np.int64)))
                planes[k] = pl
                matches[k] = mi
                k += 1
    return planes[:k], matches[:k]
