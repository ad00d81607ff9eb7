"""Pose readers: ScanNet sample and pair lists, ScanNet-1500, MegaDepth-1500."""

import cv2
import numpy as np
import pytest
from conftest import DATA, require

from slime_match.errors import ConfigError
from slime_match.eval.datasets import load_dataset
from slime_match.eval.datasets.pair import _rotation_affine
from slime_match.eval.datasets.pose import read_scannet_pairs
from slime_match.geometry.fundamental import epipolar_distance

from .helpers import rot, texture, two_view_points


def test_scannet_sample_reader_f_consistent_with_pose():
    require(DATA / "scannet_sample")
    pairs = load_dataset("scannet-sample")
    assert len(pairs) == 15 and all(p.image0.is_file() and p.image1.is_file() for p in pairs)
    rng = np.random.default_rng(0)
    for p in pairs[:5]:
        assert p.kind == "pose" and p.size == (640, 480)
        assert np.allclose(p.R @ p.R.T, np.eye(3), atol=1e-4)
        x0, x1 = two_view_points(p.K0, p.K1, p.R, p.t, rng, w=1296, h=968)
        assert epipolar_distance(p.F, x0, x1).max() < 1e-6


def test_scannet1500_matches_sample_and_megadepth1500():
    require(DATA / "gt_1500")
    scan = {p.name: p for p in load_dataset(f"scannet1500:{DATA}")}
    assert len(scan) == 1500
    p = scan["scene0711_00/1680-1995"]
    sample = load_dataset("scannet-sample")[0]
    assert np.allclose(p.R, sample.R, atol=1e-4) and np.allclose(p.t, sample.t, atol=1e-4)
    assert p.image0 == DATA / "scene0711_00" / "color" / "1680.jpg"
    mega = load_dataset(f"megadepth1500:{DATA}")
    assert len(mega) == 1500 and all(q.max_side == 1200 for q in mega[:10])
    rng = np.random.default_rng(1)
    for q in mega[::500]:
        assert np.allclose(q.R @ q.R.T, np.eye(3), atol=1e-6)
        x0, x1 = two_view_points(q.K0, q.K1, q.R, q.t, rng, w=1600, h=1200)
        assert epipolar_distance(q.F, x0, x1).max() < 1e-6
    with pytest.raises(ConfigError):
        load_dataset("megadepth1500")


def test_scannet_pairs_file_with_exif_rotation(tmp_path):
    K = np.array([[300.0, 0, 60], [0, 300, 45], [0, 0, 1]])
    R, t = rot([0, 1, 0.1], 8), np.array([0.3, 0.0, 0.1])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    (tmp_path / "images").mkdir()
    for n in ("a.jpg", "b.jpg"):
        cv2.imwrite(str(tmp_path / "images" / n), texture(90, 120))
    row = ["a.jpg", "b.jpg", "1", "0"] + [f"{v:.10g}" for v in np.r_[K.ravel(), K.ravel(), T.ravel()]]
    (tmp_path / "pairs.txt").write_text(" ".join(row) + "\n")
    (p,) = read_scannet_pairs(tmp_path / "pairs.txt")
    assert p.image0.shape[:2] == (120, 90)  # image 0 turned by 90 degrees
    rng = np.random.default_rng(5)
    x0, x1 = two_view_points(p.K0, p.K1, p.R, p.t, rng, w=90, h=120)
    assert epipolar_distance(p.F, x0, x1).max() < 1e-6
    # the rotated camera 0 still sees the same 3D point: original pixel u maps to A u
    A, _ = _rotation_affine(120, 90, 90)
    u = np.array([10.0, 20.0, 1.0])
    X = np.linalg.inv(K) @ u
    Xr = np.linalg.inv(p.R) @ (R @ X + t - p.t)  # camera-0' coordinates of the same point
    v = p.K0 @ Xr
    assert np.allclose(v[:2] / v[2], (A @ u)[:2])
