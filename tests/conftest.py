"""Shared test fixtures: paths to ../shared data and the weights cache."""

import os
from pathlib import Path

import cv2
import pytest
import torch
import torch.nn.functional as F
from skimage.data import stereo_motorcycle

from slime_match.cli import main

ROOT = Path(__file__).resolve().parents[1]
SHARED = (ROOT.parent / "shared").resolve()
DATA = SHARED / "data"
WEIGHTS = SHARED / "weights"

if WEIGHTS.is_dir():
    os.environ.setdefault("TORCH_HOME", str(WEIGHTS))


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
