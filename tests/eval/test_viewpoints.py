"""Synthetic extreme-viewpoint pairs: camera geometry with exact answers, pixel-exact rendering, the EVD layout."""

import cv2
import numpy as np
import pytest

from slime_match.errors import ConfigError
from slime_match.eval.datasets import load_dataset
from slime_match.eval.datasets.viewpoints import (
    Camera,
    camera_homography,
    fit_canvas,
    pair_cameras,
    render,
    write_viewpoint_set,
)

from .helpers import texture


def jacobian(h: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(2, 2) derivative of the homography ``h`` at the point ``xy``."""
    u, v, w = h @ np.r_[xy, 1.0]
    return (h[:2, :2] * w - np.outer([u, v], h[2, :2])) / w**2


def stretch(h: np.ndarray, xy: np.ndarray) -> float:
    """The larger over the smaller singular value of ``h``'s derivative at ``xy``."""
    s = np.linalg.svd(jacobian(h, xy), compute_uv=False)
    return float(s[0] / s[1])


def test_a_frontal_camera_sees_the_plane_at_scale_one_about_its_centre():
    h = camera_homography((81, 61), Camera(0.0, 30.0, 0.0))
    assert np.allclose(h / h[2, 2], [[1, 0, -40], [0, 1, -30], [0, 0, 1]])


def test_a_tilted_camera_foreshortens_across_its_axis_by_one_over_the_cosine():
    h = camera_homography((100, 100), Camera(60.0, 0.0, 0.0))  # axis along x: y is foreshortened by cos 60
    centre = np.array([49.5, 49.5])
    assert np.allclose(jacobian(h, centre), [[1, 0], [0, 0.5]], atol=1e-12)
    assert stretch(h, centre) == pytest.approx(2.0)


@pytest.mark.parametrize("config", ["side", "crossed"])
@pytest.mark.parametrize("tilt", [2.0, 4.0, 6.0])
def test_the_pairs_transition_tilt_at_the_planes_centre_is_the_one_asked(config, tilt):
    size = (120, 90)
    cameras = pair_cameras(config, tilt, np.random.default_rng(3))
    h0, h1 = (fit_canvas(camera_homography(size, c), size, 200)[0] for c in cameras)
    centre0 = cv2.perspectiveTransform(np.array([[[59.5, 44.5]]]), h0)[0, 0]
    assert stretch(h1 @ np.linalg.inv(h0), centre0) == pytest.approx(tilt, rel=1e-9)
    assert all(abs(c.roll) <= 20 for c in cameras)


def test_the_canvas_holds_the_warped_source_with_its_longer_side_asked():
    size = (120, 90)
    h, canvas = fit_canvas(camera_homography(size, Camera(70.0, 20.0, 10.0)), size, 300)
    corners = np.array([[[-0.5, -0.5], [119.5, -0.5], [119.5, 89.5], [-0.5, 89.5]]])
    warped = cv2.perspectiveTransform(corners, h)[0]
    assert max(canvas) == 300
    assert np.allclose(warped.min(0), -0.5) and np.all(warped.max(0) <= np.array(canvas) - 0.5 + 1e-9)


def test_rendering_is_pixel_exact_on_a_linear_image():
    # Bilinear sampling and area averaging keep a linear image linear: each canvas pixel holds the source value
    # at its centre mapped back, so any half-pixel slip of the supersampling shows.
    ys, xs = np.mgrid[0:80, 0:100].astype(np.float32)
    ramp = 0.5 * xs + 0.25 * ys
    h = np.array([[0.5, 0.0, 3.0], [0.0, 0.5, 2.0], [0.0, 0.0, 1.0]])
    out = render(ramp, h, (48, 38))
    cy, cx = np.mgrid[5:33, 5:45].astype(np.float64)
    source = cv2.perspectiveTransform(np.dstack([cx, cy]).reshape(1, -1, 2), np.linalg.inv(h))[0]
    expected = 0.5 * source[:, 0] + 0.25 * source[:, 1]
    assert np.abs(out[5:33, 5:45].ravel() - expected).max() < 1e-3


def mapped_difference(image0: np.ndarray, image1: np.ndarray, h: np.ndarray) -> float:
    """Mean absolute difference between image 0's pixels well inside the plane and image 1 sampled at their
    ``h`` images (those well inside the plane in image 1)."""
    ys, xs = np.nonzero(cv2.erode((image0.sum(2) > 0).astype(np.uint8), np.ones((15, 15))))
    xy1 = cv2.perspectiveTransform(np.c_[xs, ys][None].astype(np.float64), h)[0].astype(np.float32)
    inside1 = cv2.erode((image1.sum(2) > 0).astype(np.uint8), np.ones((15, 15)))
    px = np.round(xy1).astype(int)
    keep = (px >= 0).all(1) & (px[:, 0] < image1.shape[1]) & (px[:, 1] < image1.shape[0])
    keep[keep] = inside1[px[keep, 1], px[keep, 0]].astype(bool)
    assert keep.sum() > 5000
    sampled = cv2.remap(image1, xy1[None, keep, 0], xy1[None, keep, 1], cv2.INTER_LINEAR)[0]
    return float(np.abs(sampled - image0[ys[keep], xs[keep]]).mean())


def test_a_written_set_reads_as_an_evd_dataset_whose_truth_maps_the_texture(tmp_path):
    source = tmp_path / "plane" / "front.png"
    source.parent.mkdir()
    image = cv2.resize(texture(40, 50, seed=1), (200, 160), interpolation=cv2.INTER_CUBIC)
    cv2.imwrite(str(source), cv2.GaussianBlur(image, (0, 0), 4.0))  # smooth across a tilt-6 compression
    records = write_viewpoint_set([source], tmp_path / "set", [2.0, 6.0], seed=0, max_side=240)
    assert [r["name"] for r in records] == ["plane_front_side2", "plane_front_side6",
                                            "plane_front_crossed2", "plane_front_crossed6"]
    pairs = load_dataset(f"evd:{tmp_path / 'set'}")
    assert sorted(p.name.split("/")[-1] for p in pairs) == sorted(r["name"] for r in records)
    one_px = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    for pair in pairs:
        im0, im1 = (cv2.imread(str(p)).astype(np.float32) for p in (pair.image0, pair.image1))
        assert max(im0.shape[:2]) == 240 and max(im1.shape[:2]) == 240
        # the truth agrees with the pixels far better than the truth shifted by one pixel (the foreshortened
        # image is blurred across its tilt, so the two never agree exactly)
        assert mapped_difference(im0, im1, pair.H) < 0.5 * mapped_difference(im0, im1, one_px @ pair.H), pair.name


def test_the_seed_draws_the_cameras():
    a = pair_cameras("crossed", 4.0, np.random.default_rng(0))
    assert a == pair_cameras("crossed", 4.0, np.random.default_rng(0))
    assert a != pair_cameras("crossed", 4.0, np.random.default_rng(1))
    assert a[0].angle == pytest.approx(60.0) and a[1].axis == pytest.approx(a[0].axis + 90.0)


def test_bad_inputs_raise_clear_errors(tmp_path):
    with pytest.raises(ConfigError, match="transition tilt"):
        pair_cameras("side", 1.0, np.random.default_rng(0))
    with pytest.raises(ConfigError, match="configuration"):
        pair_cameras("above", 2.0, np.random.default_rng(0))
    with pytest.raises(ConfigError, match="cannot read"):
        write_viewpoint_set([tmp_path / "missing.png"], tmp_path / "set", [2.0])
    with pytest.raises(ConfigError, match="transition tilts"):
        write_viewpoint_set([tmp_path / "missing.png"], tmp_path / "set", [2.0, 0.5])
    with pytest.raises(ConfigError, match="max_side"):
        write_viewpoint_set([tmp_path / "missing.png"], tmp_path / "set", [2.0], max_side=0)
    assert not (tmp_path / "set").exists()
