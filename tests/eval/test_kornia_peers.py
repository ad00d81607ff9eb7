"""kornia peer LoFTR: resize geometry, options, missing weights, plumbing with random weights.

No pretrained weights are needed: the missing-weights tests use an empty hub cache with the network cut, and the
plumbing tests hand kornia's real pretrained path random checkpoints.
"""

import importlib
import socket

import cv2
import numpy as np
import pytest
import torch

from slime_match.errors import ConfigError, WeightsNotFoundError
from slime_match.eval.kornia_peers import KorniaLoFTR, fit_size, frame_of, resize_to

H, W = 96, 128


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _pair() -> tuple[np.ndarray, np.ndarray]:
    """A textured (96, 128, 3) RGB image and its copy shifted 3 px right."""
    rng = np.random.default_rng(0)
    image = cv2.GaussianBlur(rng.random((H, W + 3, 3)).astype(np.float32), (0, 0), 1.5)
    image = (image - image.min()) / (image.max() - image.min())
    return np.ascontiguousarray(image[:, 3:]), np.ascontiguousarray(image[:, :-3])


def _module(name: str):
    return importlib.import_module(name)


# ------------------------------------------------------------------------------------------- geometry


def test_fit_size_bounds_and_multiples():
    assert fit_size(96, 128, 840, 8) == (96, 128)  # small enough and already multiples: unchanged
    assert fit_size(100, 130, 840, 8) == (104, 128)  # nearest multiples of 8
    assert fit_size(960, 1280, 640, 8) == (480, 640)
    assert fit_size(96, 128, 0, 1) == (96, 128)  # 0 = no limit
    for h, w, side, mult in [
        (1000, 3000, 840, 8),
        (3001, 17, 840, 8),
        (777, 1001, 1024, 1),
        (500, 700, 100, 16),
    ]:
        nh, nw = fit_size(h, w, side, mult)
        assert max(nh, nw) <= side and nh % mult == 0 and nw % mult == 0 and min(nh, nw) >= mult


def test_frame_maps_pixel_centres_and_edges_exactly():
    small, big = (48, 64), (96, 128)
    xy = np.array([[0.0, 0.0], [63.0, 47.0], [-0.5, -0.5], [63.5, 47.5], [10.25, 3.0]])
    expect = np.array([[0.5, 0.5], [126.5, 94.5], [-0.5, -0.5], [127.5, 95.5], [21.0, 6.5]])
    np.testing.assert_array_equal(frame_of(small, big).to_original(xy), expect)
    # anisotropic: the scale differs per axis
    np.testing.assert_allclose(
        frame_of((50, 40), (100, 160)).to_original([[2.0, 2.0]]), [[9.5, 4.5]], rtol=0, atol=1e-12
    )
    assert frame_of(small, big).to_original(np.zeros((0, 2))).shape == (0, 2)


