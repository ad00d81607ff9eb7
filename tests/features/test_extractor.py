"""Shape, orientation, descriptors and the LocalFeatureExtractor on synthetic and real images."""

import math

import cv2
import pytest
import torch
from conftest import DATA, require

from slime_match.errors import ConfigError
from slime_match.features.descriptors import Descriptor, resolve_descriptor
from slime_match.features.extractor import LocalFeatureExtractor, PatchConfig
from slime_match.features.laf import PatchPyramid, ellipse_to_laf, laf_angle, laf_scale
from slime_match.features.orientation import Orienter
from slime_match.features.shape import ShapeConfig, ShapeEstimator
from slime_match.types import Keypoints


def _grid(h, w):
    return torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")


def _wrap(a: torch.Tensor) -> torch.Tensor:
    return torch.remainder(a + math.pi, 2 * math.pi) - math.pi


def _circles(xy: torch.Tensor, radius: float) -> Keypoints:
    n = xy.shape[0]
    e = torch.eye(2).expand(n, 2, 2) / radius**2
    return Keypoints(xy, e.contiguous(), torch.ones(n), torch.zeros(n, dtype=torch.int64))


@pytest.mark.parametrize("theta", [0.6, -0.6])
def test_baumberg_recovers_anisotropic_blob_shape(theta):
    y, x = _grid(160, 160)
    c, s = math.cos(theta), math.sin(theta)
    r = torch.tensor([[c, -s], [s, c]])
    cov = r @ torch.diag(torch.tensor([10.0**2, 4.0**2])) @ r.T
    d = torch.stack([x - 80, y - 80], -1)
    img = torch.exp(-0.5 * (d @ torch.linalg.inv(cov) * d).sum(-1))[None]
    laf = ellipse_to_laf(torch.tensor([[80.0, 80.0]]), torch.eye(2)[None] / 12.0**2)
    out = ShapeEstimator("baumberg", config=ShapeConfig(magnification=1.5))(PatchPyramid(img), laf)
    a = out[0, :, :2]
    shape = a @ a.T / torch.det(a)
    expect = cov / torch.det(cov).sqrt()
    assert (shape - expect).norm() / expect.norm() < 0.05
    assert torch.isclose(laf_scale(out), laf_scale(laf), rtol=1e-4).all()  # scale kept
    assert out[0, 1, 0] == 0  # upright


@pytest.mark.parametrize("phi", [-2.5, -0.8, 0.3, 1.4, 2.9])
def test_gradient_orientation_follows_an_edge(phi):
    y, x = _grid(96, 96)
    img = torch.sigmoid(((x - 48) * math.cos(phi) + (y - 48) * math.sin(phi)) / 4.0)[None]
    laf = ellipse_to_laf(torch.tensor([[48.0, 48.0]]), torch.eye(2)[None] / 15.0**2)
    out = Orienter("gradient")(PatchPyramid(img), laf)
    assert abs(float(_wrap(laf_angle(out) - phi))) < math.radians(10)


def _rotated_pair():
    path = require(DATA / "oxford_graf" / "img1.png")
    img = torch.from_numpy(cv2.imread(str(path))[200:456, 300:556, ::-1].copy()).permute(2, 0, 1).float() / 255
    rot = torch.rot90(img, 1, dims=(1, 2))  # pixel (x, y) -> (y, W - 1 - x): a rotation by -90 degrees
    g = torch.Generator().manual_seed(0)
    xy0 = 40 + 176 * torch.rand(150, 2, generator=g)
    xy1 = torch.stack([xy0[:, 1], img.shape[2] - 1 - xy0[:, 0]], 1)
    return img, rot, xy0, xy1


