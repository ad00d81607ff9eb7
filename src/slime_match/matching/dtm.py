"""DTM: Delaunay Triangulation Matching, a spatial filter of many-to-many candidate matches.

ALGORITHMS.md section 4. Matches are first grouped into *units*, the distinct pairs of rounded positions
(v0, v1): duplicated matches share their fate. Two units are *near* in an image when they sit on the same
vertex or on two Delaunay-adjacent non-border vertices; they are consistent when near in both images and
inconsistent when near in one image and more than two Delaunay edges apart in the other. Contraction
repeatedly removes, walking the units by rank, the inconsistent neighbours of every surviving unit, then
drops survivors without a surviving consistent neighbour. Expansion walks the removal iterations from the
last to the first; at each it re-triangulates the kept units and puts back every unit removed at that
iteration or later (so a unit rejected by a coarse mesh gets another chance on the denser ones) whose
position is predicted in both directions: its point lies in the image of the kept triangle containing its
other point (border triangles: border corners mapped by the local affine fit of the nearest kept vertex's
neighbourhood).

Deviations from the spec, all for low inlier ratios and strong viewpoint changes (Oxford graf 1->4 Blob
candidates, ~6-20% correct, used to collapse to 2 matches):

- *Flip tolerance.* Near in one image but two edges apart in the other (through any vertex, border ones
  included) is neither consistent nor inconsistent: under perspective a Delaunay edge between two correct
  matches is often flipped in the other image, and an edge over an empty area may pass on the other side
  of a carving keypoint. Counting these as inconsistent made correct matches remove each other, iteration
  after iteration, down to a handful.
- *Rank.* Units are ranked by the number of consistent neighbours (descending), then by score (ascending);
  the spec's order (score, ties by count) never uses the count on continuous Blob scores, and the
  best-scored outliers, which are the majority there, removed the inliers around them.
- *Settling.* Contraction stops at an iteration that would remove fewer than ``settle_fraction`` of the
  alive units (and does not remove them): the long tail of iterations removing a few units each costs
  most of the time and expansion
  restores the same final set.

Everything is sparse: adjacency as sorted int64 pair keys, OpenCV's incremental Delaunay (``Subdiv2D``,
several times faster than Qhull on integer positions), vectorised point location by a visibility walk.
"""

from __future__ import annotations

import logging
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from scipy.spatial import cKDTree

from ..errors import ConfigError
from ..options import config_from_dict

log = logging.getLogger("slime_match")
_PARALLEL_MIN = 6000  # points (candidates + unmatched) from which both meshes are built in two threads


@dataclass
class DTMConfig:
    """DTM parameters.

    Attributes:
        border_spacing: spacing of the border ring vertices, as a multiple of sqrt(W * H / n_vertices).
        inside_tolerance: pixels by which a point may fall outside the predicted triangle in expansion.
        max_iterations: safety bound on contraction iterations.
        settle_fraction: contraction stops, keeping the alive units, at an iteration that would remove fewer
            than this fraction of them (0: only when nothing is removed, as in the spec).
    """

    border_spacing: float = 1.0
    inside_tolerance: float = 2.0
    max_iterations: int = 100
    settle_fraction: float = 0.01

    def __post_init__(self) -> None:
        if not self.border_spacing > 0:
            raise ConfigError(f"DTMConfig.border_spacing must be > 0, got {self.border_spacing}")
        if self.inside_tolerance < 0:
            raise ConfigError(f"DTMConfig.inside_tolerance must be >= 0 px, got {self.inside_tolerance}")
        if self.max_iterations < 1:
            raise ConfigError(f"DTMConfig.max_iterations must be >= 1, got {self.max_iterations}")
        if not 0 <= self.settle_fraction < 1:
            raise ConfigError(f"DTMConfig.settle_fraction must be in [0, 1), got {self.settle_fraction}")

    @classmethod
    def from_dict(cls, options: dict) -> DTMConfig:
        """Config from a dict; unknown keys raise ConfigError."""
        return config_from_dict(cls, options)


@dataclass
class DTMResult:
    """Per-candidate DTM outcome.

    Attributes:
        keep: (K,) bool, the match passes DTM.
        removed_at: (K,) int64 contraction iteration at which the match was removed, -1 if never.
        restored: (K,) bool, removed in contraction and put back in expansion.
    """

    keep: np.ndarray
    removed_at: np.ndarray
    restored: np.ndarray


