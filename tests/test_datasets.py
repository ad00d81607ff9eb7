"""Dataset readers on the real files in ../shared/data and on tiny synthetic folders."""

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import DATA, require

from slime_match.errors import ConfigError
from slime_match.eval import datasets as D
from slime_match.eval.metrics import correct_matches_disparity
from slime_match.geometry.fundamental import epipolar_distance
from slime_match.geometry.homography import project
from slime_match.resize import resize_image, to_original


def _rot(axis, deg):
    return cv2.Rodrigues(np.asarray(axis, np.float64) / np.linalg.norm(axis) * math.radians(deg))[0]


def _two_view_points(K0, K1, R, t, rng, n=50, w=640, h=480):
    """Pixels of image 0 back-projected at random depths and projected into image 1."""
    x0 = rng.uniform([0, 0], [w, h], (n, 2))
    rays = np.concatenate([x0, np.ones((n, 1))], 1) @ np.linalg.inv(K0).T
    X = rays * rng.uniform(1, 10, (n, 1))
    p = (X @ R.T + t) @ K1.T
    return x0, p[:, :2] / p[:, 2:]


def _same_up_to_scale(a, b):
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    return min(np.abs(a - b).max(), np.abs(a + b).max())


# ---------------------------------------------------------------------------------------------------- real data


def test_graf_oxford_reader():
    require(DATA / "oxford_graf")
    pairs = D.load_dataset("graf")
    assert [p.name for p in pairs] == [f"oxford_graf/1-{k}" for k in range(2, 7)]
    p = pairs[1]
    assert p.kind == "homography" and p.image0.name == "img1.png" and p.image1.name == "img3.png"
    assert p.H[0, 0] == pytest.approx(0.76285898) and p.H[1, 2] == pytest.approx(-76.999973)


def test_hpatches_reader_root_and_sequence():
    require(DATA / "hpatches")
    pairs = D.load_dataset("hpatches")
    assert len(pairs) == 10 and {p.name.split("/")[0] for p in pairs} == {"v_churchill", "v_wormhole"}
    seq = D.load_dataset(f"hpatches:{DATA / 'hpatches' / 'v_wormhole'}")
    assert [p.name for p in seq] == [f"v_wormhole/1-{k}" for k in range(2, 7)]
    assert seq[0].H[0, 0] == pytest.approx(1.4733) and all(p.image1.suffix == ".ppm" for p in seq)


def test_scannet_sample_reader_f_consistent_with_pose():
    require(DATA / "scannet_sample")
    pairs = D.load_dataset("scannet-sample")
    assert len(pairs) == 15 and all(p.image0.is_file() and p.image1.is_file() for p in pairs)
    rng = np.random.default_rng(0)
    for p in pairs[:5]:
        assert p.kind == "pose" and p.size == (640, 480)
        assert np.allclose(p.R @ p.R.T, np.eye(3), atol=1e-4)
        x0, x1 = _two_view_points(p.K0, p.K1, p.R, p.t, rng, w=1296, h=968)
        assert epipolar_distance(p.F, x0, x1).max() < 1e-6


def test_scannet1500_matches_sample_and_megadepth1500():
    require(DATA / "gt_1500")
    scan = {p.name: p for p in D.load_dataset(f"scannet1500:{DATA}")}
    assert len(scan) == 1500
    p = scan["scene0711_00/1680-1995"]
    sample = D.load_dataset("scannet-sample")[0]
    assert np.allclose(p.R, sample.R, atol=1e-4) and np.allclose(p.t, sample.t, atol=1e-4)
    assert p.image0 == DATA / "scene0711_00" / "color" / "1680.jpg"
    mega = D.load_dataset(f"megadepth1500:{DATA}")
    assert len(mega) == 1500 and all(q.max_side == 1200 for q in mega[:10])
    rng = np.random.default_rng(1)
    for q in mega[::500]:
        assert np.allclose(q.R @ q.R.T, np.eye(3), atol=1e-6)
        x0, x1 = _two_view_points(q.K0, q.K1, q.R, q.t, rng, w=1600, h=1200)
        assert epipolar_distance(q.F, x0, x1).max() < 1e-6
    with pytest.raises(ConfigError):
        D.load_dataset("megadepth1500")


def test_motorcycle_disparity_pair():
    (p,) = D.load_dataset("motorcycle")
    assert p.kind == "disparity" and p.image0.shape == p.disparity.shape + (3,)
    rows, cols = np.nonzero(np.isfinite(p.disparity))
    x0 = np.stack([cols, rows], 1)[::997].astype(float)
    x1 = x0 - np.stack([p.disparity[rows, cols][::997], np.zeros(len(x0))], 1)
    assert correct_matches_disparity(x0, x1, p.disparity, t=0.5).all()
    assert epipolar_distance(p.F, x0, x1).max() < 1e-9


# ----------------------------------------------------------------------------------------- synthetic folders


def _texture(h=60, w=80, seed=0):
    return np.random.default_rng(seed).integers(0, 255, (h, w, 3), dtype=np.uint8)


