"""One image's DTM mesh: its triangulation and point location against Qhull."""

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from slime_match.matching import dtm_mesh

from .helpers import cross


def test_delaunay_and_locate_match_scipy():
    g = np.random.default_rng(0)
    pts = np.unique(np.rint(g.uniform(0, 300, (500, 2))), axis=0)
    pts = np.r_[pts, [[-1, -1], [301, -1], [301, 301], [-1, 301]]]
    tri = dtm_mesh._Triangulation.of(pts)
    ref = Delaunay(pts)
    # same triangle count and area as Qhull (ties between cocircular points may flip a few edges)
    area = lambda s: cross(pts[s[:, 1]] - pts[s[:, 0]], pts[s[:, 2]] - pts[s[:, 0]])
    assert len(tri.simplices) == len(ref.simplices) and area(tri.simplices).sum() == np.abs(area(ref.simplices)).sum()
    assert np.all(area(tri.simplices) > 0)  # counter-clockwise in x-right, y-down axes
    for q in (g.uniform(-0.5, 300.5, (2000, 2)), np.rint(g.uniform(-1, 301, (2000, 2)))):  # integer: on edges
        found = tri.locate(q, cKDTree(pts).query(q)[1])
        assert np.all(found >= 0)
        corners = pts[tri.simplices[found]]  # (P, 3, 2): q inside its triangle (barycentric test)
        lam = np.stack([cross(corners[:, (k + 1) % 3] - q, corners[:, (k + 2) % 3] - q) for k in range(3)], 1)
        assert np.all(lam >= -1e-9)
    # neighbours are symmetric and share an edge
    t, k = np.nonzero(tri.neighbors >= 0)
    assert np.all((tri.neighbors[tri.neighbors[t, k]] == t[:, None]).any(1))
    far = np.array([[-50.0, 0.0], [400.0, 400.0]])
    assert np.all(tri.locate(far, cKDTree(pts).query(far)[1]) == -1)
