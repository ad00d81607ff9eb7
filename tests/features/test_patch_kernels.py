"""Compiled per-patch loops (CPU) against reference formulas and against the torch path (which CUDA runs)."""

import math
import subprocess
import sys

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from conftest import random_patches
from kornia.filters import spatial_gradient

from slime_match.features import patch_kernels as pk
from slime_match.features.gradients import DominantGradientOrientation, SIFTPatchDescriptor
from slime_match.features.laf import PatchPyramid, laf_scale
from slime_match.features.shape import _second_moments, _torch_second_moments, second_moment_shape


def _ramp(angle: float, p: int = 32) -> torch.Tensor:
    """(1, 1, P, P) linear ramp whose gradient points at ``angle`` (radians, patch pixel coordinates)."""
    yy, xx = torch.meshgrid(torch.arange(p, dtype=torch.float32), torch.arange(p, dtype=torch.float32), indexing="ij")
    return (0.5 + 0.01 * (math.cos(angle) * xx + math.sin(angle) * yy))[None, None]


def test_atan2_within_float32_rounding():
    rng = np.random.default_rng(0)
    y, x = rng.standard_normal((2, 100_000)).astype(np.float32)
    y[:4], x[:4] = [0.0, 1.0, -1.0, 0.0], [-1.0, 0.0, 0.0, 1.0]  # axes
    ours = np.array([pk._atan2(a, b) for a, b in zip(y[:2000], x[:2000], strict=True)])
    assert np.abs(ours - np.arctan2(y[:2000].astype(np.float64), x[:2000])).max() < 4e-7
    assert ours[0] == np.float32(math.pi)


def test_votes_of_known_gradients():
    """A gradient at angle a votes its magnitude into bins floor(a * bins / 2 pi), linearly split."""
    bins = 8
    angles = np.array([0.0, 0.3, math.pi / 2, 2.0, -0.7, -math.pi / 4 + 1e-3], np.float32)
    mags = np.array([1.0, 0.5, 2.0, 0.1, 0.7, 1.5], np.float32)
    gx, gy = mags * np.cos(angles), mags * np.sin(angles)
    b0, b1 = np.empty((2, len(gx)), np.int64)
    w0, w1 = np.empty((2, len(gx)), np.float32)
    pk._votes(gx.astype(np.float32), gy.astype(np.float32), bins, np.float32(0.0), np.float32(0.0), b0, b1, w0, w1)
    pos = (np.mod(angles.astype(np.float64), 2 * math.pi)) * bins / (2 * math.pi)
    assert np.array_equal(b0, np.floor(pos).astype(int) % bins) and np.array_equal(b1, (b0 + 1) % bins)
    assert np.allclose(w0 + w1, mags, atol=1e-6)
    assert np.allclose(w1, (pos - np.floor(pos)) * mags, atol=1e-5)


@pytest.mark.parametrize("angle", [0.0, math.pi / 2, math.pi, -math.pi / 2])
def test_orientation_of_a_ramp(angle):
    """The dominant orientation of an axis-aligned ramp (every pixel, border included, votes at the same
    angle, on a bin centre) is its gradient direction, counter-clockwise on screen (kornia's sign)."""
    got = DominantGradientOrientation(32, 36)(_ramp(angle))[0].item()
    assert abs(math.remainder(got + angle, 2 * math.pi)) < 1e-5


def _reference_votes(patches: torch.Tensor, mode: str, bins: int, offset: float):
    """float64 per-pixel gradients, bins and linear votes by the textbook formulas (kornia's gradients)."""
    g = spatial_gradient(patches.double(), mode)[:, 0]
    gx, gy = g[:, 0].flatten(1), g[:, 1].flatten(1)
    mag = gx.hypot(gy)
    pos = torch.remainder(torch.atan2(gy, gx) + offset, 2 * math.pi) * bins / (2 * math.pi)
    b0 = pos.floor()
    w1 = (pos - b0) * mag
    return gx, gy, b0.long() % bins, (b0.long() + 1) % bins, mag - w1, w1


def test_second_moments_against_reference():
    x = random_patches(300)
    t = torch.arange(32, dtype=torch.float64) - 15.5
    w = (torch.exp(-0.5 * (t / 7.0) ** 2)[:, None] * torch.exp(-0.5 * (t / 7.0) ** 2)[None, :]).reshape(-1)
    gx, gy, *_ = _reference_votes(x, "sobel", 8, 0.0)
    ref = torch.stack([(w * gx * gx).sum(1), (w * gx * gy).sum(1), (w * gy * gy).sum(1)], 1)
    trace = ref[:, [0, 2]].sum(1, keepdim=True)
    assert ((_second_moments(x, 7.0) - ref).abs() <= 1e-5 * trace).all()
    shape = second_moment_shape(x, 7.0).double()
    assert torch.allclose(torch.linalg.det(shape), torch.ones(len(x), dtype=torch.float64), atol=1e-5)