def _delaunay(points: np.ndarray) -> np.ndarray:
    """(T, 3) int64 Delaunay triangles of unique integer-valued points (OpenCV's incremental Subdiv2D),
    counter-clockwise in x-right, y-down pixel axes (positive cross product).

    Args:
        points: (P, 2) float64 unique integer positions, P >= 3 and not all collinear.
    """
    lo = points.min(0).astype(np.int64) - 2
    span = points.max(0).astype(np.int64) - lo + 3
    # a far bounding box keeps Subdiv2D's virtual outer vertices from shadowing hull triangles
    far = 50 * int(span.max())
    box = (int(lo[0]) - far, int(lo[1]) - far, int(span[0]) + 2 * far, int(span[1]) + 2 * far)
    subdiv = cv2.Subdiv2D(box)
    # insertion along a snake of horizontal strips keeps Subdiv2D's point location walks short
    strip = max(int(4 * np.sqrt(span[0] * span[1] / len(points))), 1)
    row = (points[:, 1].astype(np.int64) - lo[1]) // strip
    subdiv.insert(points[np.lexsort((np.where(row % 2 == 0, points[:, 0], -points[:, 0]), row))]
                  .astype(np.float32))
    corners = np.rint(subdiv.getTriangleList().reshape(-1, 2)).astype(np.int64) - lo
    index = np.empty(int(span[0] * span[1]), np.int64)  # position -> point lookup, only written cells read
    index[(points.astype(np.int64) - lo) @ np.array([1, span[0]])] = np.arange(len(points))
    simp = index[corners @ np.array([1, span[0]])].reshape(-1, 3)
    d = points[simp[:, 1:]] - points[simp[:, :1]]
    flip = d[:, 0, 0] * d[:, 1, 1] - d[:, 0, 1] * d[:, 1, 0] < 0
    simp[flip] = simp[flip][:, [0, 2, 1]]
    return simp


