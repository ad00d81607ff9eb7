"""Vectorised gradient-histogram operators and fused networks against kornia's reference modules."""

import math

import cv2
import numpy as np
import pytest
import torch
from conftest import DATA, random_patches, require, require_weights
from kornia.feature import PatchDominantGradientOrientation, SIFTDescriptor
from kornia.filters import spatial_gradient

from slime_match.errors import ConfigError
from slime_match.features.gradients import DominantGradientOrientation, SIFTPatchDescriptor, patch_gradients
from slime_match.features.harrisz import HarrisZConfig, detect_harrisz
from slime_match.features.inference import _OneDnnRun, fuse_for_inference
from slime_match.features.laf import PatchPyramid, ellipse_to_laf
from slime_match.features.orientation import Orienter
from slime_match.features.shape import ShapeEstimator
from slime_match.features.weights import load_model


@pytest.mark.parametrize("mode", ["diff", "sobel"])
def test_patch_gradients_equal_kornia(mode):
    x = random_patches(600)
    ref = spatial_gradient(x, mode)
    gx, gy = patch_gradients(x, mode)
    assert torch.allclose(gx, ref[:, 0, 0], atol=1e-6) and torch.allclose(gy, ref[:, 0, 1], atol=1e-6)
    with pytest.raises(ConfigError):
        patch_gradients(x, "scharr")


@pytest.mark.parametrize("rootsift", [True, False])
def test_sift_equals_kornia(rootsift):
    x = random_patches(600)
    ours = SIFTPatchDescriptor(32, rootsift=rootsift)(x)
    ref = SIFTDescriptor(32, rootsift=rootsift)(x)
    assert ours.shape == (600, 128)
    assert (ours - ref).abs().max() < 1e-5
    assert torch.allclose(ours[3:].norm(dim=1), torch.ones(597), atol=1e-5)


def test_sift_rot90_permutes_cells_and_bins():
    x = random_patches(600)[3:]
    sift = SIFTPatchDescriptor(32)
    d = sift(x).view(-1, 8, 4, 4)
    # torch.rot90 (dims 2, 3): content turns 90 deg counter-clockwise on screen, gradient angles (atan2 in
    # pixel coordinates, y down) decrease by pi / 2, i.e. 2 of the 8 bins; the 4x4 cell grid turns the same way.
    r = sift(torch.rot90(x, 1, dims=(2, 3))).view(-1, 8, 4, 4)
    expect = torch.roll(torch.rot90(d, 1, dims=(2, 3)), -2, dims=1)
    assert (r - expect).abs().max() < 1e-4
    assert (r - d).abs().max() > 0.1  # the permutation is not the identity


def test_dominant_orientation_equals_kornia():
    x = random_patches(600)
    ours = DominantGradientOrientation(32, 36)(x)
    ref = PatchDominantGradientOrientation(32, 36)(x)
    assert torch.isfinite(ours).all()  # flat patches (the first 3) have an empty histogram: any bin is a peak
    diff = torch.remainder(ours - ref + math.pi, 2 * math.pi) - math.pi
    assert diff[3:].abs().max() < 1e-4


@pytest.mark.parametrize("name", ["affnet", "orinet", "tfeat"])
def test_fused_networks_equal_originals(name):
    require_weights(name)
    net = load_model(name, None, "cpu")
    fused = fuse_for_inference(net)
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in fused.modules())
    onednn_runs = [m for m in fused.modules() if isinstance(m, _OneDnnRun)]
    assert len(onednn_runs) == (1 if torch.backends.mkldnn.is_available() else 0)
    x = random_patches(300)
    with torch.inference_mode():
        if name == "affnet":
            a, b = (m.features(m._normalize_input(x)).flatten(1) for m in (net, fused))
        else:
            a, b = net(x), fused(x)
    assert (a - b).abs().max() < 1e-4


def _graf_half(k: int) -> torch.Tensor:
    img = cv2.imread(str(require(DATA / "oxford_graf" / f"img{k}.png")))[:, :, ::-1]
    img = cv2.resize(img, (400, 320), interpolation=cv2.INTER_AREA)
    return torch.from_numpy(img.copy()).permute(2, 0, 1).float() / 255


def test_rootsift_matches_graf_like_kornia():
    """Same frames, same patches: correct mutual matches of ours and kornia's RootSIFT agree within 2%."""
    h = np.loadtxt(require(DATA / "oxford_graf" / "H1to2p"))
    s = np.diag([0.5, 0.5, 1.0])
    h = s @ h @ np.linalg.inv(s)  # both images halved (pixel-centre offsets are far below the threshold)
    frames, patches = [], []
    for k in (1, 2):
        img = _graf_half(k)
        kp = detect_harrisz(img, HarrisZConfig(max_keypoints=1500))
        pyr = PatchPyramid(img)
        laf = Orienter("gradient")(pyr, ShapeEstimator("baumberg")(pyr, ellipse_to_laf(kp.xy, kp.ellipse)))
        frames.append(laf[:, :, 2].numpy().astype(np.float64))
        patches.append(pyr.extract(laf, 32, 6.0))
    xy1 = np.c_[frames[0], np.ones(len(frames[0]))] @ h.T
    xy1 = xy1[:, :2] / xy1[:, 2:]
    correct = {}
    for name, sift in (("ours", SIFTPatchDescriptor(32)), ("kornia", SIFTDescriptor(32))):
        d0, d1 = (sift(p) for p in patches)
        dist = torch.cdist(d0, d1)
        nn01, nn10 = dist.argmin(1), dist.argmin(0)
        mutual = (nn10[nn01] == torch.arange(len(d0))).numpy()
        err = np.linalg.norm(xy1 - frames[1][nn01.numpy()], axis=1)
        correct[name] = int((mutual & (err < 3.0)).sum())
    assert correct["kornia"] > 100
    assert abs(correct["ours"] - correct["kornia"]) <= 0.02 * correct["kornia"]
