"""Compiled loops of DTM's meshes (numba): vertex merging, mesh construction and neighbour tables, nearest vertices,
point location, the local affine maps and the transfer test of expansion.

DTM runs on meshes of a few hundred vertices, thousands of times per Slime run. In numpy each of its steps is
dozens of calls on tiny arrays, and the call overhead dominates; here each step is one pass. Positions are
integers, so every geometric test is exact except those on the predicted images of border corners.

Conventions: a mesh has P points, the first n of them kept vertices and the others border points; triangles
are (T, 3) point indices; each point's Delaunay neighbours are a CSR list ``first``, ``degree``, ``adjacent``.
"""

from __future__ import annotations

import math

import numpy as np

from .._runtime.compiled import kernel
from .delaunay import triangulate


@kernel
def unique_inverse(keys):
    """``np.unique(keys, return_inverse=True)`` of int64 keys (K,): the distinct keys ascending (V,) and the
    index of each key among them (K,)."""
    order = np.argsort(keys)
    distinct = np.empty(len(keys), np.int64)
    inverse = np.empty(len(keys), np.int64)
    m = -1
    for i in order:
        if m < 0 or keys[i] != distinct[m]:
            m += 1
            distinct[m] = keys[i]
        inverse[i] = m
    return distinct[:m + 1], inverse


@kernel
def grid_vertices(xy, w, h):
    """Positions xy (K, 2) rounded (half to even), clipped to the w x h pixel grid and merged: (V, 2) float64
    the distinct ones by row then column, (K,) the one of each position."""
    key = np.empty(len(xy), np.int64)
    for i in range(len(xy)):
        x = min(max(np.rint(xy[i, 0]), 0.0), w - 1.0)
        y = min(max(np.rint(xy[i, 1]), 0.0), h - 1.0)
        key[i] = int(y) * (w + 2) + int(x)
    distinct, inverse = unique_inverse(key)
    out = np.empty((len(distinct), 2))
    for v in range(len(distinct)):
        out[v, 0], out[v, 1] = distinct[v] % (w + 2), distinct[v] // (w + 2)
    return out, inverse


@kernel
def carved_mesh(points, n, free):
    """A mesh in one pass: the Delaunay triangulation (``delaunay.triangulate``) of points and of the free
    points that share a triangle with a border point in the triangulation of everything (they carve the
    hull), with its neighbour tables (``mesh_tables``).

    Args:
        points: (P, 2) float64 unique integer-valued positions, the first n kept vertices, the others border
            points that include the four corners of the bounding rectangle.
        free: (F, 2) float64 unique integer-valued positions inside that rectangle, off points (F may be 0).

    Returns:
        points: (P + C, 2) the input points, then the C carving free points in their order.
        simplices, neighbors: (T, 3) the triangulation (``delaunay.triangulate``).
        first, degree, adjacent, edges: its tables (``mesh_tables``).
        error: ``delaunay.triangulate``'s error code, 0 when both triangulations succeed.
    """
    error = 0
    if len(free):
        simplices, _, error = triangulate(np.concatenate((points, free)).astype(np.int64))
        points = np.concatenate((points, free[ring_carved(simplices, n, len(points), len(free))]))
    simplices, neighbors, final_error = triangulate(points.astype(np.int64))
    first, degree, adjacent, edges = mesh_tables(simplices, len(points), n)
    return points, simplices, neighbors, first, degree, adjacent, edges, error or final_error


@kernel
def ring_carved(simplices, n, first_free, n_free):
    """(n_free,) whether each free point (indices first_free...) shares a triangle with a ring point
    (indices n to first_free - 1)."""
    out = np.zeros(n_free, np.bool_)
    for t in range(len(simplices)):
        touches = False
        for k in range(3):
            touches |= n <= simplices[t, k] < first_free
        if touches:
            for k in range(3):
                if simplices[t, k] >= first_free:
                    out[simplices[t, k] - first_free] = True
    return out


@kernel
def mesh_tables(simplices, n_pts, n):
    """The neighbour tables of a triangulation of n_pts points.

    Args:
        simplices: (T, 3) int64 triangles, counter-clockwise in x-right, y-down axes (positive cross product);
        n: the first n points are kept vertices.

    Returns:
        first, degree: (n_pts,) start and size of each point's group in ``adjacent``.
        adjacent: (3 T,) the Delaunay neighbours of every point, grouped by point.
        edges: (E, 2) undirected edges between kept vertices, a < b < n.
    """
    n_tri = len(simplices)
    degree = np.zeros(n_pts, np.int64)
    n_edges = 0
    for t in range(n_tri):
        for k in range(3):
            a, b = simplices[t, (k + 1) % 3], simplices[t, (k + 2) % 3]
            degree[a] += 1
            if a < b < n:
                n_edges += 1
    first = np.cumsum(degree) - degree
    fill = first.copy()
    adjacent = np.empty(3 * n_tri, np.int64)
    edges = np.empty((n_edges, 2), np.int64)
    n_edges = 0
    for t in range(n_tri):
        for k in range(3):
            a, b = simplices[t, (k + 1) % 3], simplices[t, (k + 2) % 3]
            adjacent[fill[a]] = b
            fill[a] += 1
            if a < b < n:
                edges[n_edges, 0], edges[n_edges, 1] = a, b
                n_edges += 1
    return first, degree, adjacent, edges