@pytest.mark.parametrize("method", ["orinet", "gradient"])
def test_orientation_rotates_with_the_image(method):
    img, rot, xy0, xy1 = _rotated_pair()
    orienter = Orienter(method)
    a0 = laf_angle(orienter(PatchPyramid(img), ellipse_to_laf(xy0, torch.eye(2).expand(150, 2, 2) / 12.0**2)))
    a1 = laf_angle(orienter(PatchPyramid(rot), ellipse_to_laf(xy1, torch.eye(2).expand(150, 2, 2) / 12.0**2)))
    err = _wrap(a1 - a0 + math.pi / 2).abs()
    assert err.median() < math.radians(5)
    assert (err < math.radians(15)).float().mean() > 0.8


def test_extractor_end_to_end_is_rotation_invariant():
    img, rot, xy0, xy1 = _rotated_pair()
    ex = LocalFeatureExtractor(PatchConfig(descriptor="tfeat", magnification=2.0))
    f0 = ex.extract(img, _circles(xy0, 8.0))
    f1 = ex.extract(rot, _circles(xy1, 8.0))
    assert f0.descriptors.shape == (150, 128) and torch.allclose(f0.descriptors.norm(dim=1), torch.ones(150))
    assert torch.all(f0.shape_laf[:, 1, 0] == 0)
    assert torch.allclose(f0.scale, torch.full((150,), 8.0), rtol=1e-4)
    assert torch.equal(f0.xy, xy0)
    nn = torch.cdist(f0.descriptors, f1.descriptors).argmin(1)
    assert (nn == torch.arange(150)).float().mean() > 0.8
    # Fixed orientation: 0 in image 1 and the image rotation (-90 degrees) in image 2, no OriNet.
    pyr1 = ex.pyramid(rot)
    g0 = ex.describe_fixed(ex.pyramid(img), f0.shape_laf, 0.0)
    g1 = ex.describe_fixed(pyr1, f1.shape_laf, -math.pi / 2)
    assert torch.allclose(_wrap(g1.angle), torch.full((150,), -math.pi / 2), atol=1e-4)
    nn = torch.cdist(g0.descriptors, g1.descriptors).argmin(1)
    assert (nn == torch.arange(150)).float().mean() > 0.9


@pytest.mark.parametrize("method", ["tfeat", "rootsift"])
def test_descriptor_dims_and_normalisation(method):
    desc = Descriptor(method)
    laf = ellipse_to_laf(torch.rand(7, 2) * 50 + 10, torch.eye(2).expand(7, 2, 2) / 36)
    out = desc(PatchPyramid(torch.rand(3, 70, 70)), laf)
    assert out.shape == (7, desc.dim) == (7, 128)
    assert torch.allclose(out.norm(dim=1), torch.ones(7), atol=1e-5)
    if method == "rootsift":
        assert (out >= 0).all()
    assert desc(PatchPyramid(torch.rand(3, 70, 70)), torch.zeros(0, 2, 3)).shape == (0, 128)


def test_upright_and_fixed_orientation():
    laf = ellipse_to_laf(torch.tensor([[20.0, 20.0]]), torch.tensor([[[0.02, 0.01], [0.01, 0.05]]]))
    pyr = PatchPyramid(torch.rand(1, 40, 40))
    assert Orienter("upright")(pyr, laf)[0, 1, 0] == 0
    from slime_match.features.orientation import OrientationConfig

    fixed = Orienter("fixed", config=OrientationConfig(angle=1.1))(pyr, laf)
    assert torch.isclose(laf_angle(fixed), torch.tensor([1.1]), atol=1e-5).all()


def test_bad_names_raise_config_error():
    with pytest.raises(ConfigError):
        ShapeEstimator("affnett")
    with pytest.raises(ConfigError):
        Orienter("sift")
    with pytest.raises(ConfigError):
        Descriptor("sosnet")
    with pytest.raises(ConfigError):
        resolve_descriptor("hardnet++")
    with pytest.raises(ConfigError):
        PatchConfig.from_dict({"magnificaton": 2.0})
    with pytest.raises(ConfigError):
        LocalFeatureExtractor(PatchConfig(orientation="fixed", descriptor="rootsift"))
