"""One image's DTM mesh: the Delaunay triangulation of its kept vertices, a border ring and the unmatched keypoints
that carve the hull, with its neighbour tables, point location, local affine maps and the transfer test of
expansion; and the merging of positions into vertices.

Meshes come from a compiled incremental Delaunay triangulation with exact integer predicates (``delaunay``);
expansion locates points by a visibility walk. The loops are compiled (``dtm_kernels``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np
from scipy.spatial import cKDTree

from .delaunay import check
from .dtm_kernels import (
    carved_mesh,
    grid_vertices,
    local_affine,
    locate,
    nearest_point,
    transfer_test,
    walk_tables,
)

_RIDGE = 1.0  # px^2, local affine fits: negligible against real neighbourhoods, decisive for degenerate ones
_NO_POINTS = np.empty((0, 2))
_BRUTE_FORCE_MAX = 1 << 20  # vertices x queries up to which a compiled scan finds nearest vertices (~1 ms)


@dataclass
class _Triangulation:
    """A planar Delaunay triangulation whose hull is the border ring, with its tables
    (``dtm_kernels.mesh_tables``).

    Attributes:
        points: (P, 2) float64 integer-valued vertex positions.
        simplices: (T, 3) int64 vertex indices, counter-clockwise in x-right, y-down pixel axes (positive
            cross product).
        neighbors: (T, 3) triangle across the edge facing each corner, -1 on the hull.
        first, degree, adjacent: (P,), (P,), (3 T,) the Delaunay neighbours of each point (CSR).
        edges: (E, 2) undirected edges between kept points (the first ones), a < b.
    """

    points: np.ndarray
    simplices: np.ndarray
    neighbors: np.ndarray
    first: np.ndarray
    degree: np.ndarray
    adjacent: np.ndarray
    edges: np.ndarray

    @classmethod
    def of(cls, points: np.ndarray, kept: int | None = None, free: np.ndarray | None = None) -> _Triangulation:
        """Triangulate unique integer-valued (P, 2) points that include the four corners of their bounding
        rectangle, the first ``kept`` (default all) being kept points, plus those of the free points (F, 2)
        that carve the hull (``dtm_kernels.carved_mesh``)."""
        points = np.ascontiguousarray(points, np.float64)
        *mesh, error = carved_mesh(points, len(points) if kept is None else kept,
                                   _NO_POINTS if free is None else free)
        check(error)
        return cls(*mesh)

    @cached_property
    def walk(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Tables lines, across, start, proper of ``dtm_kernels.locate`` and ``transfer_test``."""
        return walk_tables(self.points, self.simplices, self.neighbors)

    def locate(self, q: np.ndarray, near: np.ndarray) -> np.ndarray:
        """(Q,) index of the triangle containing each point q (Q, 2), -1 outside the hull, walking from the
        point near (Q,) close to each. Exact on integer-valued queries."""
        lines, across, start, _ = self.walk
        return locate(lines, across, start, np.ascontiguousarray(q, np.float64), near)