def _write_h(path: Path, H):
    np.savetxt(path, H)


def test_planar_folder_with_masks_and_rotated_variants(tmp_path):
    for k in (1, 2, 3):
        cv2.imwrite(str(tmp_path / f"boat{k}.png"), _texture(seed=k))
    cv2.imwrite(str(tmp_path / "boatrot2.png"), _texture(seed=9))
    H2, H3 = np.diag([1.0, 1.0, 1.0]), np.array([[1, 0, 5.0], [0, 1, 2], [0, 0, 1]])
    _write_h(tmp_path / "boat_H12.txt", H2)
    _write_h(tmp_path / "boat_H13.txt", H3)
    _write_h(tmp_path / "boatrot_H12.txt", H3)
    mask = np.zeros((60, 80), np.uint8)
    mask[:10] = 255
    cv2.imwrite(str(tmp_path / "mask_boat3.png"), mask)
    pairs = {p.name: p for p in D.load_dataset(f"planar:{tmp_path}")}
    assert set(pairs) == {"boat/1-2", "boat/1-3", "boatrot/1-2"}
    assert np.allclose(pairs["boat/1-3"].H, H3) and pairs["boat/1-3"].mask1[:10].all()
    assert pairs["boat/1-3"].mask1.sum() == 800 and pairs["boat/1-2"].mask1 is None
    rot = pairs["boatrot/1-2"]
    assert rot.image0.name == "boat1.png" and rot.image1.name == "boatrot2.png"
    with pytest.raises(FileNotFoundError):
        D.load_dataset(f"planar:{tmp_path / 'missing'}")


def test_evd_folder(tmp_path):
    for sub in ("1", "2", "h"):
        (tmp_path / sub).mkdir()
    for name in ("adam", "cafe"):
        cv2.imwrite(str(tmp_path / "1" / f"{name}.png"), _texture())
        cv2.imwrite(str(tmp_path / "2" / f"{name}.png"), _texture(seed=3))
        _write_h(tmp_path / "h" / f"{name}.txt", np.array([[2.0, 0, 1], [0, 2, 3], [0, 0, 1]]))
    pairs = D.load_dataset(f"evd:{tmp_path}")
    assert [p.name for p in pairs] == ["adam", "cafe"] and pairs[1].image1 == tmp_path / "2" / "cafe.png"
    assert pairs[0].H[1, 2] == 3.0


def test_wxbs_folder_f_from_corrs(tmp_path):
    rng = np.random.default_rng(3)
    K = np.array([[300.0, 0, 160], [0, 300, 120], [0, 0, 1]])
    R, t = _rot([0.1, 1, 0], 15), np.array([1.0, 0.2, 0.1])
    x0, x1 = _two_view_points(K, K, R, t, rng, n=40, w=320, h=240)
    d = tmp_path / "WGBS" / "kremlin"
    d.mkdir(parents=True)
    cv2.imwrite(str(d / "01.png"), _texture())
    cv2.imwrite(str(d / "02.jpg"), _texture(seed=2))
    np.savetxt(d / "corrs.txt", np.concatenate([x0, x1], 1))
    (p,) = D.load_dataset(f"wxbs:{tmp_path}")
    assert p.name == "WGBS/kremlin" and p.kind == "fundamental" and p.corrs.shape == (40, 4)
    assert _same_up_to_scale(p.F, D.fundamental_from_pose(K, K, R, t)) < 1e-6


# -------------------------------------------------------------------------------------- rotations and resizing


def _blob_image(centre, h=90, w=120):
    ys, xs = np.mgrid[0:h, 0:w]
    return (200 * np.exp(-((xs - centre[0]) ** 2 + (ys - centre[1]) ** 2) / (2 * 2.0**2))).astype(np.float32)


def _centroid(img):
    ys, xs = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
    return np.array([(xs * img).sum(), (ys * img).sum()]) / img.sum()


@pytest.mark.parametrize("angle", [90, 180, 270, -90, 30, 137.5])
def test_rotated_pair_satisfies_gt(angle):
    H = np.array([[1.0, 0.02, 7.0], [-0.01, 1.0, 4.0], [0.0, 0.0, 1.0]])
    x0 = np.array([[40.0, 30.0]])
    target = project(H, x0)[0][0]
    pair = D.Pair(
        "blob",
        _blob_image(x0[0]),
        _blob_image(target),
        "homography",
        H=H,
        corrs=np.concatenate([x0, [target]], 1),
    )
    rp = D.rotated_pair(pair, angle)
    moved = project(rp.H, x0)[0][0]
    exact = angle % 90 == 0
    assert np.abs(_centroid(rp.image1) - moved).max() < (1e-3 if exact else 0.05)
    assert np.allclose(rp.corrs[0, 2:], moved)
    if exact:
        assert rp.image1.shape == ((120, 90) if angle % 180 else (90, 120)) and rp.mask1 is None
    else:  # expanded canvas: the padding is masked out, the rotated image content is not
        assert rp.mask1.any() and not rp.mask1[tuple(np.rint(moved[::-1]).astype(int))]
    with pytest.raises(ConfigError):
        D.rotated_pair(D.Pair("d", pair.image0, pair.image1, "disparity"), 90)