@kernel
def walk_tables(points, simplices, neighbors):
    """Tables of ``locate`` and ``transfer_test``, with an extra triangle T standing for the outside.

    Move 0 from a triangle stays in it, move k = 1, 2, 3 crosses the edge facing corner k - 1.

    Returns:
        lines: (T + 1, 4, 3) per triangle and move k, (a, b, c) with a x + b y + c twice the signed area of
            the crossed edge and the point (x, y), >= 0 on the triangle's side (0 for move 0 and for
            triangle T, which thus holds every point).
        across: (T + 1, 4) the triangle each move leads to, T when it leaves the hull.
        start: (P,) a triangle at each point (the last one in ``simplices``).
        proper: (T + 1,) the triangle has a positive area (False for triangle T).
    """
    n_tri = len(simplices)
    lines = np.zeros((n_tri + 1, 4, 3))
    across = np.full((n_tri + 1, 4), n_tri, np.int64)
    start = np.empty(len(points), np.int64)
    proper = np.zeros(n_tri + 1, np.bool_)
    for t in range(n_tri):
        across[t, 0] = t
        twice_area = 0.0
        for k in range(3):
            p1, p2 = simplices[t, (k + 1) % 3], simplices[t, (k + 2) % 3]
            x1, y1, x2, y2 = points[p1, 0], points[p1, 1], points[p2, 0], points[p2, 1]
            lines[t, k + 1, 0], lines[t, k + 1, 1], lines[t, k + 1, 2] = y1 - y2, x2 - x1, x1 * y2 - y1 * x2
            twice_area += x1 * y2 - y1 * x2
            if neighbors[t, k] >= 0:
                across[t, k + 1] = neighbors[t, k]
            start[simplices[t, k]] = t
        proper[t] = twice_area > 0
    return lines, across, start, proper


@kernel
def nearest_point(points, n, q):
    """The point among the first n of points (P, 2) nearest each query q (Q, 2): (Q,) its index and (Q,)
    whether another of them is exactly as near (exact on integer-valued positions)."""
    nearest = np.empty(len(q), np.int64)
    tied = np.zeros(len(q), np.bool_)
    for i in range(len(q)):
        best = np.inf
        for v in range(n):
            dx, dy = points[v, 0] - q[i, 0], points[v, 1] - q[i, 1]
            d = dx * dx + dy * dy
            if d < best:
                best, nearest[i], tied[i] = d, v, False
            elif d == best:
                tied[i] = True
    return nearest, tied


@kernel
def locate(lines, across, start, q, near):
    """(Q,) index of the triangle containing each query point q (Q, 2), -1 outside the hull.

    Visibility walk from a triangle at the point near[i] close to each query, across the edge facing the
    most negative barycentric coordinate; it terminates on Delaunay triangulations.
    """
    outside = len(lines) - 1
    out = np.full(len(q), -1, np.int64)
    for i in range(len(q)):
        cur = start[near[i]]
        x, y = q[i, 0], q[i, 1]
        for _ in range(len(lines)):
            move, lowest = 0, 0.0
            for k in range(1, 4):
                value = lines[cur, k, 0] * x + lines[cur, k, 1] * y + lines[cur, k, 2]
                if value < lowest:
                    move, lowest = k, value
            if move == 0 or across[cur, move] == cur:
                if cur < outside:
                    out[i] = cur
                break
            cur = across[cur, move]
    return out


@kernel
def transfer_test(points, simplices, proper, n, simplex, nearest, dst_v, affine, offset, q_dst, tol):
    """Whether each q_dst lies in the image of the triangle ``simplex`` that contains its source point.

    The image of a triangle maps kept corners to dst_v and border corners by the local affine map of the
    kept vertex nearest the source point; it must have a positive orientation, and each side may miss q_dst
    by ``tol`` px.

    Args:
        simplex: (Q,) triangle of each query, -1 for none; nearest: (Q,) kept vertex nearest each source.
        dst_v: (n, 2) position in the other image of each kept vertex.
        affine, offset: (n, 2, 2), (n, 2) local affine maps (read only at border corners).
        q_dst: (Q, 2) query positions in the other image.

    Returns:
        (Q,) bool.
    """
    out = np.zeros(len(simplex), np.bool_)
    x, y = np.empty(3), np.empty(3)
    for i in range(len(simplex)):
        s = simplex[i]
        if s < 0 or not proper[s]:
            continue
        for k in range(3):
            c = simplices[s, k]
            if c < n:
                x[k], y[k] = dst_v[c, 0], dst_v[c, 1]
            else:
                v = nearest[i]
                rx, ry = points[c, 0] - points[v, 0], points[c, 1] - points[v, 1]
                x[k] = offset[v, 0] + (affine[v, 0, 0] * rx + affine[v, 0, 1] * ry)
                y[k] = offset[v, 1] + (affine[v, 1, 0] * rx + affine[v, 1, 1] * ry)
        if not (x[1] - x[0]) * (y[2] - y[0]) > (y[1] - y[0]) * (x[2] - x[0]):
            continue
        inside = True
        for k in range(3):
            ex, ey = x[(k + 1) % 3] - x[k], y[(k + 1) % 3] - y[k]
            if ex * (q_dst[i, 1] - y[k]) - ey * (q_dst[i, 0] - x[k]) < -tol * math.hypot(ex, ey):
                inside = False
        out[i] = inside
    return out


