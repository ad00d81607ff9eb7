"""DTM's compiled mesh loops against numpy, scipy and brute force: neighbour tables, local affine maps, nearest
points, vertex merging and the carved mesh."""

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from slime_match.matching import delaunay as delaunay_module
from slime_match.matching import dtm_kernels, dtm_mesh

from .helpers import cross


def test_mesh_tables_against_triangle_list():
    """The per-point neighbour lists and the kept edges, from scipy's triangles."""
    g = np.random.default_rng(5)
    pts = np.unique(np.rint(g.uniform(0, 100, (120, 2))), axis=0)
    simplices = Delaunay(pts).simplices.astype(np.int64)
    negative = cross(pts[simplices[:, 1]] - pts[simplices[:, 0]], pts[simplices[:, 2]] - pts[simplices[:, 0]]) < 0
    simplices[negative] = simplices[negative][:, [0, 2, 1]]
    kept = 70
    first, degree, adjacent, edges = dtm_kernels.mesh_tables(simplices, len(pts), kept)
    half = {(s[(k + 1) % 3], s[(k + 2) % 3]) for s in simplices.tolist() for k in range(3)}
    assert {(p, q) for p in range(len(pts)) for q in adjacent[first[p]:first[p] + degree[p]]} == half
    assert sorted(map(tuple, edges.tolist())) == sorted((p, q) for p, q in half if p < q < kept)


def test_local_affine_fits():
    """Exact on an affine map (the ridge pulls toward the same global map); equal to the ridge-regularised
    least squares of numpy on noisy data; defined on a lone vertex."""
    g = np.random.default_rng(6)
    src = np.unique(np.rint(g.uniform(0, 200, (80, 2))), axis=0)
    tri = dtm_mesh._Triangulation.of(np.r_[src, [[-1, -1], [201, -1], [201, 201], [-1, 201]]], len(src))
    m, t = np.array([[1.1, 0.2], [-0.3, 0.9]]), np.array([5.0, -7.0])
    affine, offset = dtm_kernels.local_affine(src, tri.edges, src @ m.T + t, 1.0)
    np.testing.assert_allclose(affine, np.broadcast_to(m, affine.shape), atol=1e-9)
    np.testing.assert_allclose(offset, src @ m.T + t, atol=1e-7)

    dst = src @ m.T + t + g.normal(0, 3, src.shape)
    affine, offset = dtm_kernels.local_affine(src, tri.edges, dst, 1.0)
    glob = np.linalg.lstsq(np.c_[src - src.mean(0), np.ones(len(src))], dst, rcond=None)[0][:2]
    for v in (0, 17, 55):
        hood = np.r_[v, tri.edges[tri.edges[:, 0] == v, 1], tri.edges[tri.edges[:, 1] == v, 0]]
        f = np.c_[src[hood] - src[v], np.ones(len(hood))]
        mat, rhs = f.T @ f, f.T @ dst[hood]
        mat[[0, 1], [0, 1]] += 1.0
        rhs[:2] += glob
        sol = np.linalg.solve(mat, rhs)
        np.testing.assert_allclose(affine[v], sol[:2].T, atol=1e-9)
        np.testing.assert_allclose(offset[v], sol[2], atol=1e-7)

    affine, offset = dtm_kernels.local_affine(src[:1], np.zeros((0, 2), np.int64), dst[:1], 1.0)
    np.testing.assert_allclose(affine, 0.0)
    np.testing.assert_allclose(offset, dst[:1])


def test_nearest_point_flags_exact_ties():
    """Brute-force nearest kept point (the first n), with exact ties flagged; untied answers are cKDTree's."""
    pts = np.array([[0.0, 0], [2, 0], [5, 5], [9, 9]])  # the last one is not kept
    q = np.array([[1.0, 0], [0, 1], [8, 8], [4, 5]])
    nearest, tied = dtm_kernels.nearest_point(pts, 3, q)
    np.testing.assert_array_equal(tied, [True, False, False, False])
    np.testing.assert_array_equal(nearest[1:], [0, 2, 2])
    g = np.random.default_rng(7)
    pts = np.unique(np.rint(g.uniform(0, 50, (200, 2))), axis=0)
    q = np.rint(g.uniform(0, 50, (500, 2)))
    nearest, tied = dtm_kernels.nearest_point(pts, len(pts), q)
    d2 = ((q[:, None] - pts[None]) ** 2).sum(2)
    np.testing.assert_array_equal(tied, (d2 == d2.min(1, keepdims=True)).sum(1) > 1)
    np.testing.assert_array_equal(d2[np.arange(len(q)), nearest], d2.min(1))
    np.testing.assert_array_equal(nearest[~tied], cKDTree(pts).query(q[~tied])[1])


def test_grid_vertices_and_unique_inverse_match_numpy():
    g = np.random.default_rng(8)
    xy = np.r_[g.uniform(-5, 45, (300, 2)), [[2.5, 3.5], [1.5, 0.5], [np.inf, -np.inf]]]
    xy[:50] = np.rint(xy[:50]) + 0.5  # rounding ties go to even
    h, w = 30, 40
    r = np.clip(np.rint(xy), [0, 0], [w - 1, h - 1])
    keys, inverse = np.unique(r[:, 1] * (w + 2) + r[:, 0], return_inverse=True)
    got, got_inverse = dtm_kernels.grid_vertices(xy, w, h)
    np.testing.assert_array_equal(got, np.c_[keys % (w + 2), keys // (w + 2)])
    np.testing.assert_array_equal(got_inverse, inverse)
    ints = g.integers(-3, 9, 100)
    for got, want in zip(dtm_kernels.unique_inverse(ints), np.unique(ints, return_inverse=True)):
        np.testing.assert_array_equal(got, want)


def test_carved_mesh_keeps_the_free_points_touching_the_ring():
    """The free points kept are those sharing a triangle with a ring point in the triangulation of
    everything; the mesh is the triangulation of the points plus them, with its tables."""
    g = np.random.default_rng(9)
    side = np.r_[np.arange(-1, 60, 10), 60]
    ring = np.array([[x, y] for x in side for y in (-1, 60)] + [[x, y] for x in (-1, 60) for y in side[1:-1]], float)
    inner = np.unique(np.rint(g.uniform(0, 59, (90, 2))), axis=0)
    kept, free = inner[:40], inner[40:]
    points = np.r_[kept, ring]
    everything = np.r_[points, free]
    simplices = delaunay_module.delaunay(everything)[0]
    touching = simplices[(np.isin(simplices, np.arange(40, len(points)))).any(1)]
    carved = np.unique(touching[touching >= len(points)]) - len(points)
    assert 0 < len(carved) < len(free)
    got = dtm_kernels.carved_mesh(points, 40, free)
    np.testing.assert_array_equal(got[0], np.r_[points, free[carved]])
    simplices, neighbors = delaunay_module.delaunay(got[0])
    np.testing.assert_array_equal(got[1], simplices)
    np.testing.assert_array_equal(got[2], neighbors)
    for a, b in zip(got[3:7], dtm_kernels.mesh_tables(simplices, len(got[0]), 40)):
        np.testing.assert_array_equal(a, b)
    assert got[7] == 0
    assert dtm_kernels.carved_mesh(np.delete(points, 40, 0), 40, free)[7] == 1  # corner (-1, -1) missing
