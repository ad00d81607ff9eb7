"""DTM on synthetic homography data with exact ground truth, tiny inputs and duplicates."""

import subprocess
import sys

import cv2
import numpy as np
import pytest
import torch
from conftest import require
from scipy.spatial import Delaunay, cKDTree

from slime_match.errors import ConfigError
from slime_match.eval.metrics import correct_matches_homography
from slime_match.matching import delaunay as delaunay_module
from slime_match.matching import dtm as dtm_module
from slime_match.matching import dtm_kernels
from slime_match.matching.blob import blob_match
from slime_match.matching.dtm import DTMConfig, DTMResult, dtm_filter

SIZE = (600, 800)  # (H, W)


def homography_scene(n_in=1000, out_frac=0.3, n_unmatched=2000, noise=0.7, seed=0):
    """Inliers of a random homography (+ Gaussian noise), uniform outliers, unmatched keypoints."""
    g = np.random.default_rng(seed)
    h, w = SIZE
    corners = np.array([[0, 0], [w, 0], [w, h], [0, h]], float)
    moved = corners + g.uniform(-0.15, 0.15, (4, 2)) * [w, h]
    a = []
    for (x, y), (u, v) in zip(corners, moved):
        a.append([x, y, 1, 0, 0, 0, -u * x, -u * y, -u])
        a.append([0, 0, 0, x, y, 1, -v * x, -v * y, -v])
    hom = np.linalg.svd(np.array(a))[2][-1].reshape(3, 3)
    p0 = g.uniform(0, [w, h], (5 * n_in, 2))
    q = np.c_[p0, np.ones(len(p0))] @ hom.T
    p1 = q[:, :2] / q[:, 2:]
    inside = ((p1 >= 0) & (p1 < [w, h])).all(1)
    p0, p1 = p0[inside][:n_in], p1[inside][:n_in] + g.normal(0, noise, (n_in, 2))
    n_out = round(n_in * out_frac / (1 - out_frac))
    xy0 = np.r_[p0, g.uniform(0, [w, h], (n_out, 2))]
    xy1 = np.r_[p1, g.uniform(0, [w, h], (n_out, 2))]
    inlier = np.r_[np.ones(n_in, bool), np.zeros(n_out, bool)]
    perm = g.permutation(len(xy0))
    unmatched = [g.uniform(0, [w, h], (n_unmatched, 2)) for _ in range(2)]
    return xy0[perm], xy1[perm], g.uniform(0, 1, len(xy0)), inlier[perm], unmatched


def check_result(res: DTMResult, k: int) -> None:
    assert res.keep.shape == res.removed_at.shape == res.restored.shape == (k,)
    assert res.keep.dtype == bool and res.restored.dtype == bool and res.removed_at.dtype == np.int64
    assert np.all(res.removed_at >= -1)
    # restored <=> removed in contraction and kept at the end
    np.testing.assert_array_equal(res.restored, res.keep & (res.removed_at >= 0))


@pytest.mark.parametrize("seed", [0, 1])
def test_synthetic_homography_inliers_kept_outliers_removed(seed):
    xy0, xy1, scores, inlier, (u0, u1) = homography_scene(seed=seed)
    res = dtm_filter(xy0, xy1, scores, SIZE, SIZE, u0, u1)
    check_result(res, len(xy0))
    assert res.keep[inlier].mean() >= 0.90
    assert res.keep[~inlier].mean() < 0.01
    assert res.restored.any() and (res.removed_at >= 1).any()  # both stages did work


def test_without_unmatched_and_permutation_invariance():
    xy0, xy1, scores, inlier, _ = homography_scene(n_in=400, seed=2)
    res = dtm_filter(xy0, xy1, scores, SIZE, SIZE)
    assert res.keep[inlier].mean() >= 0.90 and res.keep[~inlier].mean() < 0.01
    perm = np.random.default_rng(0).permutation(len(xy0))
    res_p = dtm_filter(xy0[perm], xy1[perm], scores[perm], SIZE, SIZE)
    np.testing.assert_array_equal(res_p.keep, res.keep[perm])
    np.testing.assert_array_equal(res_p.removed_at, res.removed_at[perm])


