"""Shared test fixtures: paths to the test data and weights folders beside the repository, and the skips of tests whose data or
weights are absent.

A test that needs network weights (AffNet, OriNet, TFeat, HardTFeat, HardNet, Key.Net) skips, naming them,
when they are neither cached nor downloadable: it calls :func:`require_weights`, and any other test or fixture
that stops on a :class:`~slime_match.errors.WeightsNotFoundError` is turned into the same skip. A test of the
learned bases (ALIKED, DISK, XFeat, LightGlue) calls :func:`require_learned_weights`, which skips unless they are
cached. With ``SLIME_REQUIRE_WEIGHTS=1`` (CI sets it) such a skip is a failure instead, so CI runs every test.

The torch-hub cache is ``TORCH_HOME`` when set; else ``.cache/torch`` in the repository when
``scripts/fetch_learned_weights.py`` built it (learned weights, and links to the shared weights), else the shared
weights folder beside the repository.
"""

import os
import socket
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from skimage.data import astronaut, stereo_motorcycle

from slime_match.cli import main
from slime_match.errors import WeightsNotFoundError
from slime_match.features.learned_weights import cache_path
from slime_match.features.weights import is_cached, load_state_dict
from slime_match.io import save_json, save_npz
from slime_match.runs.export import PairMatches

ROOT = Path(__file__).resolve().parents[1]
SHARED = (ROOT.parent / "shared").resolve()
DATA = SHARED / "data"
WEIGHTS = SHARED / "weights"
LEARNED_CACHE = ROOT / ".cache" / "torch"  # what scripts/fetch_learned_weights.py builds for the tests

if (LEARNED_CACHE / "hub" / "checkpoints").is_dir():
    os.environ.setdefault("TORCH_HOME", str(LEARNED_CACHE))
elif WEIGHTS.is_dir():
    os.environ.setdefault("TORCH_HOME", str(WEIGHTS))

REQUIRE_WEIGHTS = os.environ.get("SLIME_REQUIRE_WEIGHTS", "").strip() not in ("", "0")


def weights_unavailable(reason: str) -> None:
    """Skip the calling test, or fail it when ``SLIME_REQUIRE_WEIGHTS`` is set (CI must run every test)."""
    if REQUIRE_WEIGHTS:
        pytest.fail(f"{reason} [SLIME_REQUIRE_WEIGHTS is set: a test that needs weights must run]", pytrace=False)
    pytest.skip(reason)


def require_weights(*names: str) -> None:
    """Skip the calling test (fail under ``SLIME_REQUIRE_WEIGHTS=1``) unless the weights of every model in
    ``names`` ("affnet", "orinet", "tfeat", "hardtfeat", "hardnet", "keynet") are cached or can be downloaded
    now (a download is tried at once when a download host resolves, without waiting for retries)."""
    missing = []
    for name in names:
        if is_cached(name):
            continue
        try:
            load_state_dict(name, retry_offline=False)  # caches the file when the network allows
        except WeightsNotFoundError:
            missing.append(name)
    if missing:
        weights_unavailable(f"needs the {', '.join(missing)} weights, which are not cached (TORCH_HOME="
                            f"{os.environ.get('TORCH_HOME', 'unset')}) and could not be downloaded")


def require_learned_weights(*models: str) -> None:
    """Skip the calling test (fail under ``SLIME_REQUIRE_WEIGHTS=1``) unless the checkpoints of every model in
    ``models`` (keys of ``learned_weights.CACHE_FILES``: "aliked-n16", "disk", "lightglue-aliked"...) are in the
    torch-hub cache. Nothing is downloaded: ``scripts/fetch_learned_weights.py`` fills the cache."""
    missing = [cache_path(model) for model in models if not cache_path(model).is_file()]
    if missing:
        weights_unavailable(f"needs {', '.join(p.name for p in missing)} in {missing[0].parent}: run "
                            f"python scripts/fetch_learned_weights.py {LEARNED_CACHE} --link {WEIGHTS}")


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item):
    """A fixture that stops on missing weights skips its tests, naming them (see :func:`weights_unavailable`)."""
    try:
        return (yield)
    except WeightsNotFoundError as error:
        weights_unavailable(f"needs weights: {error}")


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item):
    """A test that stops on missing weights is skipped, naming them (see :func:`weights_unavailable`)."""
    try:
        return (yield)
    except WeightsNotFoundError as error:
        weights_unavailable(f"needs weights: {error}")


@pytest.fixture(params=["cpu", pytest.param("cuda", marks=pytest.mark.skipif(
    not torch.cuda.is_available(), reason="needs a CUDA GPU"))])
