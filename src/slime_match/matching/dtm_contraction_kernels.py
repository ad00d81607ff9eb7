"""Compiled loops of DTM's contraction (numba): the relation of two kept mesh points, the near unit pairs of a mesh,
the survivors of a ranked walk and one contraction step.

Conventions as in ``dtm_kernels``: a mesh has P points, the first n of them kept vertices and the others border
points; each point's Delaunay neighbours are a CSR list ``first``, ``degree``, ``adjacent``.
"""

from __future__ import annotations

import numpy as np

from .._runtime.compiled import kernel

NEAR, APART, FAR = 0, 1, 2  # relations of two kept mesh points, see ``relation``


@kernel
def relation(p, q, first, degree, adjacent, mark):
    """NEAR: kept mesh points p and q are one point or Delaunay neighbours; FAR: they are more than two
    Delaunay edges apart (paths through border points included); APART otherwise.

    mark: (P + 1,) int64 scratch, -1 before the first call and then shared by the calls on one mesh, cheapest
    when consecutive calls share p: mark[k] == p for the neighbours k of the last p, which mark[P] holds.
    """
    if p == q:
        return NEAR
    if mark[-1] != p:
        for j in range(first[p], first[p] + degree[p]):
            mark[adjacent[j]] = p
        mark[-1] = p
    if mark[q] == p:
        return NEAR
    for j in range(first[q], first[q] + degree[q]):  # a common neighbour (q is off the hull: its list is whole)
        if mark[adjacent[j]] == p:
            return APART
    return FAR


@kernel
def near_unit_pairs(members, start, edges):
    """Unit pairs (a, b) near in one image: on one kept vertex (each pair once, a < b) or on the two ends of
    a mesh edge.

    Args:
        members: (A,) units grouped by kept vertex; start: (n + 1,) bounds of each vertex's group.
        edges: (E, 2) the mesh edges between kept vertices.

    Returns:
        a, b: (N,) unit ids.
    """
    total = 0
    for v in range(len(start) - 1):
        size = start[v + 1] - start[v]
        total += size * (size - 1) // 2
    for e in range(len(edges)):
        total += (start[edges[e, 0] + 1] - start[edges[e, 0]]) * (start[edges[e, 1] + 1] - start[edges[e, 1]])
    a, b = np.empty(total, np.int64), np.empty(total, np.int64)
    j = 0
    for v in range(len(start) - 1):
        for i in range(start[v], start[v + 1]):
            for k in range(start[v], start[v + 1]):
                if members[i] < members[k]:
                    a[j], b[j] = members[i], members[k]
                    j += 1
    for e in range(len(edges)):
        for i in range(start[edges[e, 0]], start[edges[e, 0] + 1]):
            for k in range(start[edges[e, 1]], start[edges[e, 1] + 1]):
                a[j], b[j] = members[i], members[k]
                j += 1
    return a, b


@kernel
def survivors(a, b, order, n_units):
    """Units surviving the walk in ``order`` (the units taking part, best first) where each surviving unit
    removes its inconsistent neighbours: (n_units,) bool.

    Args:
        a, b: (E,) inconsistent unit pairs, in either order.
    """
    rank = np.full(n_units, -1, np.int64)
    for r in range(len(order)):
        rank[order[r]] = r
    count = np.zeros(n_units + 1, np.int64)  # per unit, its better-ranked inconsistent neighbours
    for e in range(len(a)):
        count[(b[e] if rank[a[e]] < rank[b[e]] else a[e]) + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    remover = np.empty(len(a), np.int64)
    for e in range(len(a)):
        better, worse = (a[e], b[e]) if rank[a[e]] < rank[b[e]] else (b[e], a[e])
        remover[fill[worse]] = better
        fill[worse] += 1
    survive = np.zeros(n_units, np.bool_)
    for u in order:
        survive[u] = True
        for j in range(start[u], start[u + 1]):
            if survive[remover[j]]:
                survive[u] = False
                break
    return survive


@kernel
def _classified_pairs(by_vertex, alive, point, n, edges, other, first, degree, adjacent):
    """The near unit pairs a, b (N,) of one image and their relation (N,) in the other image, whose mesh
    points of the units are ``other`` and whose adjacency is first, degree, adjacent."""
    members = by_vertex[alive[by_vertex]]
    start = np.zeros(n + 1, np.int64)
    for u in members:
        start[point[u] + 1] += 1
    a, b = near_unit_pairs(members, np.cumsum(start), edges)
    kind = np.empty(len(a), np.int64)
    mark = np.full(len(first) + 1, -1, np.int64)
    for j in range(len(a)):
        kind[j] = relation(other[a[j]], other[b[j]], first, degree, adjacent, mark)
    return a, b, kind


@kernel
def contraction_step(alive, by_score, point0, point1, by_vertex0, by_vertex1, edges0, edges1, n0, n1,
                     first0, degree0, adjacent0, first1, degree1, adjacent1):
    """The units one contraction iteration removes: (U,) bool.

    Each image's near unit pairs are classified in the other image: consistent when near there too (found
    from image 0's), inconsistent when more than two edges apart there. The alive units are ranked by
    consistent neighbours (descending), score (ascending), then id; walking them by rank, each surviving
    unit removes its inconsistent neighbours. Removed: the units that do not survive or have no surviving
    consistent neighbour.

    Args:
        alive: (U,) bool; by_score: (U,) the units by best score of their matches (lower is better), then id.
        point0, point1: (U,) mesh point of each unit in each image (read for alive units).
        by_vertex0, by_vertex1: (U,) the units sorted by vertex in each image, then score.
        edges*, n*, first*, degree*, adjacent*: each image's mesh (see ``mesh_tables``).
    """
    a0, b0, kind0 = _classified_pairs(by_vertex0, alive, point0, n0, edges0, point1, first1, degree1, adjacent1)
    a1, b1, kind1 = _classified_pairs(by_vertex1, alive, point1, n1, edges1, point0, first0, degree0, adjacent0)
    n_consistent = np.zeros(len(alive), np.int64)
    for j in range(len(a0)):
        if kind0[j] == NEAR:
            n_consistent[a0[j]] += 1
            n_consistent[b0[j]] += 1
    top = n_consistent.max()
    start = np.zeros(top + 2, np.int64)  # the rank: a counting sort of by_score by top - n_consistent
    for u in by_score:
        if alive[u]:
            start[top - n_consistent[u] + 1] += 1
    start = np.cumsum(start)
    order = np.empty(start[-1], np.int64)
    for u in by_score:
        if alive[u]:
            order[start[top - n_consistent[u]]] = u
            start[top - n_consistent[u]] += 1
    far0, far1 = kind0 == FAR, kind1 == FAR
    survive = survivors(np.concatenate((a0[far0], a1[far1])), np.concatenate((b0[far0], b1[far1])), order,
                        len(alive))
    supported = np.zeros(len(alive), np.bool_)
    for j in range(len(a0)):
        if kind0[j] == NEAR and survive[a0[j]] and survive[b0[j]]:
            supported[a0[j]] = supported[b0[j]] = True
    return alive & ~(survive & supported)