def test_nearest_vertex_by_scan_or_tree_gives_the_same_result(monkeypatch):
    """Small meshes find the expansion tests' nearest vertices by a compiled scan (cKDTree for exact ties),
    large ones by cKDTree alone: the same outputs either way."""
    xy0, xy1, scores, _, (u0, u1) = homography_scene(n_in=300, n_unmatched=500, seed=3)
    scan = dtm_filter(xy0, xy1, scores, SIZE, SIZE, u0, u1)
    monkeypatch.setattr(dtm_module, "_BRUTE_FORCE_MAX", 0)
    tree = dtm_filter(xy0, xy1, scores, SIZE, SIZE, u0, u1)
    assert scan.restored.any()  # the expansion ran its transfer tests
    for name in ("keep", "removed_at", "restored"):
        np.testing.assert_array_equal(getattr(scan, name), getattr(tree, name))


@pytest.mark.parametrize("seed", [0, 2])
def test_small_block_low_inlier_ratio(seed):
    """A Slime-sized block (256 x 256 px, 100 candidates, 40% inliers of an affine map, scores unrelated to
    correctness, 500 unmatched keypoints): the best-scored outliers must not wipe out the inliers."""
    g = np.random.default_rng(seed)
    p0 = g.uniform(0, 256, (200, 2))
    p1 = p0 @ np.array([[0.9, 0.15], [-0.1, 1.05]]).T + [10, -5]
    p0, p1 = p0[((p1 >= 0) & (p1 < 256)).all(1)][:40], p1[((p1 >= 0) & (p1 < 256)).all(1)][:40]
    xy0 = np.r_[p0, g.uniform(0, 256, (60, 2))]
    xy1 = np.r_[p1 + g.normal(0, 0.7, p1.shape), g.uniform(0, 256, (60, 2))]
    inlier = np.arange(100) < 40
    res = dtm_filter(xy0, xy1, g.uniform(0, 1, 100), (256, 256), (256, 256), g.uniform(0, 256, (500, 2)),
                     g.uniform(0, 256, (500, 2)))
    check_result(res, 100)
    assert res.keep[inlier].mean() >= 0.6 and res.keep[~inlier].mean() <= 0.1


@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_tiny_inputs(k):
    g = np.random.default_rng(k)
    xy = g.uniform(0, 100, (k, 2))
    res = dtm_filter(xy, xy + 5, g.uniform(size=k), (120, 140), (120, 140), g.uniform(0, 100, (7, 2)),
                     np.zeros((0, 2)))
    check_result(res, k)


def test_collinear_and_degenerate_inputs():
    line = np.c_[np.arange(0, 200, 10.0), np.full(20, 50.0)]
    res = dtm_filter(line, line * 0.5 + 3, np.arange(20.0), (100, 200), (100, 200), line + [0, 20], line)
    check_result(res, 20)
    # Coordinates outside the image and all matches on one point.
    res = dtm_filter(np.array([[-5.0, 300], [1e4, 2]]), np.zeros((2, 2)), [0.1, 0.2], (50, 60), (50, 60))
    check_result(res, 2)
    same = np.full((6, 2), 7.0)
    check_result(dtm_filter(same, same, np.ones(6), (20, 20), (20, 20)), 6)


def test_duplicated_positions_share_fate():
    xy0, xy1, scores, inlier, (u0, u1) = homography_scene(n_in=600, seed=3)
    g = np.random.default_rng(1)
    dup = g.choice(len(xy0), 400, replace=False)
    xy0d, xy1d = np.r_[xy0, xy0[dup]], np.r_[xy1, xy1[dup]]
    sd, inl = np.r_[scores, g.uniform(0, 1, len(dup))], np.r_[inlier, inlier[dup]]
    # many-to-many: extra wrong partners for some keypoints of image 0 (one vertex, several matches)
    wrong = g.choice(len(xy0), 150, replace=False)
    xy0d, xy1d = np.r_[xy0d, xy0[wrong]], np.r_[xy1d, g.uniform(0, [SIZE[1], SIZE[0]], (150, 2))]
    sd, inl = np.r_[sd, g.uniform(0, 1, 150)], np.r_[inl, np.zeros(150, bool)]
    res = dtm_filter(xy0d, xy1d, sd, SIZE, SIZE, u0, u1)
    check_result(res, len(xy0d))
    np.testing.assert_array_equal(res.keep[len(xy0):len(xy0) + len(dup)], res.keep[dup])
    assert res.keep[inl].mean() >= 0.90 and res.keep[~inl].mean() < 0.01


