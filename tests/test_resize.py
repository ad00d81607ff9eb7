"""Working-size resizing: sizes, pixel-centre mapping back to the original, homographies between frames."""

import numpy as np
import pytest

from slime_match.features.image_ops import resize_area
from slime_match.geometry.homography import project
from slime_match.resize import homography_to_original, resize_image, to_original, working_size


def test_working_size():
    assert working_size(3200, 2400, max_side=1600) == (1600, 1200)
    assert working_size(2400, 3200, max_side=1600) == (1200, 1600)
    assert working_size(800, 600, max_side=1600) == (800, 600)
    assert working_size(800, 600) == (800, 600)
    # a fixed size (ScanNet's 640 x 480) wins and is transposed for portrait images
    assert working_size(1296, 968, size=(640, 480)) == (640, 480)
    assert working_size(968, 1296, size=(640, 480)) == (480, 640)


def test_resize_image_factors_and_identity():
    image = np.random.default_rng(0).random((100, 200, 3)).astype(np.float32)
    same, scale = resize_image(image, max_side=200)
    assert same is image and scale == (1.0, 1.0)
    small, scale = resize_image(image, max_side=50)
    assert small.shape == (25, 50, 3) and scale == (4.0, 4.0)
    np.testing.assert_array_equal(small, resize_area(image, (50, 25)))  # area interpolation (test_image_ops)


def test_to_original_maps_pixel_centres():
    # working pixel (7, 3) averages original pixels 28..31 x 12..15: its centre is (29.5, 13.5)
    assert to_original(np.array([[7.0, 3.0]]), (4.0, 4.0)) == pytest.approx(np.array([[29.5, 13.5]]))
    assert to_original(np.array([[5.0, 2.0]]), (1.0, 1.0)) == pytest.approx(np.array([[5.0, 2.0]]))


def test_homography_to_original_is_exact():
    rng = np.random.default_rng(1)
    H = np.array([[0.9, 0.1, 12.0], [-0.05, 1.1, -4.0], [1e-4, -2e-4, 1.0]])
    scale0, scale1 = (2.0, 2.5), (3.0, 3.0)
    p0 = rng.uniform(0, 300, (50, 2))
    p1, _ = project(H, p0)
    H_original = homography_to_original(H, scale0, scale1)
    np.testing.assert_allclose(project(H_original, to_original(p0, scale0))[0], to_original(p1, scale1), atol=1e-8)
    stacked = homography_to_original(np.stack([H, np.eye(3)]), scale0, scale1)
    assert stacked.shape == (2, 3, 3) and np.allclose(stacked[0], H_original)