@dataclass
class _Mesh:
    """Triangulation of one image's kept vertices plus border vertices.

    Attributes:
        tri: triangulation; points [0, n) are the kept vertices (``vertex`` ids), the rest are border.
        vertex: (n,) global vertex id of each non-border point, ascending.
        local: (V,) point index of each global vertex, -1 for those not kept.
    """

    tri: _Triangulation
    vertex: np.ndarray
    local: np.ndarray
    _affine: tuple[bytes, tuple[np.ndarray, np.ndarray]] | None = field(default=None, init=False, repr=False)

    def local_affine(self, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``dtm_kernels.local_affine`` of the kept vertices to their positions dst (n, 2) in the other image:
        A (n, 2, 2), c (n, 2) with dst ~ c + A (x - src[v]) near vertex v; remembered for the last dst."""
        key = dst.tobytes()
        if self._affine is None or self._affine[0] != key:
            n = len(self.vertex)
            self._affine = key, local_affine(self.tri.points[:n], self.tri.edges, dst, _RIDGE)
        return self._affine[1]

    @cached_property
    def tree(self) -> cKDTree:
        """k-d tree of the kept vertices (resolves ties in ``_transfer_ok``)."""
        return cKDTree(self.tri.points[: len(self.vertex)])


@lru_cache(maxsize=256)
def _border_ring(size: tuple[int, int], step: int) -> np.ndarray:
    """(R, 2) integer points every ``step`` px along the four image sides, 1 px outside the pixel grid
    (cached, read-only)."""
    h, w = size
    xs = np.append(np.arange(-1, w, step), w).astype(np.float64)
    ys = np.arange(step - 1, h, step, dtype=np.float64)
    x = np.concatenate([xs, xs, np.full_like(ys, -1.0), np.full_like(ys, float(w))])
    y = np.concatenate([np.full_like(xs, -1.0), np.full_like(xs, float(h)), ys, ys])
    ring = np.stack([x, y], 1)
    ring.flags.writeable = False
    return ring


def _triangulate(vertex: np.ndarray, vertex_xy: np.ndarray, size: tuple[int, int],
                 unmatched: np.ndarray | None, border_spacing: float) -> _Mesh:
    """Delaunay mesh of the given vertices, the border ring and the carving unmatched keypoints.

    The unmatched keypoints that share a Delaunay triangle with the ring (in the triangulation of
    everything) become border vertices; the other unmatched keypoints are left out. This carves the hull:
    long triangles over areas without kept matches now touch a border vertex.

    Args:
        vertex: (n,) ascending global ids of the kept vertices; vertex_xy: (V, 2) integer positions of all
            vertices.
        unmatched: (U >= 1, 2) unique rounded unmatched keypoints of this image off all candidate vertices,
            or None.
        border_spacing: ``DTMConfig.border_spacing``.
    """
    n = len(vertex)
    h, w = size
    border = _border_ring(size, max(round(float(border_spacing * math.sqrt(w * h / max(n, 1)))), 1))
    tri = _Triangulation.of(np.concatenate([vertex_xy[vertex], border]), n, unmatched)
    local = np.full(len(vertex_xy), -1, np.int64)
    local[vertex] = np.arange(n)
    return _Mesh(tri, vertex, local)


def _transfer_ok(mesh: _Mesh, dst_v: np.ndarray, q_src: np.ndarray, q_dst: np.ndarray,
                 tol: float) -> np.ndarray:
    """Whether q_dst lies in the image of the triangle that contains q_src.

    The triangle's image must have the same (positive) orientation; each side may miss q_dst by ``tol`` px.

    Args:
        dst_v: (n >= 1, 2) position in the other image of each kept vertex's representative match.
        q_src, q_dst: (P, 2) integer positions of the tested units in this and the other image.

    Returns:
        (P,) bool.
    """
    tri, n = mesh.tri, len(mesh.vertex)
    if n * len(q_src) <= _BRUTE_FORCE_MAX:
        nearest, tied = nearest_point(tri.points, n, q_src)
        if tied.any():  # cKDTree's pick among equidistant vertices: it seeds the walk and maps border corners
            nearest[tied] = mesh.tree.query(q_src[tied])[1]
    else:
        nearest = mesh.tree.query(q_src)[1]
    affine, offset = mesh.local_affine(dst_v)
    return transfer_test(tri.points, tri.simplices, tri.walk[3], n, tri.locate(q_src, nearest), nearest, dst_v,
                         affine, offset, np.ascontiguousarray(q_dst, np.float64), tol)


def _vertices(xy: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Rounded, clipped positions merged into vertices: (V, 2) float positions (by row, then column), (K,)
    vertex of each point."""
    return grid_vertices(np.ascontiguousarray(xy, np.float64), size[1], size[0])


def _row_keys(xy: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """int64 key of integer positions inside the image (ascending with ``_vertices``' order)."""
    return xy[:, 1].astype(np.int64) * (size[1] + 2) + xy[:, 0].astype(np.int64)


def _prepare_unmatched(xy: np.ndarray | None, size: tuple[int, int],
                       vertex_xy: np.ndarray) -> np.ndarray | None:
    """(U, 2) unique rounded unmatched keypoints off the candidates' vertices (V >= 1, 2), or None if none."""
    if xy is None or len(xy) == 0:
        return None
    free = _vertices(np.asarray(xy, np.float64).reshape(-1, 2), size)[0]
    keys, taken = _row_keys(free, size), _row_keys(vertex_xy, size)
    free = free[taken[np.minimum(np.searchsorted(taken, keys), len(taken) - 1)] != keys]
    return free if len(free) else None