def test_sift_histograms_against_reference():
    """Dense reference: per-pixel votes in float64 pooled by the (P*P, cells) matrix of the torch path."""
    x = random_patches(300)
    sift = SIFTPatchDescriptor(32, rootsift=False)
    _, _, b0, b1, w0, w1 = _reference_votes(x, "diff", 8, 0.0)
    hist = torch.zeros(len(x), 8, 32 * 32, dtype=torch.float64)
    hist.scatter_add_(1, b0[:, None], w0[:, None]).scatter_add_(1, b1[:, None], w1[:, None])
    ref = (hist @ sift.pool.double()).flatten(1)
    ours = pk.sift_histograms(x[:, 0].numpy(), sift._cell, sift._weight, 4, 8, np.float32(0.0))
    assert np.abs(ours - ref.numpy()).max() < 1e-5 * ref.abs().max().item()
    ramp = pk.sift_histograms(_ramp(0.3)[:, 0].numpy(), sift._cell, sift._weight, 4, 8, np.float32(0.0))
    ramp = ramp.reshape(8, 16)  # gradient angles 0.15...0.55 rad: bins 0 and 1 only
    assert np.abs(ramp[2:]).max() == 0 and ramp[:2].min() > 0


def test_sift_kernel_equals_torch_path():
    x = random_patches(300)
    sift = SIFTPatchDescriptor(32)
    ref = sift._normalise(sift._torch_histograms(x))
    assert (sift(x) - ref).abs().max() < 1e-5


def test_orientation_kernel_equals_torch_path():
    x = random_patches(300)
    ori = DominantGradientOrientation(32, 36)
    ours, ref = ori._histograms(x), ori._torch_histograms(x)
    assert ((ours - ref).abs().max() / ref.abs().max()) < 1e-5


def test_second_moment_kernel_equals_torch_path():
    x = random_patches(300)
    t = torch.arange(32, dtype=torch.float32) - 15.5
    w1 = torch.exp(-0.5 * (t / 10.0) ** 2)
    ours, ref = _second_moments(x, 10.0), _torch_second_moments(x, w1[:, None] * w1[None, :])
    trace = ref[:, [0, 2]].sum(1, keepdim=True)
    assert ((ours - ref).abs() <= 1e-5 * trace).all()


def test_sampler_equals_grid_sample():
    """The compiled sampler against the torch path (one grid_sample per level), frames in and out of the
    image, at every level; bit-exact on FMA CPUs, float rounding elsewhere."""
    g = torch.Generator().manual_seed(0)
    image = F.avg_pool2d(torch.rand(3, 130, 170, generator=g)[None], 3, 1, 1)[0]
    pyr = PatchPyramid(image)
    n = 400
    xy = torch.rand(n, 2, generator=g) * torch.tensor([200.0, 160.0]) - 15.0
    a = torch.randn(n, 2, 2, generator=g) * torch.rand(n, 1, 1, generator=g) * 12.0
    laf = torch.cat([a, xy[:, :, None]], 2)
    for magnification in (1.0, 6.0):
        ours = pyr.extract(laf, 32, magnification)
        step = 2.0 * magnification * laf_scale(laf) / 31
        level = torch.floor(torch.log2(step.clamp_min(1e-6))).clamp(0, len(pyr.levels) - 1).long()
        affine = laf * pyr._norm[level][:, :, None]
        affine[:, :, 2] -= 1.0
        ref = pyr._grid_sample(affine, level, torch.linspace(-magnification, magnification, 32))
        assert ours.shape == ref.shape == (n, 1, 32, 32)
        assert (ours - ref).abs().max() < 1e-5
    assert len(set(level.tolist())) > 2


def test_sampler_survives_non_finite_frames():
    pyr = PatchPyramid(torch.rand(3, 40, 50))
    laf = torch.tensor([[[1.0, 0.0, float("nan")], [0.0, 1.0, 10.0]], [[1e30, 0.0, 1e30], [0.0, 1.0, -1e30]]])
    assert pyr.extract(laf, 8, 1.0).shape == (2, 1, 8, 8)


_WARM_CHECK = """
import numpy as np
from numba.core.registry import CPUDispatcher
from slime_match.features import extractor, patch_kernels
from slime_match.pipelines import BaseConfig, make_base_pipeline
kernels = {n: k for n, k in vars(patch_kernels).items() if isinstance(k, CPUDispatcher)}
extractor.warm_up()
loaded = {n: len(k.signatures) for n, k in kernels.items()}
pipeline = make_base_pipeline(BaseConfig(shape="baumberg", orientation="gradient", descriptor="rootsift"))
image = np.random.default_rng(0).uniform(0, 1, (96, 128, 3)).astype(np.float32)
context = pipeline.prepare(image)
pipeline.describe_fixed(context, pipeline.detect(context), 0.5)
print(loaded == {n: len(k.signatures) for n, k in kernels.items()}, sum(loaded.values()))
"""


def test_warm_up_loads_what_weight_free_extraction_calls():
    """After ``extractor.warm_up`` a real weight-free extraction compiles nothing more (forked workers
    inherit every kernel)."""
    out = subprocess.run([sys.executable, "-c", _WARM_CHECK], capture_output=True, text=True, check=True)
    same, loaded = out.stdout.split()
    assert same == "True" and int(loaded) >= 4  # sampling, moments, orientation, SIFT
