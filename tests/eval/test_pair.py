"""Pair ground truth under rotated views, and intrinsics of a protocol-resized frame."""

import cv2
import numpy as np
import pytest
from conftest import DATA, require

from slime_match.errors import ConfigError
from slime_match.eval.datasets import load_dataset
from slime_match.eval.datasets.pair import Pair, fundamental_from_pose, rotated_pair, scale_intrinsics
from slime_match.geometry.fundamental import epipolar_distance
from slime_match.geometry.homography import project
from slime_match.resize import resize_image

from .helpers import rot, same_up_to_scale, texture, two_view_points


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
    pair = Pair(
        "blob",
        _blob_image(x0[0]),
        _blob_image(target),
        "homography",
        H=H,
        corrs=np.concatenate([x0, [target]], 1),
    )
    rp = rotated_pair(pair, angle)
    moved = project(rp.H, x0)[0][0]
    exact = angle % 90 == 0
    assert np.abs(_centroid(rp.image1) - moved).max() < (1e-3 if exact else 0.05)
    assert np.allclose(rp.corrs[0, 2:], moved)
    if exact:
        assert rp.image1.shape == ((120, 90) if angle % 180 else (90, 120)) and rp.mask1 is None
    else:  # expanded canvas: the padding is masked out, the rotated image content is not
        assert rp.mask1.any() and not rp.mask1[tuple(np.rint(moved[::-1]).astype(int))]
    with pytest.raises(ConfigError):
        rotated_pair(Pair("d", pair.image0, pair.image1, "disparity"), 90)


@pytest.mark.parametrize("angle", [90, 25])
def test_rotated_pose_pair_updates_camera(angle):
    rng = np.random.default_rng(4)
    K0 = np.array([[300.0, 0, 60], [0, 310, 45], [0, 0, 1]])
    K1 = np.array([[280.0, 0, 58], [0, 290, 44], [0, 0, 1]])
    R, t = rot([0.2, 1, 0], 10), np.array([0.5, 0.1, 0.0])
    pair = Pair(
        "p",
        texture(90, 120),
        texture(90, 120, 1),
        "pose",
        F=fundamental_from_pose(K0, K1, R, t),
        K0=K0,
        K1=K1,
        R=R,
        t=t,
    )
    rp = rotated_pair(pair, angle)
    assert np.allclose(np.tril(rp.K1, -1), 0) and (np.diag(rp.K1) > 0).all()
    assert same_up_to_scale(rp.F, fundamental_from_pose(K0, rp.K1, rp.R, rp.t)) < 1e-9
    x0, x1 = two_view_points(K0, rp.K1, rp.R, rp.t, rng, w=120, h=90)
    assert epipolar_distance(rp.F, x0, x1).max() < 1e-6


def test_scale_intrinsics_follows_the_protocol_resize():
    img = np.zeros((968, 1296, 3), np.uint8)
    small, frame = resize_image(img, size=(640, 480))
    assert small.shape == (480, 640, 3) and frame.factor == pytest.approx((640 / 1296, 480 / 968))
    K = np.array([[1163.0, 0, 653.6], [0, 1164.8, 481.6], [0, 0, 1]])
    X = np.array([[0.3, -0.2, 2.0], [-0.5, 0.1, 3.0]])
    p_orig = X @ K.T
    p_small = X @ scale_intrinsics(K, frame).T
    back = frame.to_original(p_small[:, :2] / p_small[:, 2:])
    assert np.allclose(back, p_orig[:, :2] / p_orig[:, 2:])


def test_rotated_graf_keeps_valid_area():
    require(DATA / "oxford_graf")
    from slime_match.eval.metrics import valid_area_homography

    p = load_dataset("graf")[1]
    s0 = cv2.imread(str(p.image0)).shape[:2]
    img1 = cv2.imread(str(p.image1))
    rp = rotated_pair(p, 270)
    assert np.array_equal(rp.image1, np.rot90(img1, 3))
    v0, v1 = valid_area_homography(p.H, s0, img1.shape[:2])
    r0, r1 = valid_area_homography(rp.H, s0, rp.image1.shape[:2])
    # a 90-degree rotation permutes the pixels of image 1 exactly: same valid pixels, rotated
    assert np.array_equal(v0, r0) and np.array_equal(np.rot90(v1, 3), r1)