@dataclass
class _Triangulation:
    """A planar Delaunay triangulation whose hull is the border ring (SciPy's ``Delaunay`` layout).

    Attributes:
        points: (P, 2) float64 integer-valued vertex positions.
        simplices: (T, 3) int64 counter-clockwise vertex indices (see ``_delaunay``).
        half_edges: (3 T, 2) directed Delaunay edges: every pair of neighbours once in each direction,
            except along the hull, where only border vertices lie.
    """

    points: np.ndarray
    simplices: np.ndarray
    half_edges: np.ndarray

    @classmethod
    def of(cls, points: np.ndarray) -> _Triangulation:
        """Triangulate unique integer-valued (P, 2) points."""
        simp = _delaunay(points)
        # the edge facing corner k runs from corner k + 1 to corner k + 2
        return cls(points, simp, np.stack([simp[:, [1, 2, 0]], simp[:, [2, 0, 1]]], 2).reshape(-1, 2))

    @cached_property
    def neighbors(self) -> np.ndarray:
        """(T, 3) triangle across the edge facing each corner, -1 on the hull."""
        half, n = self.half_edges, len(self.points)
        # the twin of a half edge runs the other way in the neighbouring triangle
        undirected = np.minimum(half[:, 0], half[:, 1]) * n + np.maximum(half[:, 0], half[:, 1])
        order = np.argsort(undirected, kind="stable")
        twin = np.full(len(half), -1, np.int64)
        same = undirected[order][1:] == undirected[order][:-1]
        twin[order[1:][same]], twin[order[:-1][same]] = order[:-1][same], order[1:][same]
        return np.where(twin >= 0, twin // 3, -1).reshape(-1, 3)


@dataclass
class _Mesh:
    """Triangulation of one image's kept vertices plus border vertices.

    Attributes:
        tri: triangulation; points [0, n) are the kept vertices (``vertex`` ids), the rest are border.
        vertex: (n,) global vertex id of each non-border point.
        edges: (E, 2) undirected Delaunay edges between non-border points (local indices, a < b).
    """

    tri: _Triangulation
    vertex: np.ndarray
    edges: np.ndarray


def _border_ring(size: tuple[int, int], n_vertices: int, scale: float) -> np.ndarray:
    """(R, 2) integer points along the four image sides, 1 px outside the pixel grid."""
    h, w = size
    step = max(round(float(scale * np.sqrt(w * h / max(n_vertices, 1)))), 1)
    xs = np.append(np.arange(-1, w, step), w).astype(np.float64)
    ys = np.arange(step - 1, h, step, dtype=np.float64)
    x = np.concatenate([xs, xs, np.full_like(ys, -1.0), np.full_like(ys, float(w))])
    y = np.concatenate([np.full_like(xs, -1.0), np.full_like(xs, float(h)), ys, ys])
    return np.stack([x, y], 1)


def _triangulate(vertex: np.ndarray, vertex_xy: np.ndarray, size: tuple[int, int],
                 unmatched: np.ndarray | None, cfg: DTMConfig) -> _Mesh:
    """Delaunay mesh of the given vertices, the border ring and the carving unmatched keypoints.

    The unmatched keypoints that share a Delaunay triangle with the ring (in the triangulation of
    everything) become border vertices; the other unmatched keypoints are left out. This carves the hull:
    long triangles over areas without kept matches now touch a border vertex.

    Args:
        vertex: (n,) global ids of the kept vertices; vertex_xy: (V, 2) integer positions of all vertices.
        unmatched: (U >= 1, 2) unique rounded unmatched keypoints of this image off all candidate vertices,
            or None.
    """
    pts = vertex_xy[vertex]
    n = len(pts)
    border = _border_ring(size, n, cfg.border_spacing)
    if unmatched is not None:
        first_free = n + len(border)
        s = _delaunay(np.concatenate([pts, border, unmatched]))
        ring_tri = s[((s >= n) & (s < first_free)).any(1)]
        carved = np.zeros(len(unmatched), bool)
        carved[ring_tri[ring_tri >= first_free] - first_free] = True
        border = np.concatenate([border, unmatched[carved]])
    tri = _Triangulation.of(np.concatenate([pts, border]))
    e = tri.half_edges
    e = e[(e[:, 0] < e[:, 1]) & (e[:, 1] < n)]
    return _Mesh(tri, vertex, e)


def _locate(tri: _Triangulation, q: np.ndarray, near: np.ndarray) -> np.ndarray:
    """(P,) index of the triangle containing each query point, -1 outside the hull.

    Vectorised visibility walk from a triangle at a vertex near each query (``tri.neighbors`` across the
    edge facing the most negative barycentric coordinate); it terminates on Delaunay triangulations.

    Args:
        q: (P, 2) query points; near: (P,) index of a vertex of ``tri`` close to each query.
    """
    pts, simp, nbr = tri.points, tri.simplices, tri.neighbors
    start = np.empty(len(pts), np.int64)
    start[simp.ravel()] = np.repeat(np.arange(len(simp)), 3)
    cur = start[near]
    out = np.full(len(q), -1, np.int64)
    todo = np.arange(len(q))
    for _ in range(len(simp) + 1):
        if not len(todo):
            break
        d = pts[simp[cur[todo]]] - q[todo, None, :]  # (m, 3, 2) corners relative to the query
        d1, d2 = d[:, [1, 2, 0]], d[:, [2, 0, 1]]
        lam = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]  # (m, 3) twice the barycentric areas
        inside = (lam >= 0).all(1)
        out[todo[inside]] = cur[todo[inside]]
        step = nbr[cur[todo], np.argmin(lam, 1)]
        move = ~inside & (step >= 0)
        cur[todo[move]] = step[move]
        todo = todo[move]
    return out


