"""Working-size resizing: sizes, area interpolation, the working frame."""

import numpy as np
import pytest

from slime_match.features.image_ops import resize_area
from slime_match.geometry.frames import Frame
from slime_match.resize import resize_image, working_size


def test_working_size():
    assert working_size(3200, 2400, max_side=1600) == (1600, 1200)
    assert working_size(2400, 3200, max_side=1600) == (1200, 1600)
    assert working_size(800, 600, max_side=1600) == (800, 600)
    assert working_size(800, 600) == (800, 600)
    # a fixed size (ScanNet's 640 x 480) wins and is transposed for portrait images
    assert working_size(1296, 968, size=(640, 480)) == (640, 480)
    assert working_size(968, 1296, size=(640, 480)) == (480, 640)


def test_resize_image_frames_and_identity():
    image = np.random.default_rng(0).random((100, 200, 3)).astype(np.float32)
    same, frame = resize_image(image, max_side=200)
    assert same is image and frame == Frame()
    small, frame = resize_image(image, max_side=50)
    assert small.shape == (25, 50, 3) and frame == Frame((0.25, 0.25))
    np.testing.assert_array_equal(small, resize_area(image, (50, 25)))  # area interpolation (test_image_ops)
    # working pixel (7, 3) averages original pixels 28..31 x 12..15: its centre is (29.5, 13.5)
    assert frame.to_original(np.array([[7.0, 3.0]])) == pytest.approx(np.array([[29.5, 13.5]]))