def test_config_validation():
    with pytest.raises(ConfigError):
        dtm_filter(np.zeros((1, 2)), np.zeros((1, 2)), [0.0], (10, 10), (10, 10), config={"nope": 1})
    with pytest.raises(ConfigError):
        DTMConfig(border_spacing=0)
    with pytest.raises(ConfigError):
        DTMConfig(settle_fraction=1.0)
    with pytest.raises(ValueError):
        dtm_filter(np.zeros((2, 2)), np.zeros((1, 2)), [0.0], (10, 10), (10, 10))


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
    np.testing.assert_array_equal(dtm_kernels.survivors(a, b, order, n), ref)


def cross(u, v):
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]


def test_delaunay_and_locate_match_scipy():
    g = np.random.default_rng(0)
    pts = np.unique(np.rint(g.uniform(0, 300, (500, 2))), axis=0)
    pts = np.r_[pts, [[-1, -1], [301, -1], [301, 301], [-1, 301]]]
    tri = dtm_module._Triangulation.of(pts)
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


def test_near_pairs_and_classify_match_brute_force():
    """Near pairs from the mesh edges and the near / more-than-two-edges-apart tests against graph
    distances computed on a dense adjacency matrix."""
    g = np.random.default_rng(4)
    size = (120, 160)
    vxy = np.unique(np.rint(g.uniform(0, [159, 119], (150, 2))), axis=0)
    vertex = np.sort(g.choice(len(vxy), 60, replace=False))
    unmatched = np.unique(np.rint(g.uniform(0, [159, 119], (80, 2))), axis=0)
    unmatched = unmatched[~(unmatched[:, None] == vxy[None]).all(2).any(1)]
    mesh = dtm_module._triangulate(vertex, vxy, size, unmatched, DTMConfig())
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
    a, b = dtm_kernels.near_unit_pairs(units[order], start, tri.edges)
    point_of = dict(zip(units, unit_point))
    got = {(min(x, y), max(x, y)) for x, y in zip(a, b)}
    assert len(got) == len(a)  # each pair once
    expected = {(min(x, y), max(x, y)) for i, x in enumerate(units) for y in units[i + 1:]
                if near[point_of[x], point_of[y]]}
    assert got == expected
    p, q = g.integers(0, n, (2, 3000))
    p[::2] = p[1::2]  # runs of one p (marks reused) and changes of p (marks redone, stale ones left)
    mark = np.full(big + 1, -1, np.int64)
    kind = np.array([dtm_kernels.relation(i, j, tri.first, tri.degree, tri.adjacent, mark) for i, j in zip(p, q)])
    is_near, is_far = kind == dtm_kernels.NEAR, kind == dtm_kernels.FAR
    np.testing.assert_array_equal(is_near, near[p, q])
    np.testing.assert_array_equal(is_far, ~within_two[p, q])


def test_real_pair_blob_then_dtm(data_dir):
    """Oxford graf 1-2 with OpenCV RootSIFT: DTM keeps the correct Blob candidates and drops the rest."""
    folder = require(data_dir / "oxford_graf")
    hom = np.loadtxt(folder / "H1to2p")
    feats = []
    for name in ("img1.png", "img2.png"):
        img = cv2.imread(str(folder / name), cv2.IMREAD_GRAYSCALE)
        kp, desc = cv2.SIFT_create(3000).detectAndCompute(img, None)
        desc = np.sqrt(desc / np.maximum(desc.sum(1, keepdims=True), 1e-9))
        feats.append((np.array([p.pt for p in kp]), torch.from_numpy(desc).float(), img.shape))
    (xy0, d0, size0), (xy1, d1, size1) = feats
    cand = blob_match(d0, d1, torch.from_numpy(xy0), torch.from_numpy(xy1))
    proj = np.c_[xy0[cand.idx0], np.ones(len(cand))] @ hom.T
    correct = np.linalg.norm(proj[:, :2] / proj[:, 2:] - xy1[cand.idx1], axis=1) < 3
    unmatched = [np.delete(xy, np.unique(idx), 0) for xy, idx in ((xy0, cand.idx0), (xy1, cand.idx1))]
    res = dtm_filter(xy0[cand.idx0], xy1[cand.idx1], cand.scores, size0, size1, *unmatched)
    assert correct.sum() > 500 and correct.mean() < 0.5
    assert res.keep[correct].mean() > 0.9
    assert correct[res.keep].mean() > 0.8


