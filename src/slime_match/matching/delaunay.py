"""Delaunay triangulation of integer points inside a rectangle whose four corners are among them (numba).

DTM triangulates each image's kept matches plus a border ring thousands of times per Slime run, on a few
hundred points each time. This incremental (Lawson) triangulation starts from the two triangles of the
bounding rectangle, inserts the other points along a snake of horizontal strips (short point-location walks)
and restores the empty-circle property by edge flips. Points on the rectangle's sides split hull edges, so
no outer super-triangle is needed and the hull is exactly the rectangle. Positions are integers and the
orientation and in-circle predicates are evaluated exactly in int64, which bounds the rectangle's sides
(``MAX_SIDE``). Cocircular points (common on the pixel grid) keep the edge present when they meet: the
result is a valid Delaunay triangulation whose ties depend on the insertion order.
"""

from __future__ import annotations

import math

import numpy as np

from .._runtime.compiled import kernel

_NEXT = np.array([1, 2, 0])  # corner k + 1 and k + 2, mod 3
_PREV = np.array([2, 0, 1])

MAX_SIDE = 20_000  # px; in-circle terms stay below 2^62 for coordinate differences up to this


@kernel
def _orient(p, a, b, c):
    """Twice the signed area of the points a, b, c of p (P, 2) int64 (> 0: counter-clockwise in x-right,
    y-up axes, i.e. a positive cross product)."""
    return (p[b, 0] - p[a, 0]) * (p[c, 1] - p[a, 1]) - (p[b, 1] - p[a, 1]) * (p[c, 0] - p[a, 0])


@kernel
def _in_circle(p, a, b, c, d):
    """> 0 when point d lies strictly inside the circumcircle of the positively oriented triangle a, b, c."""
    adx, ady = p[a, 0] - p[d, 0], p[a, 1] - p[d, 1]
    bdx, bdy = p[b, 0] - p[d, 0], p[b, 1] - p[d, 1]
    cdx, cdy = p[c, 0] - p[d, 0], p[c, 1] - p[d, 1]
    return ((adx * adx + ady * ady) * (bdx * cdy - cdx * bdy) + (bdx * bdx + bdy * bdy) * (cdx * ady - adx * cdy)
            + (cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady))


@kernel
def _relink(nbr, t, old, new):
    """Triangle t (if any) now borders ``new`` where it bordered ``old``."""
    if t >= 0:
        for k in range(3):
            if nbr[t, k] == old:
                nbr[t, k] = new


@kernel
def _set(tri, nbr, t, a, b, c, na, nb, nc):
    tri[t, 0], tri[t, 1], tri[t, 2] = a, b, c
    nbr[t, 0], nbr[t, 1], nbr[t, 2] = na, nb, nc


@kernel
def _legalize(p, tri, nbr, stack, top):
    """Flip, until none is left, the stacked edges (triangle, corner at the new point) that fail the
    empty-circle test; each flip stacks the two edges it exposes."""
    while top > 0:
        top -= 1
        t, k = stack[top, 0], stack[top, 1]
        n = nbr[t, k]
        if n < 0:
            continue
        j = 0
        while nbr[n, j] != t:
            j += 1
        # t = (v, s, r) with v the new point; n = (q, r, s)
        v, s, r = tri[t, k], tri[t, _NEXT[k]], tri[t, _PREV[k]]
        q = tri[n, j]
        if _in_circle(p, v, s, r, q) <= 0:
            continue
        t_s, t_r = nbr[t, _NEXT[k]], nbr[t, _PREV[k]]  # across r-v and v-s
        n_r, n_s = nbr[n, _NEXT[j]], nbr[n, _PREV[j]]  # across s-q and q-r
        _set(tri, nbr, t, v, s, q, n_r, n, t_r)
        _set(tri, nbr, n, v, q, r, n_s, t_s, t)
        _relink(nbr, n_r, n, t)
        _relink(nbr, t_s, t, n)
        stack[top, 0], stack[top, 1] = t, 0
        stack[top + 1, 0], stack[top + 1, 1] = n, 0
        top += 2


@kernel
def insertion_order(ip, y0, strip):
    """(P,) order of integer points ip (P, 2) along a snake of horizontal strips ``strip`` px high from y0:
    strips top to bottom, x ascending in even strips and descending in odd ones, ties by index."""
    span = 1
    for i in range(len(ip)):
        span = max(span, abs(ip[i, 0]) + 1)
    key = np.empty(len(ip), np.int64)
    for i in range(len(ip)):
        row = (ip[i, 1] - y0) // strip
        key[i] = row * (2 * span + 1) + (-ip[i, 0] if row & 1 else ip[i, 0]) + span
    return np.argsort(key, kind="mergesort")


