"""DTM on synthetic homography data with exact ground truth, tiny inputs and duplicates."""

import subprocess
import sys

import cv2
import numpy as np
import pytest
import torch
from conftest import require

from slime_match.errors import ConfigError
from slime_match.eval.metrics import correct_matches_homography
from slime_match.matching import dtm_mesh
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
    monkeypatch.setattr(dtm_mesh, "_BRUTE_FORCE_MAX", 0)
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


def _graf_candidates(folder, k: int):
    """OpenCV RootSIFT (3000 a side) Blob candidates of graf 1 -> k: xy0, xy1 (N, 2), sizes, candidates, GT."""
    feats = []
    for name in ("img1.png", f"img{k}.png"):
        img = cv2.imread(str(folder / name), cv2.IMREAD_GRAYSCALE)
        kp, desc = cv2.SIFT_create(3000).detectAndCompute(img, None)
        desc = np.sqrt(desc / np.maximum(desc.sum(1, keepdims=True), 1e-9))
        feats.append((np.array([p.pt for p in kp]), torch.from_numpy(desc).float(), img.shape))
    (xy0, d0, size0), (xy1, d1, size1) = feats
    cand = blob_match(d0, d1, torch.from_numpy(xy0), torch.from_numpy(xy1))
    return xy0, xy1, size0, size1, cand, np.loadtxt(folder / f"H1to{k}p")


def test_real_pair_blob_then_dtm(data_dir):
    """Oxford graf 1-2 with OpenCV RootSIFT: DTM keeps the correct Blob candidates and drops the rest."""
    xy0, xy1, size0, size1, cand, hom = _graf_candidates(require(data_dir / "oxford_graf"), 2)
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
    xy0, xy1, size0, size1, cand, hom = _graf_candidates(require(data_dir / "oxford_graf"), 4)
    correct = correct_matches_homography(xy0[cand.idx0], xy1[cand.idx1], hom, t=15)
    unmatched = [np.delete(xy, np.unique(idx), 0) for xy, idx in ((xy0, cand.idx0), (xy1, cand.idx1))]
    res = dtm_filter(xy0[cand.idx0], xy1[cand.idx1], cand.scores, size0, size1, *unmatched)
    assert correct.sum() > 300 and correct.mean() < 0.15
    assert correct[res.keep].sum() > 0.6 * correct.sum()
    assert correct[res.keep].mean() > 0.85


_WARM_CHECK = """
import numpy as np
from numba.core.registry import CPUDispatcher
from slime_match.matching import delaunay, dtm, dtm_contraction_kernels, dtm_kernels
kernels = {(m.__name__, n): k for m in (delaunay, dtm_kernels, dtm_contraction_kernels)
           for n, k in vars(m).items() if isinstance(k, CPUDispatcher)}
dtm.warm_up()
loaded = {n: len(k.signatures) for n, k in kernels.items()}
g = np.random.default_rng(1)
xy = np.rint(g.uniform(0, 300, (600, 2)))
moved = np.where(g.uniform(size=(600, 1)) < 0.6, xy + g.normal(0, 1, xy.shape), g.uniform(0, 300, xy.shape))
dtm.dtm_filter(xy, moved, g.uniform(size=600), (300, 300), (300, 300), g.uniform(0, 300, (300, 2)),
               g.uniform(0, 300, (300, 2)))
dtm.dtm_filter(xy, moved, g.uniform(size=600), (300, 300), (300, 300))
print(loaded == {n: len(k.signatures) for n, k in kernels.items()}, sum(loaded.values()))
"""


def test_warm_up_loads_what_dtm_calls():
    """After ``warm_up`` a real DTM call compiles nothing more (forked workers inherit every kernel)."""
    out = subprocess.run([sys.executable, "-c", _WARM_CHECK], capture_output=True, text=True, check=True)
    same, loaded = out.stdout.split()
    assert same == "True" and int(loaded) >= 8  # every kernel dtm.py calls