def test_real_pair_low_inlier_ratio_does_not_collapse(data_dir):
    """Oxford graf 1-4 (strong viewpoint change): < 10% of the Blob candidates are correct; DTM must keep
    most of them (it used to collapse to 2 matches) with a high precision."""
    folder = require(data_dir / "oxford_graf")
    hom = np.loadtxt(folder / "H1to4p")
    feats = []
    for name in ("img1.png", "img4.png"):
        img = cv2.imread(str(folder / name), cv2.IMREAD_GRAYSCALE)
        kp, desc = cv2.SIFT_create(3000).detectAndCompute(img, None)
        desc = np.sqrt(desc / np.maximum(desc.sum(1, keepdims=True), 1e-9))
        feats.append((np.array([p.pt for p in kp]), torch.from_numpy(desc).float(), img.shape))
    (xy0, d0, size0), (xy1, d1, size1) = feats
    cand = blob_match(d0, d1, torch.from_numpy(xy0), torch.from_numpy(xy1))
    correct = correct_matches_homography(xy0[cand.idx0], xy1[cand.idx1], hom, t=15)
    unmatched = [np.delete(xy, np.unique(idx), 0) for xy, idx in ((xy0, cand.idx0), (xy1, cand.idx1))]
    res = dtm_filter(xy0[cand.idx0], xy1[cand.idx1], cand.scores, size0, size1, *unmatched)
    assert correct.sum() > 300 and correct.mean() < 0.15
    assert correct[res.keep].sum() > 0.6 * correct.sum()
    assert correct[res.keep].mean() > 0.85


_WARM_CHECK = """
import numpy as np
from numba.core.registry import CPUDispatcher
from slime_match.matching import delaunay, dtm, dtm_kernels
kernels = {(m.__name__, n): k for m in (delaunay, dtm_kernels) for n, k in vars(m).items()
           if isinstance(k, CPUDispatcher)}
dtm.load_kernels()
loaded = {n: len(k.signatures) for n, k in kernels.items()}
g = np.random.default_rng(1)
xy = np.rint(g.uniform(0, 300, (600, 2)))
moved = np.where(g.uniform(size=(600, 1)) < 0.6, xy + g.normal(0, 1, xy.shape), g.uniform(0, 300, xy.shape))
dtm.dtm_filter(xy, moved, g.uniform(size=600), (300, 300), (300, 300), g.uniform(0, 300, (300, 2)),
               g.uniform(0, 300, (300, 2)))
dtm.dtm_filter(xy, moved, g.uniform(size=600), (300, 300), (300, 300))
print(loaded == {n: len(k.signatures) for n, k in kernels.items()}, sum(loaded.values()))
"""


def test_load_kernels_loads_what_dtm_calls():
    """After ``load_kernels`` a real DTM call compiles nothing more (forked workers inherit every kernel)."""
    out = subprocess.run([sys.executable, "-c", _WARM_CHECK], capture_output=True, text=True, check=True)
    same, loaded = out.stdout.split()
    assert same == "True" and int(loaded) >= 8  # every kernel dtm.py calls


def test_local_affine_fits():
    """Exact on an affine map (the ridge pulls toward the same global map); equal to the ridge-regularised
    least squares of numpy on noisy data; defined on a lone vertex."""
    g = np.random.default_rng(6)
    src = np.unique(np.rint(g.uniform(0, 200, (80, 2))), axis=0)
    tri = dtm_module._Triangulation.of(np.r_[src, [[-1, -1], [201, -1], [201, 201], [-1, 201]]], len(src))
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
