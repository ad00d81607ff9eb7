"""Image operations: exact answers on synthetic images, torch paths against OpenCV's, the three resamplers."""

import math

import cv2
import numpy as np
import pytest
import torch

from slime_match.features import image_ops
from slime_match.features.image_ops import (
    blurred_rows,
    central_gradient,
    gaussian_blur,
    gaussian_blur_torch,
    gaussian_kernel,
    gaussian_radius,
    lanczos_upsample2,
    lanczos_upsample2_torch,
    max_filter,
    max_filter_torch,
    resize_area,
    resize_lanczos,
    row_strips,
    scaled_size,
)


def test_torch_kernels_match_opencv_paths():
    x = torch.rand(2, 37, 52)
    for sigma in (0.7, 2.0, 4.0):
        ref = torch.stack(gaussian_blur(list(x), sigma))  # OpenCV on CPU
        assert torch.allclose(gaussian_blur_torch(x, gaussian_kernel(sigma)), ref, atol=1e-5)
    r = torch.rand(37, 52)
    pooled = torch.nn.functional.max_pool2d(r[None, None], 7, stride=1, padding=3)[0, 0]
    assert torch.equal(max_filter(r, 7), pooled)
    assert torch.equal(max_filter_torch(r, 7), pooled)
    up = lanczos_upsample2_torch(x)
    ref = torch.from_numpy(
        np.stack([cv2.resize(ch, None, fx=2, fy=2, interpolation=cv2.INTER_LANCZOS4) for ch in x.numpy()])
    )
    assert up.shape == (2, 74, 104) and torch.allclose(up, ref, atol=1e-5)
    assert torch.equal(lanczos_upsample2(x), ref)  # OpenCV writing each channel into place


def test_use_opencv_on_cpu_tensors_only():
    assert image_ops.use_opencv(torch.zeros(2, 2))
    assert not image_ops.use_opencv(torch.zeros(2, 2, device="meta"))


@pytest.mark.parametrize("opencv", [True, False], ids=["opencv", "torch"])
def test_lanczos_upsample2_of_a_constant_is_the_constant(monkeypatch, opencv):
    monkeypatch.setattr(image_ops, "use_opencv", lambda x: opencv)
    up = lanczos_upsample2(torch.full((3, 9, 14), 0.25))
    assert up.shape == (3, 18, 28)
    torch.testing.assert_close(up, torch.full_like(up, 0.25), rtol=0, atol=1e-6)


def test_central_gradient_of_ramps():
    y, x = torch.meshgrid(torch.arange(6.0), torch.arange(8.0), indexing="ij")
    gx, gy = central_gradient(3.0 * x - 2.0 * y)
    # interior: the slopes; border rows and columns: half the one-sided difference
    expected_x = torch.full((6, 8), 3.0)
    expected_x[:, [0, -1]] = 1.5
    expected_y = torch.full((6, 8), -2.0)
    expected_y[[0, -1]] = -1.0
    assert torch.equal(gx, expected_x) and torch.equal(gy, expected_y)


def test_gaussian_radius_and_kernel():
    assert [gaussian_radius(s) for s in (0.1, 1.0, math.sqrt(2.0), 4.0)] == [1, 3, 5, 12]
    for sigma in (0.5, 1.0, 2.5):
        k = gaussian_kernel(sigma)
        r = gaussian_radius(sigma)
        assert k.shape == (2 * r + 1,) and k.dtype == np.float64
        assert k.sum() == pytest.approx(1.0, abs=1e-15)
        offsets = np.arange(-r, r + 1)
        np.testing.assert_allclose(k / k[r], np.exp(-(offsets**2) / (2 * sigma**2)), rtol=1e-14)


@pytest.mark.parametrize("opencv", [True, False], ids=["opencv", "torch"])
def test_gaussian_blur_of_a_constant_and_an_impulse(monkeypatch, opencv):
    monkeypatch.setattr(image_ops, "use_opencv", lambda x: opencv)
    sigma = 1.5
    flat = gaussian_blur([torch.full((20, 30), 0.7)], sigma)[0]
    torch.testing.assert_close(flat, torch.full_like(flat, 0.7), rtol=0, atol=1e-6)
    # an impulse far from the border blurs to the outer product of the kernel with itself
    impulse = torch.zeros(31, 33)
    impulse[15, 16] = 1.0
    k = torch.from_numpy(gaussian_kernel(sigma)).float()
    r = gaussian_radius(sigma)
    expected = torch.zeros(31, 33)
    expected[15 - r : 16 + r, 16 - r : 17 + r] = torch.outer(k, k)
    torch.testing.assert_close(gaussian_blur([impulse], sigma)[0], expected, rtol=0, atol=1e-7)


