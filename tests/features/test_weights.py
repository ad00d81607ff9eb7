"""Weights: kornia's cache layout, HardNet's and HardTFeat's real checkpoints, "auto"'s choice, clear errors
without network."""

import shutil
import socket

import kornia
import kornia.core.download as kdownload
import pytest
import torch
import torch.nn.functional as F
from conftest import require_weights

from slime_match.errors import WeightsNotFoundError
from slime_match.features.descriptors import AUTO_ORDER, Descriptor, resolve_descriptor
from slime_match.features.laf import PatchPyramid, ellipse_to_laf
from slime_match.features.weights import checkpoint_dir, is_cached, load_model, load_state_dict, weights_path


@pytest.fixture
def no_network(monkeypatch):
    """Every download attempt fails at once (non-transient, so kornia does not retry)."""

    def fail(*args, **kwargs):
        raise RuntimeError("network disabled in tests")

    monkeypatch.setattr(kdownload, "_download_url_to_file", fail)


@pytest.fixture
def hardnet_home(tmp_path):
    """A torch home whose hub cache holds a HardNet checkpoint in kornia's real format."""
    folder = tmp_path / "hub" / "checkpoints"
    folder.mkdir(parents=True)
    torch.manual_seed(0)
    net = kornia.feature.HardNet(pretrained=False)
    torch.save({"state_dict": net.state_dict()}, folder / "checkpoint_liberty_with_aug.pth")
    return tmp_path, net.eval()


def test_hardnet_checkpoint_loads_from_weights_dir_and_torch_home(hardnet_home, monkeypatch, no_network):
    home, reference = hardnet_home
    assert checkpoint_dir(home) == home / "hub" / "checkpoints"
    assert is_cached("hardnet", home)
    patches = torch.rand(5, 1, 32, 32)
    with torch.inference_mode():
        expect = reference(patches)
        assert torch.allclose(load_model("hardnet", home)(patches), expect, atol=1e-6)
        monkeypatch.setenv("TORCH_HOME", str(home))
        assert torch.allclose(load_model("hardnet")(patches), expect, atol=1e-6)
    desc = Descriptor("hardnet")
    laf = ellipse_to_laf(torch.tensor([[30.0, 30.0], [50.0, 40.0]]), torch.eye(2).expand(2, 2, 2) / 25)
    out = desc(PatchPyramid(torch.rand(3, 80, 90)), laf)
    assert out.shape == (2, desc.dim) and torch.allclose(out.norm(dim=1), torch.ones(2))
    assert resolve_descriptor("auto") == ("hardnet", None)


@pytest.mark.parametrize(
    ("name", "alternative"),
    [("hardnet", "--descriptor hardtfeat or tfeat (other weights) or rootsift (weight-free)"),
     ("affnet", "--shape baumberg (weight-free)"),
     ("orinet", "--orientation gradient|upright"), ("keynet", "the hz+ or rootsift base pipelines")],
)
def test_missing_weights_raise_with_alternatives(tmp_path, no_network, name, alternative):
    with pytest.raises(WeightsNotFoundError, match="could not be downloaded") as err:
        load_model(name, tmp_path)
    assert alternative in str(err.value)
    assert not any(tmp_path.iterdir())  # nothing half-written


def test_auto_descriptor_falls_back_to_rootsift_with_warning(tmp_path, no_network):
    name, warning = resolve_descriptor("auto", tmp_path)
    assert name == "rootsift"
    assert "hardnet, hardtfeat, tfeat unavailable, using rootsift (weight-free) instead" in warning
    assert "--descriptor hardtfeat or tfeat (other weights) or rootsift (weight-free)" in warning
    assert resolve_descriptor("tfeat", tmp_path) == ("tfeat", None)
    with pytest.raises(WeightsNotFoundError, match="none of hardnet, hardtfeat, tfeat is available"):
        resolve_descriptor("auto", tmp_path, candidates=AUTO_ORDER[:-1])  # a pipeline that needs a network


@pytest.mark.parametrize(("present", "chosen", "passed_over"),
                         [("HardTFeat.pth", "hardtfeat", "hardnet"), ("tfeat-liberty.params", "tfeat", "hardnet, hardtfeat")])
def test_auto_descriptor_takes_the_best_available(tmp_path, no_network, present, chosen, passed_over):
    require_weights(chosen)
    source = weights_path(chosen)
    shutil.copy(source, tmp_path / present)
    name, warning = resolve_descriptor("auto", tmp_path)
    assert name == chosen and f"{passed_over} unavailable, using {chosen} (learned) instead" in warning


def test_hardtfeat_is_tfeat_with_its_own_weights():
    """HardTFeat's checkpoint in kornia's TFeat gives the network its authors trained: per-patch normalisation,
    two convolutions with tanh and max pooling, and an 8x8 convolution with tanh as the descriptor."""
    require_weights("hardtfeat")
    raw = load_state_dict("hardtfeat")["state_dict"]
    patches = torch.rand(6, 1, 32, 32)
    flat = patches.reshape(6, -1)
    x = (patches - flat.mean(1).view(6, 1, 1, 1)) / (flat.std(1, unbiased=False).view(6, 1, 1, 1) + 1e-7)
    x = F.max_pool2d(torch.tanh(F.conv2d(x, raw["features.0.weight"], raw["features.0.bias"])), 2)
    x = torch.tanh(F.conv2d(x, raw["features.3.weight"], raw["features.3.bias"]))
    expect = torch.tanh(F.conv2d(x, raw["classifier.1.weight"], raw["classifier.1.bias"])).reshape(6, -1)
    with torch.inference_mode():
        got = load_model("hardtfeat")(patches)
    assert got.shape == (6, 128) and torch.allclose(got, expect, atol=1e-3)
    assert Descriptor("hardtfeat").describe_patches(patches).norm(dim=1).allclose(torch.ones(6))


def test_shared_weights_load(no_network):
    require_weights("affnet", "orinet", "tfeat", "keynet")
    for name in ("affnet", "orinet", "tfeat", "keynet"):
        assert not load_model(name).training


def test_auto_descriptor_offline_falls_back_without_waiting_for_retries(tmp_path, monkeypatch):
    """No download host resolves: "auto" takes its fallback at once; kornia's downloader is not called."""

    def no_dns(host, *args, **kwargs):
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    def downloader(*args, **kwargs):
        raise AssertionError("the downloader must not run when no host resolves")

    monkeypatch.setattr(socket, "getaddrinfo", no_dns)
    monkeypatch.setattr(kdownload, "load_state_dict_from_url", downloader)
    name, warning = resolve_descriptor("auto", tmp_path)
    assert name == "rootsift"
    assert "no download host resolves: huggingface.co" in warning
    assert "--descriptor hardtfeat or tfeat (other weights) or rootsift (weight-free)" in warning
    with pytest.raises(WeightsNotFoundError, match="must not run"):  # explicit HardNet: kornia's downloader runs
        load_model("hardnet", tmp_path)
