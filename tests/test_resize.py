"""Working-size resizing: sizes, area interpolation, the working frame."""

import numpy as np
import pytest

from slime_match.features.image_ops import resize_area, resize_lanczos
from slime_match.geometry.frames import Frame
from slime_match.resize import pair_factors, resize_image, working_factor, working_size


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


def test_working_size_policy():
    """Small images grow to min_side on their shorter side, large ones shrink to max_side on their longer side,
    with one factor per image (aspect kept); max_side wins; None or 0 turns a limit off."""
    assert working_factor(240, 180, min_side=480) == 480 / 180
    assert working_size(240, 180, min_side=480, max_side=1200) == (640, 480)
    assert working_size(180, 240, min_side=480, max_side=1200) == (480, 640)  # portrait
    assert working_size(400, 600, min_side=480, max_side=1200) == (480, 720)  # WxBS tyn
    assert working_size(1707, 1280, min_side=480, max_side=1200) == (1200, 900)  # WxBS kyiv_dolltheater
    assert working_size(1280, 1707, min_side=480, max_side=1200) == (900, 1200)
    assert working_size(800, 640, min_side=480, max_side=1200) == (800, 640)  # graf: inside the limits
    assert working_size(480, 1200, min_side=480, max_side=1200) == (480, 1200)  # on both limits
    assert working_size(2000, 100, min_side=480, max_side=1200) == (1200, 60)  # max_side wins
    assert working_size(300, 200, min_side=480, max_side=600) == (600, 400)  # growth stops at max_side
    assert working_size(240, 180, min_side=0, max_side=0) == (240, 180)
    assert working_size(240, 180, min_side=None, max_side=None) == (240, 180)
    assert working_size(3000, 2000, min_side=480) == (3000, 2000)  # no cap
    assert working_factor(800, 640, 480, 1200) == 1.0


def test_frame_maps_working_points_back_exactly():
    """A 2.5x upsample (240 x 192 -> 600 x 480): working px -> original px and back, exactly."""
    image = np.random.default_rng(1).random((192, 240, 3)).astype(np.float32)
    big, frame = resize_image(image, max_side=1200, min_side=480)
    assert big.shape == (480, 600, 3) and frame == Frame((2.5, 2.5))
    # original pixel (x, y) covers [x - 0.5, x + 0.5): its centre is working (2.5 x + 0.75, 2.5 y + 0.75)
    original = np.array([[0.0, 0.0], [10.0, 7.0], [239.0, 191.0], [-0.5, -0.5]])
    working = np.array([[0.75, 0.75], [25.75, 18.25], [598.25, 478.25], [-0.5, -0.5]])
    np.testing.assert_allclose(frame.from_original(original), working, rtol=0, atol=1e-12)
    np.testing.assert_allclose(frame.to_original(working), original, rtol=0, atol=1e-12)
    # a portrait image grows by the factor of its shorter (horizontal) side
    _, frame = resize_image(image.transpose(1, 0, 2), max_side=1200, min_side=480)
    assert frame == Frame((2.5, 2.5))


def test_upsampling_then_mapping_back_gives_original_pixels():
    """A bright pixel of a small image, upsampled 2x (Lanczos3), peaks where the frame maps its centre: the
    intensity centroid of the working peak maps back to the original pixel."""
    image = np.zeros((60, 100), np.float32)
    image[20, 30] = 1.0
    image[45, 71] = 1.0
    big, frame = resize_image(image, min_side=120)
    assert big.shape == (120, 200) and frame == Frame((2.0, 2.0))
    assert big.min() >= 0.0 and big.max() <= 1.0  # Lanczos3 ringing clipped to the input's range
    for x, y in ((30, 20), (71, 45)):
        centre = frame.from_original(np.array([[x, y]]))[0]  # (2x + 0.5, 2y + 0.5)
        x0, y0 = int(centre[0]) - 5, int(centre[1]) - 5
        patch = big[y0:y0 + 12, x0:x0 + 12].astype(np.float64)
        ys, xs = np.mgrid[y0:y0 + 12, x0:x0 + 12]
        centroid = np.array([[(xs * patch).sum(), (ys * patch).sum()]]) / patch.sum()
        np.testing.assert_allclose(frame.to_original(centroid), [[x, y]], atol=1e-6)


def test_resize_image_interpolation():
    """Growth by the policy is Lanczos3 (as Slime's block levels), shrinking area interpolation."""
    image = np.random.default_rng(2).random((50, 80, 3)).astype(np.float32)
    big, _ = resize_image(image, min_side=100)
    np.testing.assert_array_equal(big, np.clip(resize_lanczos(image, 2.0), image.min(), image.max()))
    assert big.dtype == np.float32
    small, _ = resize_image(image, max_side=40)
    np.testing.assert_array_equal(small, resize_area(image, (40, 25)))


def test_pair_factors():
    """A pair shares the factor closest to 1 that meets both images' limits, else each has its own."""
    assert pair_factors((800, 640), (800, 640), 480, 1200) == (1.0, 1.0)  # graf: inside the limits
    assert pair_factors((400, 600), (400, 600), 480, 1200) == (1.2, 1.2)  # WxBS tyn
    assert pair_factors((800, 534), (400, 600), 480, 1200) == (1.2, 1.2)  # WxBS bridge: both grow by 1.2
    assert pair_factors((1707, 1280), (1280, 1024), 480, 1200) == (1200 / 1707, 1200 / 1707)  # kyiv_dolltheater
    assert pair_factors((779, 1000), (1707, 1280), 480, 1200) == (1200 / 1707, 1200 / 1707)
    # no shared factor: 779 x 1000 needs at least 480 / 779 = 0.62, 1707 x 1280 at most 1024 / 1707 = 0.60
    assert pair_factors((779, 1000), (1707, 1280), 480, 1024) == (1.0, 1024 / 1707)
    assert pair_factors((240, 180), (4000, 3000), 480, 1200) == (480 / 180, 0.3)
    # without min_side a shared factor still keeps every side at 32 px or more
    assert pair_factors((120, 100), (4000, 3000), None, 1200) == (1.0, 0.3)
    assert pair_factors((240, 180), (3000, 2000), None, None) == (1.0, 1.0)
    assert pair_factors((240, 180), (300, 200), 480, None) == (480 / 180, 480 / 180)