@pytest.mark.parametrize("angle", [90, 25])
def test_rotated_pose_pair_updates_camera(angle):
    rng = np.random.default_rng(4)
    K0 = np.array([[300.0, 0, 60], [0, 310, 45], [0, 0, 1]])
    K1 = np.array([[280.0, 0, 58], [0, 290, 44], [0, 0, 1]])
    R, t = _rot([0.2, 1, 0], 10), np.array([0.5, 0.1, 0.0])
    pair = D.Pair(
        "p",
        _texture(90, 120),
        _texture(90, 120, 1),
        "pose",
        F=D.fundamental_from_pose(K0, K1, R, t),
        K0=K0,
        K1=K1,
        R=R,
        t=t,
    )
    rp = D.rotated_pair(pair, angle)
    assert np.allclose(np.tril(rp.K1, -1), 0) and (np.diag(rp.K1) > 0).all()
    assert _same_up_to_scale(rp.F, D.fundamental_from_pose(K0, rp.K1, rp.R, rp.t)) < 1e-9
    x0, x1 = _two_view_points(K0, rp.K1, rp.R, rp.t, rng, w=120, h=90)
    assert epipolar_distance(rp.F, x0, x1).max() < 1e-6


def test_scannet_pairs_file_with_exif_rotation(tmp_path):
    K = np.array([[300.0, 0, 60], [0, 300, 45], [0, 0, 1]])
    R, t = _rot([0, 1, 0.1], 8), np.array([0.3, 0.0, 0.1])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    (tmp_path / "images").mkdir()
    for n in ("a.jpg", "b.jpg"):
        cv2.imwrite(str(tmp_path / "images" / n), _texture(90, 120))
    row = ["a.jpg", "b.jpg", "1", "0"] + [f"{v:.10g}" for v in np.r_[K.ravel(), K.ravel(), T.ravel()]]
    (tmp_path / "pairs.txt").write_text(" ".join(row) + "\n")
    (p,) = D.read_scannet_pairs(tmp_path / "pairs.txt")
    assert p.image0.shape[:2] == (120, 90)  # image 0 turned by 90 degrees
    rng = np.random.default_rng(5)
    x0, x1 = _two_view_points(p.K0, p.K1, p.R, p.t, rng, w=90, h=120)
    assert epipolar_distance(p.F, x0, x1).max() < 1e-6
    # the rotated camera 0 still sees the same 3D point: original pixel u maps to A u
    A, _ = D._rotation_affine(120, 90, 90)
    u = np.array([10.0, 20.0, 1.0])
    X = np.linalg.inv(K) @ u
    Xr = np.linalg.inv(p.R) @ (R @ X + t - p.t)  # camera-0' coordinates of the same point
    v = p.K0 @ Xr
    assert np.allclose(v[:2] / v[2], (A @ u)[:2])


def test_scale_intrinsics_follows_the_protocol_resize():
    img = np.zeros((968, 1296, 3), np.uint8)
    small, scale = resize_image(img, size=(640, 480))
    assert small.shape == (480, 640, 3) and scale == pytest.approx((1296 / 640, 968 / 480))
    K = np.array([[1163.0, 0, 653.6], [0, 1164.8, 481.6], [0, 0, 1]])
    X = np.array([[0.3, -0.2, 2.0], [-0.5, 0.1, 3.0]])
    p_orig = X @ K.T
    p_small = X @ D.scale_intrinsics(K, scale).T
    back = to_original(p_small[:, :2] / p_small[:, 2:], scale)
    assert np.allclose(back, p_orig[:, :2] / p_orig[:, 2:])


def test_load_dataset_errors(tmp_path):
    with pytest.raises(ConfigError):
        D.load_dataset("nonsense")
    with pytest.raises(FileNotFoundError):
        D.load_dataset(f"wxbs:{tmp_path}")
    with pytest.raises(FileNotFoundError):
        D.load_dataset(f"evd:{tmp_path / 'nope'}")
    with pytest.raises(ConfigError):
        D.Pair("x", tmp_path, tmp_path, "stereo")


def test_rotated_graf_keeps_valid_area():
    require(DATA / "oxford_graf")
    from slime_match.eval.metrics import valid_area_homography

    p = D.load_dataset("graf")[1]
    s0 = cv2.imread(str(p.image0)).shape[:2]
    img1 = cv2.imread(str(p.image1))
    rp = D.rotated_pair(p, 270)
    assert np.array_equal(rp.image1, np.rot90(img1, 3))
    v0, v1 = valid_area_homography(p.H, s0, img1.shape[:2])
    r0, r1 = valid_area_homography(rp.H, s0, rp.image1.shape[:2])
    # a 90-degree rotation permutes the pixels of image 1 exactly: same valid pixels, rotated
    assert np.array_equal(v0, r0) and np.array_equal(np.rot90(v1, 3), r1)
