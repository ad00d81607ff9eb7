"""Compiled loop of the epipolar vote (paper Sec. 3.6, numba): every (F, match) pair tested in one pass.

On large images the superset H holds hundreds of sets, so the vote tests hundreds of thousands of fundamental
matrices against tens of thousands of matches. Each test is a few products; in torch it took six passes over
(F, match) temporaries, here it is one pass in registers (float64).
"""

from __future__ import annotations

from .._runtime.compiled import kernel


@kernel
def epipolar_votes(f, x0, x1, tol2, votes):
    """Add to ``votes`` the number of fundamental matrices each match is consistent with.

    Args:
        f: (B, 3, 3) float64 fundamental matrices, ``x'^T F x = 0``.
        x0, x1: (2, N) float64 match positions in images 1 and 2 (homogeneous coordinate 1 implied).
        tol2: squared distance threshold, in the units of x0 and x1.
        votes: (N,) float64, incremented in place where the larger distance of the two points to their
            epipolar lines, ``|x'^T F x| / min(|(F x)_12|, |(F^T x')_12|)``, is below sqrt(tol2).
    """
    a0s, a1s, c0s, c1s = x0[0], x0[1], x1[0], x1[1]
    for b in range(f.shape[0]):
        f00, f01, f02 = f[b, 0, 0], f[b, 0, 1], f[b, 0, 2]
        f10, f11, f12 = f[b, 1, 0], f[b, 1, 1], f[b, 1, 2]
        f20, f21, f22 = f[b, 2, 0], f[b, 2, 1], f[b, 2, 2]
        for i in range(len(votes)):  # no branch in this loop, so that it vectorises (about 4x faster)
            a0, a1, c0, c1 = a0s[i], a1s[i], c0s[i], c1s[i]
            l0 = f00 * a0 + f01 * a1 + f02  # F x
            l1 = f10 * a0 + f11 * a1 + f12
            l2 = f20 * a0 + f21 * a1 + f22
            m0 = f00 * c0 + f10 * c1 + f20  # F^T x'
            m1 = f01 * c0 + f11 * c1 + f21
            alg = c0 * l0 + c1 * l1 + l2
            votes[i] += 1.0 if alg * alg < tol2 * min(l0 * l0 + l1 * l1, m0 * m0 + m1 * m1) else 0.0