def test_resize_then_map_back_agrees_with_opencv_on_a_ramp():
    """Shrinking x / y ramps by 2: resized pixel j holds exactly the original coordinate its frame gives."""
    xs, ys = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    small = resize_to(np.stack([xs, ys, xs], -1), (H // 2, W // 2))
    jx, jy = np.meshgrid(np.arange(W // 2), np.arange(H // 2))
    mapped = frame_of((H // 2, W // 2), (H, W)).to_original(np.stack([jx.ravel(), jy.ravel()], 1))
    np.testing.assert_array_equal(small[..., 0].ravel(), mapped[:, 0])
    np.testing.assert_array_equal(small[..., 1].ravel(), mapped[:, 1])


# ------------------------------------------------------------------------------------------- options


@pytest.mark.parametrize(
    ("cls", "options"),
    [
        (KorniaLoFTR, {"weights": "nope"}),
        (KorniaLoFTR, {"max_side": 4}),
        (KorniaLoFTR, {"max_side": "big"}),
        (KorniaLoFTR, {"threshold": 1.5}),
        (KorniaLoFTR, {"device": "gpu-ish"}),
        (KorniaLoFTR, {"num_features": 100}),  # not a LoFTR option
    ],
)
def test_bad_option_is_a_config_error(cls, options):
    with pytest.raises(ConfigError):
        cls(**options)


# ------------------------------------------------------------------------------------------- missing weights


@pytest.fixture
def offline(tmp_path, monkeypatch):
    """An empty torch-hub cache and no network: name resolution fails as it does offline, and kornia gets no
    time to wait between retries (so the test is fast and the same on machines with internet or weights)."""
    monkeypatch.setattr(torch.hub, "_hub_dir", None, raising=False)
    monkeypatch.setenv("TORCH_HOME", str(tmp_path))

    def no_dns(*args, **kwargs):
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known (network cut by the test)")

    monkeypatch.setattr(socket, "getaddrinfo", no_dns)
    monkeypatch.setattr(_module("kornia.core.download"), "_MAX_CALL_SLEEP_SECONDS", 0.0, raising=False)
    return tmp_path / "hub" / "checkpoints"


def test_missing_weights_raise_a_helpful_error(offline):
    image0, image1 = _pair()
    model = "LoFTR 'outdoor'"
    method = KorniaLoFTR(device="cpu")  # building the method costs nothing: the models load on the first call
    with pytest.raises(WeightsNotFoundError) as err:
        method(image0, image1)
    text = str(err.value)
    assert model in text and str(offline) in text and "could not be downloaded" in text
    assert "network cut by the test" in text  # the failed download itself, not some other error
    for alternative in ("keynet", "hz+", "rootsift", "opencv-sift"):
        assert alternative in text
    assert not (offline / "loftr_outdoor.ckpt").exists()


def test_unrelated_loading_errors_are_not_disguised(offline, monkeypatch):
    loftr_module = _module("kornia.feature.loftr.loftr")
    monkeypatch.setattr(
        loftr_module, "load_state_dict_from_url", lambda *a, **k: {"state_dict": {"x": torch.ones(1)}}
    )
    with pytest.raises(RuntimeError, match="state_dict") as err:  # a wrong checkpoint, not a missing one
        KorniaLoFTR(device="cpu")(*_pair())
    assert not isinstance(err.value, WeightsNotFoundError)


# ------------------------------------------------------------------------------------------- random weights


def _check_contract(out, shape0, shape1):
    xy0, xy1, scores, seconds = out
    k = len(scores)
    assert k > 0
    assert xy0.shape == (k, 2) and xy1.shape == (k, 2) and scores.shape == (k,)
    assert xy0.dtype == xy1.dtype == scores.dtype == np.float64
    assert np.isfinite(scores).all() and np.isfinite(xy0).all() and np.isfinite(xy1).all()
    for xy, (h, w) in ((xy0, shape0), (xy1, shape1)):
        assert (xy >= -0.5).all() and (xy[:, 0] <= w - 0.5).all() and (xy[:, 1] <= h - 0.5).all()
    assert isinstance(seconds, float) and seconds > 0


def test_loftr_plumbing_with_random_weights(offline, monkeypatch):
    import kornia.feature as KF

    torch.manual_seed(0)
    checkpoint = {"state_dict": KF.LoFTR(pretrained=None).state_dict()}
    calls = []
    monkeypatch.setattr(
        _module("kornia.feature.loftr.loftr"),
        "load_state_dict_from_url",
        lambda url, **k: calls.append(url) or checkpoint,
    )
    image0, image1 = _pair()
    # 96 x 128 -> 48 x 64 (multiples of 8, longest side 64), threshold 0 so that random weights give matches
    method = KorniaLoFTR(max_side=64, threshold=0.0, device="cpu")
    out = method(image0, image1[:80])
    assert len(calls) == 1 and "loftr_outdoor" in str(
        calls[0]
    )  # kornia's real pretrained path, "outdoor" weights
    _check_contract(out, (H, W), (80, W))
    xy0, _, scores, _ = out
    assert (scores >= 0).all() and (scores < 1).all()
    # keypoints0 sit on LoFTR's coarse grid, 8 * cell - 0.5 in the 48 x 64 image: 16 * cell - 0.5 here
    np.testing.assert_array_equal((xy0 + 0.5) % 16, 0)
