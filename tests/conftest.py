"""Shared test fixtures: paths to ../shared data and the weights cache."""

import os
from pathlib import Path

import pytest

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
