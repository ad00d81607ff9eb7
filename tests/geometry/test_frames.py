"""Pixel frames: exact maps between an original image and its resized, cropped views."""

import numpy as np
import pytest

from slime_match.geometry.frames import Frame, homographies_to_original, stack_matrices
from slime_match.geometry.homography import project
from slime_match.slime.blocks import make_blocks


def test_frame_maps_pixel_centres_and_edges():
    frame = Frame((0.5, 0.25), (3.0, -2.0))  # halved in x, quartered in y, cut at (3, -2)
    original = np.array([[0.5, 1.5], [-0.5, -0.5], [9.5, 3.5]])  # centre of 2x4 pixels, the corner, and another
    np.testing.assert_array_equal(frame.from_original(original), [[-3.0, 2.0], [-3.5, 1.5], [1.5, 2.5]])
    np.testing.assert_array_equal(frame.to_original(frame.from_original(original)), original)
    homogeneous = np.c_[original, np.ones(3)] @ frame.matrix().T
    np.testing.assert_array_equal(homogeneous[:, :2], frame.from_original(original))
    assert Frame.of_sizes((200, 100), (400, 400)) == Frame((0.5, 0.25))
    assert Frame().to_original(np.zeros((0, 2))).shape == (0, 2)


def test_homographies_between_frames_map_original_points():
    rng = np.random.default_rng(1)
    h = np.array([[0.9, 0.1, 12.0], [-0.05, 1.1, -4.0], [1e-4, -2e-4, 1.0]])
    frame0, frame1 = Frame((0.5, 0.4), (10.0, 0.0)), Frame((1 / 3, 1 / 3))
    p0 = rng.uniform(0, 300, (50, 2))
    p1, _ = project(h, p0)
    h_original = homographies_to_original(h, frame0, frame1)
    np.testing.assert_allclose(project(h_original, frame0.to_original(p0))[0], frame1.to_original(p1), atol=1e-8)
    stacked = homographies_to_original(np.stack([h, np.eye(3)]), [frame0, frame0], [frame1, frame1])
    assert stacked.shape == (2, 3, 3) and np.allclose(stacked[0], h_original)
    assert stack_matrices([]).shape == (0, 3, 3)


@pytest.mark.parametrize("size", [(480, 640), (640, 800)])
def test_block_frames_are_the_level_cut_at_the_box(size):
    """A block image's pixel is its level's pixel minus the box corner; the level is the image resized."""
    for block in make_blocks(*size):
        xy = np.array([[5.0, 7.0], [100.25, 33.5]])
        np.testing.assert_array_equal(block.frame.to_original(xy), block.level_frame.to_original(xy + block.box[:2]))
        assert block.level_frame.factor == (block.fx, block.fy) and block.level_frame.origin == (0.0, 0.0)