@pytest.mark.parametrize("opencv", [True, False], ids=["opencv", "torch"])
def test_blurred_rows_equal_the_whole_images_rows(monkeypatch, opencv):
    monkeypatch.setattr(image_ops, "use_opencv", lambda x: opencv)
    x = torch.rand(40, 23)
    sigma = 1.2
    r = gaussian_radius(sigma)
    whole = gaussian_blur([x], sigma)[0]
    for start, stop in ((10, 17), (0, 5), (35, 40)):
        first, last = max(0, start - r), min(40, stop + r)
        rows = blurred_rows([x[first:last]], sigma, start, stop, first)[0]
        assert torch.equal(rows, whole[start:stop])


@pytest.mark.parametrize("opencv", [True, False], ids=["opencv", "torch"])
def test_max_filter_of_single_peaks(monkeypatch, opencv):
    monkeypatch.setattr(image_ops, "use_opencv", lambda x: opencv)
    x = torch.zeros(12, 15)
    x[6, 7] = 2.0
    x[0, 14] = 1.0  # a corner peak: only the window's part inside the image is filled
    expected = torch.zeros(12, 15)
    expected[:3, 12:] = 1.0
    expected[4:9, 5:10] = 2.0
    assert torch.equal(max_filter(x, 5), expected)


def test_row_strips_cover_the_image_once():
    assert row_strips(10, 10, 99, 30) == [(0, 2), (2, 5), (5, 8), (8, 10)]
    assert row_strips(11, 9, 99, 30) == [(0, 11)]  # up to whole_pixels: one strip
    assert row_strips(3, 1000, 99, 30) == [(0, 1), (1, 2), (2, 3)]  # never an empty strip


def test_scaled_size():
    assert scaled_size(480, 640, 0.4) == (256, 192)
    assert scaled_size(480, 640, 1.0) == (640, 480)
    assert scaled_size(3, 5, 0.01) == (1, 1)  # never an empty image


def test_resize_lanczos_matches_references():
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.random((120, 160, 3)).astype(np.float32), (0, 0), 3)
    up = resize_lanczos(img, 2.0)
    assert up.shape == (240, 320, 3) and up.dtype == np.float32
    ref = cv2.resize(img, (320, 240), interpolation=cv2.INTER_LANCZOS4)
    assert np.abs(up - ref)[8:-8, 8:-8].max() < 5e-3
    down = resize_lanczos(img, 0.5)
    ref = cv2.resize(img, (80, 60), interpolation=cv2.INTER_AREA)
    assert np.abs(down - ref)[4:-4, 4:-4].max() < 5e-3
    np.testing.assert_allclose(resize_lanczos(np.full((37, 53), 2.5), 0.37), 2.5, atol=1e-9)
    # antialiasing: a Nyquist checkerboard shrinks to a flat grey
    checker = (np.indices((64, 64)).sum(0) % 2).astype(np.float64)
    assert resize_lanczos(checker, 0.25)[2:-2, 2:-2].std() < 0.01


def test_resize_lanczos_by_one_is_the_identity():
    image = np.random.default_rng(1).integers(0, 256, (17, 23, 3), dtype=np.uint8)
    same = resize_lanczos(image, 1.0)
    assert same.dtype == np.float32  # integer input comes back as float32
    np.testing.assert_array_equal(same, image.astype(np.float32))
    grey = np.random.default_rng(2).random((9, 4))
    np.testing.assert_array_equal(resize_lanczos(grey, 1.0), grey)


def test_resize_area_means_and_bilinear_upsampling():
    image = np.random.default_rng(0).random((100, 200, 3)).astype(np.float32)
    small = resize_area(image, (50, 25))
    assert small.shape == (25, 50, 3) and small.dtype == np.float32
    # area interpolation: each output pixel is the mean of its 4 x 4 input pixels
    assert small[3, 7] == pytest.approx(image[12:16, 28:32].mean(axis=(0, 1)), abs=1e-5)
    # enlarging is bilinear: a 2x ramp 0, 1 gives 0, 0.25, 0.75, 1 (pixel centres aligned, borders clamped)
    ramp = np.array([[0.0, 1.0]], np.float32)
    np.testing.assert_allclose(resize_area(ramp, (4, 1)), [[0.0, 0.25, 0.75, 1.0]], atol=1e-6)
