"""DTM's compiled contraction loops against brute force: the survivors of a ranked walk, the near unit pairs of a
mesh and the relation of two mesh points."""

import numpy as np

from slime_match.matching import dtm_contraction_kernels, dtm_mesh
from slime_match.matching.dtm import DTMConfig


def test_greedy_survivors_matches_sequential_walk():
    g = np.random.default_rng(0)
    n = 300
    pairs = np.unique(np.sort(g.integers(0, n, (900, 2)), 1), axis=0)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    rank = g.permutation(n)
    a = np.where(rank[pairs[:, 0]] < rank[pairs[:, 1]], pairs[:, 0], pairs[:, 1])
    b = np.where(rank[pairs[:, 0]] < rank[pairs[:, 1]], pairs[:, 1], pairs[:, 0])
    alive = g.uniform(size=n) < 0.9
    ref = alive.copy()
    for u in np.argsort(rank):
        if ref[u]:
            ref[b[(a == u) & alive[b]]] = False
    sel = alive[a] & alive[b]
    order = np.argsort(rank)
    order = order[alive[order]]
    swap = g.uniform(size=sel.sum()) < 0.5  # the kernel takes the pairs in either order
    a, b = np.where(swap, b[sel], a[sel]), np.where(swap, a[sel], b[sel])
    np.testing.assert_array_equal(dtm_contraction_kernels.survivors(a, b, order, n), ref)


def test_near_pairs_and_classify_match_brute_force():
    """Near pairs from the mesh edges and the near / more-than-two-edges-apart tests against graph
    distances computed on a dense adjacency matrix."""
    g = np.random.default_rng(4)
    size = (120, 160)
    vxy = np.unique(np.rint(g.uniform(0, [159, 119], (150, 2))), axis=0)
    vertex = np.sort(g.choice(len(vxy), 60, replace=False))
    unmatched = np.unique(np.rint(g.uniform(0, [159, 119], (80, 2))), axis=0)
    unmatched = unmatched[~(unmatched[:, None] == vxy[None]).all(2).any(1)]
    mesh = dtm_mesh._triangulate(vertex, vxy, size, unmatched, DTMConfig().border_spacing)
    n, big = len(vertex), len(mesh.tri.points)
    adj = np.zeros((big, big), bool)
    tri = mesh.tri
    for p in range(big):
        adj[p, tri.adjacent[tri.first[p]:tri.first[p] + tri.degree[p]]] = True
    within_two = adj | (adj.astype(int) @ adj.astype(int) > 0) | np.eye(big, dtype=bool)
    near = adj | np.eye(big, dtype=bool)
    # units: 1 to 3 per kept vertex
    unit_point = np.repeat(np.arange(n), g.integers(1, 4, n))
    units = g.permutation(len(unit_point)) + 5  # arbitrary ids
    order = np.argsort(unit_point, kind="stable")
    start = np.r_[0, np.bincount(unit_point, minlength=n).cumsum()]
    a, b = dtm_contraction_kernels.near_unit_pairs(units[order], start, tri.edges)
    point_of = dict(zip(units, unit_point))
    got = {(min(x, y), max(x, y)) for x, y in zip(a, b)}
    assert len(got) == len(a)  # each pair once
    expected = {(min(x, y), max(x, y)) for i, x in enumerate(units) for y in units[i + 1:]
                if near[point_of[x], point_of[y]]}
    assert got == expected
    p, q = g.integers(0, n, (2, 3000))
    p[::2] = p[1::2]  # runs of one p (marks reused) and changes of p (marks redone, stale ones left)
    mark = np.full(big + 1, -1, np.int64)
    kind = np.array([dtm_contraction_kernels.relation(i, j, tri.first, tri.degree, tri.adjacent, mark) for i, j in zip(p, q)])
    is_near, is_far = kind == dtm_contraction_kernels.NEAR, kind == dtm_contraction_kernels.FAR
    np.testing.assert_array_equal(is_near, near[p, q])
    np.testing.assert_array_equal(is_far, ~within_two[p, q])
