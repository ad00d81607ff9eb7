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
  most of the time and expansion restores the same final set.

Implementation: each image's mesh (``dtm_mesh``) comes from a compiled incremental Delaunay triangulation with
exact integer predicates (``delaunay``: 2-3x faster than OpenCV's ``Subdiv2D`` on these meshes of a few hundred
points, and far faster than Qhull) and is only rebuilt when the image's vertex set changes.
Contraction works on unordered unit pairs: the near pairs of each image are enumerated from its mesh edges
and the units grouped by vertex, then classified in the other image by walking Delaunay neighbours. Expansion
locates points by a visibility walk; a unit's test in an image only depends on the kept set, so a rejected
unit is tested again only after the set grows, and image 1 only tests the units that image 0 accepts (its
mesh is not built when none is). The loops over points, triangles and unit pairs are compiled
(``dtm_kernels``, ``dtm_contraction_kernels``): the meshes are small and many, so numpy's per-call overhead
would dominate.
"""

from __future__ import annotations

import logging
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cache

import numpy as np

from .._runtime.options import config_from_dict
from ..errors import ConfigError
from .delaunay import MAX_SIDE
from .dtm_contraction_kernels import contraction_step
from .dtm_kernels import unique_inverse
from .dtm_mesh import _Mesh, _prepare_unmatched, _transfer_ok, _triangulate, _vertices

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
    warm_up()
    return _filter(xy0, xy1, scores, size0, size1, unmatched0, unmatched1, config)


@cache
def warm_up() -> None:
    """Load DTM's compiled loops (``dtm_kernels``, ``dtm_contraction_kernels``) in this process, once: about 0.4 s from numba's on-disk
    cache, about 13 s on a 2-core CPU the first time they are compiled. Call it before forking workers that
    run DTM, or each of them pays it."""
    start = time.perf_counter()
    g = np.random.default_rng(0)
    xy = g.uniform(0, 64, (40, 2))
    _filter(xy, xy + g.normal(0, 8, xy.shape), g.uniform(size=40), (64, 64), (64, 64), g.uniform(0, 64, (10, 2)),
            g.uniform(0, 64, (10, 2)), None)
    seconds = time.perf_counter() - start
    if seconds > 2:
        log.info("DTM: compiled its loops in %.1f s (first use; numba caches them for later runs)", seconds)


def _filter(xy0, xy1, scores, size0, size1, unmatched0, unmatched1, config) -> DTMResult:
    """``dtm_filter`` once the kernels are loaded."""
    cfg = DTMConfig.from_dict(config) if isinstance(config, dict) else (config or DTMConfig())
    xy0 = np.asarray(xy0, np.float64).reshape(-1, 2)
    xy1 = np.asarray(xy1, np.float64).reshape(-1, 2)
    scores = np.asarray(scores, np.float64).reshape(-1)
    k = len(xy0)
    if not (len(xy1) == len(scores) == k):
        raise ValueError("xy0, xy1 and scores must have the same length")
    sizes = (tuple(int(s) for s in size0), tuple(int(s) for s in size1))
    if max(max(sizes[0]), max(sizes[1])) + 1 > MAX_SIDE:
        raise ValueError(f"DTM supports images up to {MAX_SIDE - 1} px a side (exact integer Delaunay predicates), "
                         f"got {sizes[0]} and {sizes[1]}: resize the images")
    if k == 0:
        return DTMResult(np.zeros(0, bool), np.zeros(0, np.int64), np.zeros(0, bool))

    (vxy0, v0), (vxy1, v1) = _vertices(xy0, sizes[0]), _vertices(xy1, sizes[1])
    unit_keys, unit_of = unique_inverse(v0 * len(vxy1) + v1)
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
        rounded unmatched keypoints or None; alive: (U,) currently kept units; by_vertex: per image, (U,)
        the units sorted by vertex, then score; by_score: (U,) the units by score, then id.
    """

    def __init__(self, uv: tuple[np.ndarray, np.ndarray], score: np.ndarray,
                 vxy: tuple[np.ndarray, np.ndarray],
                 sizes: tuple[tuple[int, int], tuple[int, int]],
                 unmatched: tuple[np.ndarray | None, np.ndarray | None], cfg: DTMConfig,
                 pool: ThreadPoolExecutor | None) -> None:
        self.uv, self.score, self.vxy, self.sizes = uv, score, vxy, sizes
        self.unmatched, self.cfg, self.pool = unmatched, cfg, pool
        self.alive = np.ones(len(score), bool)
        self.by_vertex = tuple(np.lexsort((score, v)) for v in uv)
        self.by_score = np.argsort(score, kind="stable")
        self._cache: list[tuple[bytes, _Mesh] | None] = [None, None]

    def mesh(self, s: int) -> _Mesh:
        """Image s's mesh of the alive units' vertices; the last one is reused while they do not change."""
        vertex = np.bincount(self.uv[s][self.alive], minlength=len(self.vxy[s])).nonzero()[0]
        key = vertex.tobytes()
        cached = self._cache[s]
        if cached is None or cached[0] != key:
            cached = self._cache[s] = (key, _triangulate(vertex, self.vxy[s], self.sizes[s], self.unmatched[s],
                                                         self.cfg.border_spacing))
        return cached[1]

    def meshes(self) -> tuple[_Mesh, _Mesh]:
        """Both images' meshes, built in two threads for large inputs (the compiled loops release the GIL)."""
        if self.pool is not None:
            return tuple(self.pool.map(self.mesh, (0, 1)))
        return self.mesh(0), self.mesh(1)

    def grouped(self, s: int) -> np.ndarray:
        """(A,) the alive units sorted by vertex in image s, then score."""
        return self.by_vertex[s][self.alive[self.by_vertex[s]]]

    def contract(self) -> tuple[np.ndarray, int]:
        """Stage 1. Returns (U,) removal iteration (-1 never) and the number of removing iterations.

        Each image's near pairs are classified in the other image: consistent when near there too (found
        from image 0's), inconsistent when more than two edges apart there.
        """
        n_units = len(self.score)
        removed_at = np.full(n_units, -1, np.int64)
        iteration = 0
        while iteration < self.cfg.max_iterations and self.alive.any():
            m0, m1 = self.meshes()
            removed = contraction_step(self.alive, self.by_score, m0.local[self.uv[0]], m1.local[self.uv[1]],
                                       *self.by_vertex, m0.tri.edges, m1.tri.edges, len(m0.vertex),
                                       len(m1.vertex), m0.tri.first, m0.tri.degree, m0.tri.adjacent,
                                       m1.tri.first, m1.tri.degree, m1.tri.adjacent)
            n_removed = np.count_nonzero(removed)
            if not n_removed or n_removed < self.cfg.settle_fraction * np.count_nonzero(self.alive):
                break
            removed_at[removed] = iteration
            self.alive &= ~removed
            iteration += 1
        return removed_at, iteration

    def expand(self, removed_at: np.ndarray, iterations: int) -> np.ndarray:
        """Stage 2, from the last removal iteration to the first: a unit removed at or after it returns
        when both images' kept triangulations predict its position. Returns (U,) restored flags.

        A unit rejected by the current kept set is not tested again until that set grows.
        """
        restored = np.zeros(len(self.score), bool)
        if not self.alive.any():
            return restored
        rejected = np.zeros(len(self.score), bool)
        for it in range(iterations - 1, -1, -1):
            cand = ((removed_at >= it) & ~self.alive & ~rejected).nonzero()[0]
            if not len(cand):
                continue
            back = cand[self._predicted(cand)]
            rejected[cand] = True
            if len(back):
                restored[back] = True
                self.alive[back] = True
                rejected[:] = False
        return restored

    def _predicted(self, cand: np.ndarray) -> np.ndarray:
        """(C,) whether both images' kept triangulations predict the position of the units cand (C,)."""
        if self.pool is not None:
            self.meshes()
        ok = np.arange(len(cand))
        for s in (0, 1):  # image 1 only tests the units image 0 accepts
            o = 1 - s
            grouped = self.grouped(s)
            v = self.uv[s][grouped]
            first = np.empty(len(v), bool)  # best-scored alive unit on each kept vertex
            first[0] = True
            np.not_equal(v[1:], v[:-1], out=first[1:])
            rep = grouped[first]
            unit = cand[ok]
            ok = ok[_transfer_ok(self.mesh(s), self.vxy[o][self.uv[o][rep]], self.vxy[s][self.uv[s][unit]],
                                 self.vxy[o][self.uv[o][unit]], self.cfg.inside_tolerance)]
            if not len(ok):
                break
        out = np.zeros(len(cand), bool)
        out[ok] = True
        return out
