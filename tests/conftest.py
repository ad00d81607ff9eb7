"""Shared test fixtures: paths to ../shared data and the weights cache."""

import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from skimage.data import stereo_motorcycle

from slime_match.cli import main
from slime_match.io import save_json, save_npz
from slime_match.runs.export import PairMatches

ROOT = Path(__file__).resolve().parents[1]
SHARED = (ROOT.parent / "shared").resolve()
DATA = SHARED / "data"
WEIGHTS = SHARED / "weights"

if WEIGHTS.is_dir():
    os.environ.setdefault("TORCH_HOME", str(WEIGHTS))


@pytest.fixture(params=["cpu", pytest.param("cuda", marks=pytest.mark.skipif(
    not torch.cuda.is_available(), reason="needs a CUDA GPU"))])
def device(request) -> torch.device:
    """Each device a test runs on: the CPU, and CUDA where a GPU is present (skipped elsewhere)."""
    return torch.device(request.param)


def require(path: Path) -> Path:
    """Skip the calling test when a ../shared file it reads is absent (e.g. a user's clone)."""
    if not path.exists():
        pytest.skip(f"needs {path}")
    return path


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