@kernel
def _solve3(m, r):
    """Solve the 3 x 3 system m x = r (r: (3, 2)) by Gaussian elimination with partial pivoting (m and r are
    overwritten); returns x (3, 2)."""
    for col in range(3):
        pivot = col
        for row in range(col + 1, 3):
            if abs(m[row, col]) > abs(m[pivot, col]):
                pivot = row
        for c in range(3):
            m[col, c], m[pivot, c] = m[pivot, c], m[col, c]
        for c in range(2):
            r[col, c], r[pivot, c] = r[pivot, c], r[col, c]
        for row in range(col + 1, 3):
            factor = m[row, col] / m[col, col]
            for c in range(col, 3):
                m[row, c] -= factor * m[col, c]
            for c in range(2):
                r[row, c] -= factor * r[col, c]
    x = np.empty((3, 2))
    for row in range(2, -1, -1):
        for c in range(2):
            value = r[row, c]
            for k in range(row + 1, 3):
                value -= m[row, k] * x[k, c]
            x[row, c] = value / m[row, row]
    return x


@kernel
def local_affine(src, edges, dst, ridge):
    """Affine maps dst ~ c + A (x - src[v]) fitted over each kept vertex's closed Delaunay neighbourhood by
    least squares, ridge-regularised toward the global affine fit: ``ridge`` (px^2) is added to the normal
    equations' linear diagonal, pulling A toward the global linear map (so that collinear or single-vertex
    neighbourhoods stay defined).

    Args:
        src, dst: (n >= 1, 2) positions of the kept vertices and of their matches; edges: (E, 2) mesh edges.

    Returns:
        A (n, 2, 2), c (n, 2).
    """
    n = len(src)
    mean_s, mean_d = np.zeros(2), np.zeros(2)
    for v in range(n):
        for k in range(2):
            mean_s[k] += src[v, k] / n
            mean_d[k] += dst[v, k] / n
    # global linear map: centred least squares (a vanishing ridge picks the minimum-norm one if singular)
    sxx, sxy, syy = 0.0, 0.0, 0.0
    cross = np.zeros((2, 2))  # sum (x - mean_s)_r (dst - mean_d)_c
    for v in range(n):
        x, y = src[v, 0] - mean_s[0], src[v, 1] - mean_s[1]
        sxx, sxy, syy = sxx + x * x, sxy + x * y, syy + y * y
        for c in range(2):
            d = dst[v, c] - mean_d[c]
            cross[0, c] += x * d
            cross[1, c] += y * d
    tiny = 1e-12 * max(sxx + syy, 1.0)
    sxx, syy = sxx + tiny, syy + tiny
    det = sxx * syy - sxy * sxy
    glob = np.empty((2, 2))  # rows: the coefficients of x and y
    for c in range(2):
        glob[0, c] = (syy * cross[0, c] - sxy * cross[1, c]) / det
        glob[1, c] = (sxx * cross[1, c] - sxy * cross[0, c]) / det
    mat, rhs = np.zeros((n, 3, 3)), np.zeros((n, 3, 2))
    f = np.empty(3)
    for j in range(2 * len(edges) + n):
        if j < 2 * len(edges):
            v, w = edges[j // 2, j % 2], edges[j // 2, 1 - j % 2]
        else:
            v = w = j - 2 * len(edges)
        f[0], f[1], f[2] = src[w, 0] - src[v, 0], src[w, 1] - src[v, 1], 1.0
        for r in range(3):
            for c in range(3):
                mat[v, r, c] += f[r] * f[c]
            for c in range(2):
                rhs[v, r, c] += f[r] * dst[w, c]
    affine, offset = np.empty((n, 2, 2)), np.empty((n, 2))
    for v in range(n):
        for k in range(2):
            mat[v, k, k] += ridge
            for c in range(2):
                rhs[v, k, c] += ridge * glob[k, c]
        sol = _solve3(mat[v], rhs[v])
        for c in range(2):
            affine[v, c, 0], affine[v, c, 1] = sol[0, c], sol[1, c]
            offset[v, c] = sol[2, c]
    return affine, offset
