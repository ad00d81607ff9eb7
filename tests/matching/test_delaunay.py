"""The compiled integer Delaunay triangulation (matching/delaunay.py) against exact definitions and Qhull."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from slime_match.matching.delaunay import MAX_SIDE, delaunay


def with_corners(pts: np.ndarray, lo: float, hi: float) -> np.ndarray:
    corners = np.array([[lo, lo], [hi, lo], [hi, hi], [lo, hi]], float)
    return np.unique(np.r_[pts, corners], axis=0)


def assert_delaunay(pts: np.ndarray, simplices: np.ndarray, neighbors: np.ndarray) -> None:
    """Positive orientation, an exact tiling of the bounding rectangle, neighbours across the edge facing
    each corner, and no point strictly inside any triangle's circumcircle (exact integer in-circle
    determinant)."""
    p = pts.astype(np.int64)
    for t, k in zip(*np.nonzero(neighbors >= 0)):
        edge = {simplices[t, (k + 1) % 3], simplices[t, (k + 2) % 3]}
        other = neighbors[t, k]
        assert edge <= set(simplices[other]) and t in neighbors[other]
    hull_edges = (neighbors < 0).sum()
    on_sides = ((p == p.min(0)) | (p == p.max(0))).any(1).sum()  # the hull is the rectangle
    assert hull_edges == on_sides
    a, b, c = p[simplices[:, 0]], p[simplices[:, 1]], p[simplices[:, 2]]
    twice_area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    assert np.all(twice_area > 0)
    assert twice_area.sum() == 2 * np.prod(np.ptp(p, 0))
    for t in range(len(simplices)):
        ad, bd, cd = a[t] - p, b[t] - p, c[t] - p
        det = ((ad ** 2).sum(1) * (bd[:, 0] * cd[:, 1] - cd[:, 0] * bd[:, 1])
               + (bd ** 2).sum(1) * (cd[:, 0] * ad[:, 1] - ad[:, 0] * cd[:, 1])
               + (cd ** 2).sum(1) * (ad[:, 0] * bd[:, 1] - bd[:, 0] * ad[:, 1]))
        assert np.all(det <= 0), f"triangle {t} has a point inside its circumcircle"


@pytest.mark.parametrize("n, span", [(3, 4), (60, 10), (400, 300), (1500, 50)])
def test_delaunay_property_and_count(n, span):
    """Random integer points, the denser ones on a small grid with many cocircular ties; Qhull gives the
    same number of triangles (2 P - h - 2 for h hull points)."""
    g = np.random.default_rng(n)
    pts = with_corners(np.rint(g.uniform(0, span, (n, 2))), -1, span + 1)
    pts = pts[g.permutation(len(pts))]
    simplices, neighbors = delaunay(pts)
    assert_delaunay(pts, simplices, neighbors)
    assert len(simplices) == len(Delaunay(pts).simplices)


def test_points_on_the_rectangle_sides_split_the_hull():
    """A border ring of collinear points along the sides (DTM's mesh hull) plus interior points."""
    side = np.arange(0, 41, 5.0)
    ring = np.unique(np.r_[np.c_[side, 0 * side], np.c_[side, 0 * side + 40], np.c_[0 * side, side],
                           np.c_[0 * side + 40, side]], axis=0)
    inner = np.unique(np.rint(np.random.default_rng(1).uniform(1, 39, (30, 2))), axis=0)
    pts = np.r_[ring, inner]
    simplices, neighbors = delaunay(pts)
    assert_delaunay(pts, simplices, neighbors)
    edges = {tuple(sorted((s[k], s[(k + 1) % 3]))) for s in simplices.tolist() for k in range(3)}
    for i, j in zip(range(8), range(1, 9)):  # consecutive points of the top side are joined
        top = [np.flatnonzero((pts == (5.0 * m, 0.0)).all(1))[0] for m in (i, j)]
        assert tuple(sorted(top)) in edges


def test_bad_point_sets_raise():
    square = np.array([[0, 0], [9, 0], [9, 9], [0, 9], [4, 4]], float)
    with pytest.raises(ValueError, match="corners"):
        delaunay(square[1:])
    with pytest.raises(ValueError, match="unique"):
        delaunay(np.r_[square, [[4, 4]]])
    with pytest.raises(ValueError, match="corners"):
        delaunay(np.array([[0, 0], [5, 0], [9, 0]], float))  # flat
    with pytest.raises(ValueError, match="px"):
        delaunay(square * (MAX_SIDE + 1))