def device(request) -> torch.device:
    """Each device a test runs on: the CPU, and CUDA where a GPU is present (skipped elsewhere)."""
    return torch.device(request.param)


@pytest.fixture
def one_torch_thread():
    """Torch on one thread for the test: networks on small images run about as fast, and spare a busy machine."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def require(path: Path) -> Path:
    """Skip the calling test when a data file it reads is absent (e.g. a user's clone)."""
    if not path.exists():
        pytest.skip(f"needs {path}")
    return path


def rotated_astronaut(angle: float = 20.0, scale: float = 0.8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """scikit-image's astronaut at 384 x 384 and its copy rotated by ``angle`` degrees and scaled by ``scale``
    about the centre: image 0, image 1 and the homography 0 -> 1."""
    image = cv2.resize(astronaut().astype(np.float32) / 255, (384, 384), interpolation=cv2.INTER_AREA)
    H = np.vstack([cv2.getRotationMatrix2D((191.5, 191.5), angle, scale), [0, 0, 1]])
    return image, cv2.warpPerspective(image, H, (384, 384), flags=cv2.INTER_LINEAR), H


@pytest.fixture
def offline(tmp_path, monkeypatch):
    """An empty torch-hub cache and no network (name resolution fails as it does offline); the cache folder."""
    monkeypatch.setattr(torch.hub, "_hub_dir", None, raising=False)
    monkeypatch.setenv("TORCH_HOME", str(tmp_path))

    def no_dns(*args, **kwargs):
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known (network cut by the test)")

    monkeypatch.setattr(socket, "getaddrinfo", no_dns)
    return tmp_path / "hub" / "checkpoints"


@pytest.fixture
def data_dir() -> Path:
    return require(DATA)


@pytest.fixture(scope="session")
def pair(tmp_path_factory):
    """A real stereo pair (scikit-image's Middlebury motorcycle), halved for speed."""
    folder = tmp_path_factory.mktemp("pair")
    left, right, _ = stereo_motorcycle()
    paths = []
    for name, image in (("left.png", left), ("right.png", right)):
        small = cv2.resize(image, (370, 250), interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(folder / name), small[:, :, ::-1])
        paths.append(str(folder / name))
    return paths


def run_cli(capsys, *argv) -> tuple[int, str, str]:
    """Run the ``slime`` command line in-process: (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def random_patches(n: int, seed: int = 0) -> torch.Tensor:
    """(n, 1, 32, 32) patches: half random noise, half smooth (blob-like), the first 3 flat."""
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 1, 32, 32, generator=g)
    x[: n // 2] = F.avg_pool2d(torch.rand(n // 2, 1, 40, 40, generator=g), 9, 1)
    x[:3] = 0.4
    return x


def export_pairs() -> list[PairMatches]:
    """The matches of a run, for the SfM exports: two pairs sharing image a, with duplicates, a near-duplicate
    0.4 px away and a repeated keypoint pair."""
    ab = PairMatches("a.png", "b.png",
                     np.array([[10, 10], [10, 10], [10.4, 10.3], [50, 50]], float),
                     np.array([[20, 20], [30, 30], [20, 20], [60, 60]], float),
                     np.array([0.1, 0.2, 0.05, 0.3]))
    ac = PairMatches("a.png", "c.png", np.array([[50.5, 50], [5, 5]], float), np.array([[7, 7], [9, 9]], float),
                     np.array([0.4, 0.2]))
    return [ab, ac]


def write_run_folder(tmp_path, pairs: list[PairMatches], inliers: bool = False):
    """A run folder as `slime pairs` writes it, holding ``pairs``."""
    run = tmp_path / "run"
    records = []
    for pair in pairs:
        folder = f"{pair.name0}__{pair.name1}"
        arrays = {"keypoints0": pair.keypoints0, "keypoints1": pair.keypoints1, "scores": pair.scores}
        if inliers:
            arrays["inliers"] = pair.scores < 0.25
        (run / folder).mkdir(parents=True)
        save_npz(run / folder / "matches.npz", **arrays)
        records.append({"image0": pair.name0, "image1": pair.name1, "folder": folder, "status": "done"})
    records.append({"image0": "a.png", "image1": "x.png", "folder": "a.png__x.png", "status": "failed"})
    save_json(run / "pairs.json", {"pairs": records, "finished": True})
    return run


@pytest.fixture
def small_images(tmp_path):
    """Three random 64x48 images a.png, b.png, c.png (the images of :func:`export_pairs`)."""
    folder = tmp_path / "images"
    folder.mkdir()
    g = np.random.default_rng(0)
    for name in ("a.png", "b.png", "c.png"):
        cv2.imwrite(str(folder / name), g.integers(0, 255, (48, 64, 3), dtype=np.uint8))
    return folder