@kernel
def triangulate(points):
    """Delaunay triangles of unique integer points whose bounding rectangle's corners are among them.

    The four corners are inserted first, then the other points along a snake of strips about four mean point
    spacings high (``insertion_order``).

    Args:
        points: (P, 2) int64 positions.

    Returns:
        triangles: (T, 3) int64, positive cross product (counter-clockwise in x-right, y-down pixel axes).
        neighbors: (T, 3) int64 triangle across the edge facing each corner, -1 on the hull.
        error: 0 ok, 1 a bounding-rectangle corner is missing or the rectangle is flat, 2 a point is
            repeated, 3 the rectangle is more than ``MAX_SIDE`` px a side.
    """
    n_pts = len(points)
    x0, y0, x1, y1 = points[0, 0], points[0, 1], points[0, 0], points[0, 1]
    for i in range(n_pts):
        x0, y0 = min(x0, points[i, 0]), min(y0, points[i, 1])
        x1, y1 = max(x1, points[i, 0]), max(y1, points[i, 1])
    corner = np.full(4, -1, np.int64)  # (x0, y0), (x1, y0), (x1, y1), (x0, y1)
    for i in range(n_pts):
        x, y = points[i, 0], points[i, 1]
        if y == y0 and x == x0:
            corner[0] = i
        elif y == y0 and x == x1:
            corner[1] = i
        elif y == y1 and x == x1:
            corner[2] = i
        elif y == y1 and x == x0:
            corner[3] = i
    tri = np.empty((2 * n_pts, 3), np.int64)
    nbr = np.full((2 * n_pts, 3), -1, np.int64)
    if x0 == x1 or y0 == y1 or corner.min() < 0:
        return tri[:0], nbr[:0], 1
    if max(x1 - x0, y1 - y0) > MAX_SIDE:
        return tri[:0], nbr[:0], 3
    stack = np.empty((4 * n_pts + 8, 2), np.int64)
    c0, c1, c2, c3 = corner[0], corner[1], corner[2], corner[3]
    _set(tri, nbr, 0, c0, c1, c2, -1, 1, -1)  # positive cross product in (x, y)
    _set(tri, nbr, 1, c0, c2, c3, -1, -1, 0)
    n_tri, cur = 2, 0
    strip = max(int(4 * math.sqrt((x1 - x0 + 1) * (y1 - y0 + 1) / n_pts)), 1)
    for v in insertion_order(points, y0, strip):
        if v == c0 or v == c1 or v == c2 or v == c3:
            continue
        # visibility walk to the triangle holding v, noting the edges v lies on (two: v is a corner)
        moved = True
        while moved:
            moved, on_edge, n_on = False, -1, 0
            for k in range(3):
                side = _orient(points, tri[cur, _NEXT[k]], tri[cur, _PREV[k]], v)
                if side < 0:
                    cur = nbr[cur, k]
                    moved = True
                    break
                if side == 0:
                    on_edge, n_on = k, n_on + 1
        if n_on > 1:
            return tri[:0], nbr[:0], 2
        t = cur
        if on_edge < 0:  # split t = (a, b, c) into (a, b, v), (b, c, v), (c, a, v)
            a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
            na, nb, nc = nbr[t, 0], nbr[t, 1], nbr[t, 2]
            t1, t2 = n_tri, n_tri + 1
            n_tri += 2
            _set(tri, nbr, t, a, b, v, t1, t2, nc)
            _set(tri, nbr, t1, b, c, v, t2, t, na)
            _set(tri, nbr, t2, c, a, v, t, t1, nb)
            _relink(nbr, na, t, t1)
            _relink(nbr, nb, t, t2)
            stack[0, 0], stack[0, 1] = t, 2
            stack[1, 0], stack[1, 1] = t1, 2
            stack[2, 0], stack[2, 1] = t2, 2
            top = 3
        else:  # v on the edge y-z of t = (x, y, z): split t and the triangle u = (w, z, y) across it
            k = on_edge
            x, y, z = tri[t, k], tri[t, _NEXT[k]], tri[t, _PREV[k]]
            u, n_y, n_z = nbr[t, k], nbr[t, _NEXT[k]], nbr[t, _PREV[k]]
            b = n_tri
            n_tri += 1
            _set(tri, nbr, t, x, y, v, -1, b, n_z)
            _set(tri, nbr, b, x, v, z, -1, n_y, t)
            _relink(nbr, n_y, t, b)
            stack[0, 0], stack[0, 1] = t, 2
            stack[1, 0], stack[1, 1] = b, 1
            top = 2
            if u >= 0:
                j = 0
                while nbr[u, j] != t:
                    j += 1
                w = tri[u, j]
                u_z, u_y = nbr[u, _NEXT[j]], nbr[u, _PREV[j]]  # across y-w and w-z
                d = n_tri
                n_tri += 1
                _set(tri, nbr, u, w, z, v, b, d, u_y)
                _set(tri, nbr, d, w, v, y, t, u_z, u)
                _relink(nbr, u_z, u, d)
                nbr[t, 0], nbr[b, 0] = d, u
                stack[2, 0], stack[2, 1] = u, 2
                stack[3, 0], stack[3, 1] = d, 1
                top = 4
        _legalize(points, tri, nbr, stack, top)
        cur = t
    return tri[:n_tri], nbr[:n_tri], 0


def delaunay(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Delaunay triangulation of unique integer-valued (P, 2) points whose bounding rectangle, at most
    ``MAX_SIDE`` px a side, has its four corners among them.

    Returns:
        (T, 3) int64 triangles (positive cross product) and (T, 3) the triangle across the edge facing each
        corner (-1 on the hull).
    """
    simplices, neighbors, error = triangulate(np.ascontiguousarray(points, np.int64))
    check(error)
    return simplices, neighbors


def check(error: int) -> None:
    """Raise the ValueError that a ``triangulate`` error code stands for (0: none)."""
    if error:
        raise ValueError({1: "Delaunay: the four corners of the points' bounding rectangle must be among them",
                          2: "Delaunay: points must be unique",
                          3: f"Delaunay: points span more than {MAX_SIDE} px (exact int64 predicates)"}[error])