def _row_keys(xy: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """int64 key of integer positions inside the image."""
    return xy[:, 1].astype(np.int64) * (size[1] + 2) + xy[:, 0].astype(np.int64)


def _near_pairs(unit_vertex: np.ndarray, alive: np.ndarray, mesh: _Mesh, n_units: int) -> np.ndarray:
    """Sorted int64 keys a * n_units + b of ordered unit pairs a != b, both alive, near in this image."""
    units = np.flatnonzero(alive)
    n = len(mesh.vertex)
    local = np.full(unit_vertex.max() + 1, -1, np.int64)
    local[mesh.vertex] = np.arange(n)
    lv = local[unit_vertex[units]]
    order = np.argsort(lv, kind="stable")
    units, lv = units[order], lv[order]
    count = np.bincount(lv, minlength=n)
    start = np.cumsum(count) - count
    a = np.concatenate([mesh.edges[:, 0], mesh.edges[:, 1], np.arange(n)])
    b = np.concatenate([mesh.edges[:, 1], mesh.edges[:, 0], np.arange(n)])
    pairs = count[a] * count[b]
    e = np.repeat(np.arange(len(a)), pairs)
    offset = np.arange(len(e)) - np.repeat(np.cumsum(pairs) - pairs, pairs)
    ua = units[start[a[e]] + offset // count[b[e]]]
    ub = units[start[b[e]] + offset % count[b[e]]]
    keys = ua * n_units + ub
    return np.sort(keys[ua != ub])


def _within_two(mesh: _Mesh, unit_vertex: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(P,) whether the vertices of units a and b in this mesh are at most two Delaunay edges apart.

    The middle vertex may be a border vertex: an edge over an empty area in one image may well pass on
    the other side of a carving keypoint in the other image.
    """
    n = len(mesh.tri.points)
    local = np.full(unit_vertex.max() + 1, -1, np.int64)
    local[mesh.vertex] = np.arange(len(mesh.vertex))
    edge = np.sort(mesh.tri.half_edges[:, 0] * n + mesh.tri.half_edges[:, 1])  # CSR order by source
    deg = np.bincount(edge // n, minlength=n)
    start = np.cumsum(deg) - deg
    qa, qb = local[unit_vertex[a]], local[unit_vertex[b]]
    # every path qa -> k -> qb: k runs over the neighbours of qa
    path = np.repeat(np.arange(len(qa)), deg[qa])
    group = np.cumsum(deg[qa]) - deg[qa]
    middle = edge[np.arange(len(path)) - group[path] + start[qa][path]] % n
    hop = np.zeros(len(qa), bool)
    hop[path[_member(edge, middle * n + qb[path])]] = True
    return hop | _member(edge, qa * n + qb)


def _member(sorted_keys: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(Q,) whether each query key is in the sorted int64 keys."""
    pos = np.minimum(np.searchsorted(sorted_keys, q), len(sorted_keys) - 1)
    return sorted_keys[pos] == q


def _greedy_survivors(a: np.ndarray, b: np.ndarray, alive: np.ndarray) -> np.ndarray:
    """Units surviving the walk by rank where each surviving unit removes its inconsistent neighbours.

    Vectorised in rounds with the same result as the sequential walk: a unit dies once a better-ranked
    inconsistent neighbour is known to survive, and survives once all of them are known to die.

    Args:
        a, b: (E,) inconsistent unit pairs with rank[a] < rank[b] (a can remove b).
        alive: (U,) units taking part.
    """
    state = np.where(alive, 0, -1).astype(np.int8)  # 0 undecided, 1 survives, -1 removed / absent
    while True:
        undecided_b = state[b] == 0
        a_r, b_r = a[undecided_b], b[undecided_b]
        if not len(b_r):
            state[state == 0] = 1
            return state == 1
        killed = np.zeros(len(state), bool)
        killed[b_r[state[a_r] == 1]] = True
        blocked = np.zeros(len(state), bool)
        blocked[b_r[state[a_r] == 0]] = True
        undecided = state == 0
        state[undecided & killed] = -1
        state[undecided & ~killed & ~blocked] = 1
        a, b = a_r, b_r


def _local_affine(mesh: _Mesh, src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Affine map image -> other image around each mesh vertex, fitted on its closed neighbourhood.

    Ridge-regularised toward the global affine fit so that degenerate neighbourhoods stay defined.

    Args:
        src, dst: (n, 2) positions of each mesh vertex and of its representative match in the other image.

    Returns:
        A (n, 2, 2), c (n, 2): dst ~ c + A (x - src[v]) near vertex v.
    """
    n = len(src)
    glob = np.linalg.lstsq(np.column_stack([src - src.mean(0), np.ones(n)]), dst, rcond=None)[0]
    v = np.concatenate([mesh.edges[:, 0], mesh.edges[:, 1], np.arange(n)])
    w = np.concatenate([mesh.edges[:, 1], mesh.edges[:, 0], np.arange(n)])
    f = np.column_stack([src[w] - src[v], np.ones(len(v))])  # (E, 3)
    terms = np.concatenate([(f[:, :, None] * f[:, None, :]).reshape(-1, 9),
                            (f[:, :, None] * dst[w][:, None, :]).reshape(-1, 6)], 1)  # (E, 15)
    order = np.argsort(v, kind="stable")
    count = np.bincount(v, minlength=n)  # >= 1: every vertex is in its own neighbourhood
    sums = np.add.reduceat(terms[order], np.cumsum(count) - count)
    mat, rhs = sums[:, :9].reshape(n, 3, 3), sums[:, 9:].reshape(n, 3, 2)
    ridge = 1.0  # px^2: negligible against real neighbourhoods, decisive for degenerate ones
    mat[:, [0, 1], [0, 1]] += ridge
    rhs[:, :2, :] += ridge * glob[:2][None]
    sol = np.linalg.solve(mat, rhs)
    return np.transpose(sol[:, :2, :], (0, 2, 1)), sol[:, 2, :]


def _transfer_ok(mesh: _Mesh, vertex_xy_src: np.ndarray, rep_dst: np.ndarray, q_src: np.ndarray,
                 q_dst: np.ndarray, tol: float) -> np.ndarray:
    """Whether q_dst lies in the image of the triangle that contains q_src.

    Args:
        vertex_xy_src: (V, 2) vertex positions in this image; rep_dst: (V, 2) position in the other image of
            each vertex's representative kept match.
        q_src, q_dst: (P, 2) the tested units in this and the other image.

    Returns:
        (P,) bool.
    """
    tri, n = mesh.tri, len(mesh.vertex)
    if len(q_src) == 0 or n == 0:
        return np.zeros(len(q_src), bool)
    src_v = vertex_xy_src[mesh.vertex].astype(np.float64)
    dst_v = rep_dst[mesh.vertex]
    _, nearest = cKDTree(src_v).query(q_src)
    simplex = _locate(tri, q_src, nearest)
    found = simplex >= 0
    corners = tri.simplices[np.maximum(simplex, 0)]  # (P, 3)
    src_tri = tri.points[corners]
    dst_tri = np.empty_like(src_tri)
    is_vertex = corners < n
    dst_tri[is_vertex] = dst_v[corners[is_vertex]]
    if not is_vertex.all():
        affine, offset = _local_affine(mesh, src_v, dst_v)
        nearest = np.broadcast_to(nearest[:, None], corners.shape)[~is_vertex]
        rel = src_tri[~is_vertex] - src_v[nearest]
        dst_tri[~is_vertex] = offset[nearest] + np.einsum("kij,kj->ki", affine[nearest], rel)
    sign_src = np.sign(_cross(src_tri[:, 1] - src_tri[:, 0], src_tri[:, 2] - src_tri[:, 0]))
    sign_dst = np.sign(_cross(dst_tri[:, 1] - dst_tri[:, 0], dst_tri[:, 2] - dst_tri[:, 0]))
    ok = found & (sign_src != 0) & (sign_src == sign_dst)
    for k in range(3):
        p, r = dst_tri[:, k], dst_tri[:, (k + 1) % 3]
        edge = r - p
        length = np.hypot(edge[:, 0], edge[:, 1])
        side = sign_dst * _cross(edge, q_dst - p)
        ok &= (length > 0) & (side >= -tol * length)
    return ok


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]


def _vertices(xy: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Rounded, clipped positions merged into vertices: (V, 2) float positions, (K,) vertex of each point."""
    h, w = size
    r = np.clip(np.rint(xy), [0, 0], [w - 1, h - 1])
    uniq, inverse = np.unique(_row_keys(r, size), return_inverse=True)
    return np.stack([uniq % (w + 2), uniq // (w + 2)], 1).astype(np.float64), inverse.reshape(-1)


def _prepare_unmatched(xy: np.ndarray | None, size: tuple[int, int],
                       vertex_xy: np.ndarray) -> np.ndarray | None:
    """(U, 2) unique rounded unmatched keypoints off the candidates' vertices (V, 2), or None if none."""
    if xy is None or len(xy) == 0:
        return None
    free = _vertices(np.asarray(xy, np.float64).reshape(-1, 2), size)[0]
    free = free[~np.isin(_row_keys(free, size), _row_keys(vertex_xy, size))]
    return free if len(free) else None


def dtm_filter(xy0: np.ndarray, xy1: np.ndarray, scores: np.ndarray, size0: tuple[int, int],
               size1: tuple[int, int], unmatched0: np.ndarray | None = None,
               unmatched1: np.ndarray | None = None, config: DTMConfig | dict | None = None) -> DTMResult:
    """Delaunay Triangulation Matching.

    Args:
        xy0, xy1: (K, 2) keypoint positions in pixels of the K candidate matches in images 0 and 1.
        scores: (K,) dissimilarities, lower is better.
        size0, size1: (H, W) image sizes in pixels.
        unmatched0, unmatched1: (N0, 2), (N1, 2) the other keypoints of each image (carve the hull).
        config: DTMConfig, a dict of its fields, or None for the defaults.

    Returns:
        DTMResult with per-candidate keep flags, removal iterations and restoration flags.
    """
    cfg = DTMConfig.from_dict(config) if isinstance(config, dict) else (config or DTMConfig())
    xy0 = np.asarray(xy0, np.float64).reshape(-1, 2)
    xy1 = np.asarray(xy1, np.float64).reshape(-1, 2)
    scores = np.asarray(scores, np.float64).reshape(-1)
    k = len(xy0)
    if not (len(xy1) == len(scores) == k):
        raise ValueError("xy0, xy1 and scores must have the same length")
    sizes = (tuple(int(s) for s in size0), tuple(int(s) for s in size1))
    if k == 0:
        return DTMResult(np.zeros(0, bool), np.zeros(0, np.int64), np.zeros(0, bool))

    (vxy0, v0), (vxy1, v1) = _vertices(xy0, sizes[0]), _vertices(xy1, sizes[1])
    unit_keys, unit_of = np.unique(v0 * len(vxy1) + v1, return_inverse=True)
    unit_of = unit_of.reshape(-1)
    uscore = np.full(len(unit_keys), np.inf)
    np.minimum.at(uscore, unit_of, scores)
    unmatched = (_prepare_unmatched(unmatched0, sizes[0], vxy0),
                 _prepare_unmatched(unmatched1, sizes[1], vxy1))
    n_points = k + sum(len(u) for u in unmatched if u is not None)
    pool = ThreadPoolExecutor(2) if n_points >= _PARALLEL_MIN else None
    try:
        units = _Units((unit_keys // len(vxy1), unit_keys % len(vxy1)), uscore, (vxy0, vxy1), sizes,
                       unmatched, cfg, pool)
        removed_at, iterations = units.contract()
        restored = units.expand(removed_at, iterations)
    finally:
        if pool is not None:
            pool.shutdown()
    log.debug("DTM: %d contraction iterations, %d of %d units kept (%d restored)", iterations,
              units.alive.sum(), len(uscore), restored.sum())
    return DTMResult(units.alive[unit_of], removed_at[unit_of], restored[unit_of])


class _Units:
    """The distinct (vertex 0, vertex 1) pairs of the candidates and their alive flags.

    Attributes:
        uv: per image, (U,) vertex id of each unit; score: (U,) best score of the unit's matches;
        vxy: per image, (V, 2) vertex positions; sizes: per image (H, W); unmatched: per image (N, 2)
        rounded unmatched keypoints or None; alive: (U,) currently kept units.
    """

    def __init__(self, uv: tuple[np.ndarray, np.ndarray], score: np.ndarray,
                 vxy: tuple[np.ndarray, np.ndarray],
                 sizes: tuple[tuple[int, int], tuple[int, int]],
                 unmatched: tuple[np.ndarray | None, np.ndarray | None], cfg: DTMConfig,
                 pool: ThreadPoolExecutor | None) -> None:
        self.uv, self.score, self.vxy, self.sizes = uv, score, vxy, sizes
        self.unmatched, self.cfg, self.pool = unmatched, cfg, pool
        self.alive = np.ones(len(score), bool)
        self._cache: tuple[bytes, tuple[_Mesh, _Mesh]] | None = None

    def meshes(self) -> tuple[_Mesh, _Mesh]:
        """Both images' meshes of the alive units, in two threads for large inputs (OpenCV releases the
        GIL); the last pair is reused while the alive set does not change."""
        key = np.packbits(self.alive).tobytes()
        if self._cache is None or self._cache[0] != key:
            alive = self.alive.copy()
            def build(s: int) -> _Mesh:
                return _triangulate(np.unique(self.uv[s][alive]), self.vxy[s], self.sizes[s],
                                    self.unmatched[s], self.cfg)
            built = tuple(self.pool.map(build, (0, 1)) if self.pool is not None else map(build, (0, 1)))
            self._cache = (key, built)
        return self._cache[1]

    def contract(self) -> tuple[np.ndarray, int]:
        """Stage 1. Returns (U,) removal iteration (-1 never) and the number of removing iterations."""
        n_units = len(self.score)
        removed_at = np.full(n_units, -1, np.int64)
        iteration = 0
        while iteration < self.cfg.max_iterations and self.alive.any():
            mesh = self.meshes()
            near0, near1 = (_near_pairs(self.uv[s], self.alive, mesh[s], n_units) for s in (0, 1))
            consistent = np.intersect1d(near0, near1, assume_unique=True)
            only0 = np.setdiff1d(near0, near1, assume_unique=True)
            only1 = np.setdiff1d(near1, near0, assume_unique=True)
            inconsistent = np.sort(np.concatenate([
                only0[~_within_two(mesh[1], self.uv[1], only0 // n_units, only0 % n_units)],
                only1[~_within_two(mesh[0], self.uv[0], only1 // n_units, only1 % n_units)]]))
            n_consistent = np.bincount(consistent // n_units, minlength=n_units)
            rank = np.empty(n_units, np.int64)
            rank[np.lexsort((self.score, -n_consistent))] = np.arange(n_units)
            a, b = inconsistent // n_units, inconsistent % n_units
            better = rank[a] < rank[b]
            survive = _greedy_survivors(a[better], b[better], self.alive)
            ca, cb = consistent // n_units, consistent % n_units
            supported = np.zeros(n_units, bool)
            supported[ca[survive[ca] & survive[cb]]] = True
            removed = self.alive & ~(survive & supported)
            if not removed.any() or removed.sum() < self.cfg.settle_fraction * self.alive.sum():
                break
            removed_at[removed] = iteration
            self.alive &= ~removed
            iteration += 1
        return removed_at, iteration

    def expand(self, removed_at: np.ndarray, iterations: int) -> np.ndarray:
        """Stage 2, from the last removal iteration to the first: a unit removed at or after it returns
        when both images' kept triangulations predict its position. Returns (U,) restored flags."""
        restored = np.zeros(len(self.score), bool)
        for it in range(iterations - 1, -1, -1):
            cand = np.flatnonzero((removed_at >= it) & ~self.alive)
            if not self.alive.any() or not len(cand):
                continue
            mesh = self.meshes()
            ok = np.ones(len(cand), bool)
            for s in (0, 1):
                o = 1 - s
                rep = _representatives(self.uv[s], self.score, self.alive, len(self.vxy[s]))
                rep_dst = np.zeros_like(self.vxy[s])
                has = rep >= 0
                rep_dst[has] = self.vxy[o][self.uv[o][rep[has]]]
                ok &= _transfer_ok(mesh[s], self.vxy[s], rep_dst, self.vxy[s][self.uv[s][cand]],
                                   self.vxy[o][self.uv[o][cand]], self.cfg.inside_tolerance)
            restored[cand[ok]] = True
            self.alive[cand[ok]] = True
        return restored


def _representatives(v_this: np.ndarray, uscore: np.ndarray, alive: np.ndarray,
                     n_vertices: int) -> np.ndarray:
    """(V,) best-scored alive unit on each vertex of this image, -1 where none."""
    units = np.flatnonzero(alive)
    order = units[np.lexsort((uscore[units], v_this[units]))]
    first = np.append(True, v_this[order][1:] != v_this[order][:-1])
    rep = np.full(n_vertices, -1, np.int64)
    rep[v_this[order[first]]] = order[first]
    return rep
