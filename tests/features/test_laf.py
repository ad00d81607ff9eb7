"""Ellipse -> LAF, angle conventions and patch extraction from the pyramid."""

import math

import pytest
import torch

from slime_match.features.laf import (
    PatchPyramid,
    ellipse_to_laf,
    laf_angle,
    laf_scale,
    rotate_laf,
    set_laf_angle,
    upright_laf,
)


def _rot(t: float) -> torch.Tensor:
    return torch.tensor([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]], dtype=torch.float64)


def _random_ellipses(n: int, seed: int = 0, lo: float = 2.0, hi: float = 22.0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    angles = torch.rand(n, generator=g, dtype=torch.float64) * math.pi
    axes = lo + (hi - lo) * torch.rand(n, 2, generator=g, dtype=torch.float64)
    r = torch.stack([_rot(float(a)) for a in angles])
    return r @ torch.diag_embed(axes.pow(-2)) @ r.transpose(1, 2)


def test_ellipse_to_laf_is_exact_inverse_sqrt_on_rotated_ellipses():
    e = _random_ellipses(200)
    xy = torch.rand(200, 2, dtype=torch.float64) * 500
    laf = ellipse_to_laf(xy, e)
    a = laf[:, :, :2]
    assert torch.allclose(a @ a.transpose(1, 2), torch.linalg.inv(e), rtol=1e-9, atol=1e-9)
    assert torch.allclose(a, a.transpose(1, 2))
    assert torch.equal(laf[:, :, 2], xy)
    # The unit circle lands on the ellipse boundary: u^T A^T E A u = 1.
    u = torch.stack([torch.cos(torch.linspace(0, 6.28, 50)), torch.sin(torch.linspace(0, 6.28, 50))]).double()
    q = ((a @ u).transpose(1, 2) @ e * (a @ u).transpose(1, 2)).sum(-1)
    assert torch.allclose(q, torch.ones_like(q), atol=1e-9)


def test_set_laf_angle_round_trip_keeps_ellipse():
    laf = ellipse_to_laf(torch.rand(100, 2) * 300, _random_ellipses(100, 1).float())
    ellipse = laf[:, :, :2] @ laf[:, :, :2].transpose(1, 2)
    up = upright_laf(laf)
    assert torch.all(up[:, 1, 0] == 0) and torch.all(up[:, 0, 0] > 0) and torch.all(up[:, 1, 1] > 0)
    assert torch.allclose(laf_angle(up), torch.zeros(100), atol=1e-6)
    angles = (torch.rand(100) - 0.5) * 2 * math.pi
    for target in (angles, 1.0, -2.5):
        out = set_laf_angle(laf, target)
        expect = torch.as_tensor(target).expand(100)
        diff = torch.remainder(laf_angle(out) - expect + math.pi, 2 * math.pi) - math.pi
        assert diff.abs().max() < 1e-4
        assert torch.allclose(out[:, :, :2] @ out[:, :, :2].transpose(1, 2), ellipse, rtol=1e-4, atol=1e-3)
        assert torch.allclose(laf_scale(out), laf_scale(laf), rtol=1e-5)
        assert torch.equal(out[:, :, 2], laf[:, :, 2])


def test_set_laf_angle_is_covariant_with_image_rotation():
    e = _random_ellipses(50, 2)
    laf = ellipse_to_laf(torch.zeros(50, 2, dtype=torch.float64), e)
    theta = 0.7
    r = _rot(theta)
    rotated = ellipse_to_laf(torch.zeros(50, 2, dtype=torch.float64), r @ e @ r.T)
    expect = r @ set_laf_angle(laf, 0.0)[:, :, :2]
    assert torch.allclose(set_laf_angle(rotated, theta)[:, :, :2], expect, atol=1e-9)


def _smooth_image(h: int, w: int, rotation: float = 0.0, centre=(0.0, 0.0), freq: float = 1.0) -> torch.Tensor:
    """Analytic, non-symmetric, low-frequency grey image; ``rotation`` rotates the content about ``centre``."""
    y, x = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    c, s = math.cos(-rotation), math.sin(-rotation)
    xr = c * (x - centre[0]) - s * (y - centre[1]) + centre[0]
    yr = s * (x - centre[0]) + c * (y - centre[1]) + centre[1]
    return _field(xr * freq, yr * freq)[None].float()


def _field(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Smooth test field; its frequencies are below 0.12 rad/px."""
    return 0.5 + 0.2 * torch.sin(0.11 * x + 0.05 * y) + 0.2 * torch.cos(0.07 * y - 0.03 * x + 0.4 * torch.sin(0.02 * x))


@pytest.mark.parametrize(("scale", "freq"), [(4.0, 1.0), (40.0, 0.15)])
def test_patches_sample_the_frame(scale, freq):
    """Level 0 (scale 4) and level 2 (scale 40, lower-frequency content that its blur keeps)."""
    img = _smooth_image(300, 400, freq=freq)
    pyr = PatchPyramid(img)
    e = _random_ellipses(20, 3, 6.0, 14.0)
    laf = ellipse_to_laf(torch.tensor([[200.0, 150.0]] * 20, dtype=torch.float64), e)
    # Scale the frames to the requested size, keep them anisotropic and rotated.
    laf[:, :, :2] *= (scale / laf_scale(laf))[:, None, None]
    laf = rotate_laf(laf, torch.rand(20, dtype=torch.float64) * 6)
    p = 16
    patches = pyr.extract(laf.float(), patch_size=p, magnification=1.5)
    assert patches.shape == (20, 1, p, p)
    lin = torch.linspace(-1.5, 1.5, p, dtype=torch.float64)
    gy, gx = torch.meshgrid(lin, lin, indexing="ij")
    pts = laf[:, :, :2] @ torch.stack([gx.reshape(-1), gy.reshape(-1)]) + laf[:, :, 2:]
    expect = _field(pts[:, 0] * freq, pts[:, 1] * freq).reshape(20, 1, p, p).float()
    assert (patches - expect).abs().max() < 0.01


def test_patch_at_rotated_laf_equals_rotated_content():
    theta = 0.6
    centre = (160.0, 120.0)
    img0 = _smooth_image(240, 320)
    img1 = _smooth_image(240, 320, rotation=theta, centre=centre)
    laf0 = ellipse_to_laf(torch.tensor([[150.0, 110.0]]), torch.tensor([[[1 / 20.0**2, 0.0], [0.0, 1 / 9.0**2]]]))
    laf0 = set_laf_angle(laf0, 0.3)
    r = _rot(theta).float()
    c = torch.tensor(centre)
    laf1 = torch.cat([r @ laf0[:, :, :2], (r @ (laf0[0, :, 2] - c) + c)[None, :, None]], dim=2)
    p0 = PatchPyramid(img0).extract(laf0, 32, 1.5)
    p1 = PatchPyramid(img1).extract(laf1, 32, 1.5)
    assert (p0 - p1).abs().max() < 0.01
    # Rotating the frame by 90 degrees inside the patch rotates the patch content.
    p90 = PatchPyramid(img0).extract(rotate_laf(laf0, torch.tensor([math.pi / 2])), 32, 1.5)
    assert (torch.rot90(p90, -1, dims=(2, 3)) - p0).abs().max() < 1e-3


def test_pyramid_handles_grey_and_empty():
    pyr = PatchPyramid(torch.rand(1, 64, 80))
    assert pyr.levels[0].shape == (1, 1, 64, 80) and [lv.shape[-1] for lv in pyr.levels] == [80, 40, 20]
    assert pyr.extract(torch.zeros(0, 2, 3)).shape == (0, 1, 32, 32)


@pytest.mark.parametrize("decimation_sigma, sigma", [(None, math.sqrt(4.0 - 0.25)), (1.0, 1.0)])
def test_pyramid_level_blur(decimation_sigma, sigma):
    """An impulse at an even pixel: level 1 samples the blur kernel every 2 parent pixels, so neighbours
    fall by exp(-2^2 / (2 sigma^2)); by default sigma reaches 2 parent px from 0.5, kornia-like it is 1."""
    img = torch.zeros(1, 64, 64)
    img[0, 32, 32] = 1.0
    level = PatchPyramid(img, decimation_sigma=decimation_sigma).levels[1][0, 0]
    ratio = float(level[16, 17] / level[16, 16])
    assert ratio == pytest.approx(math.exp(-2.0 / sigma**2), rel=1e-3)
