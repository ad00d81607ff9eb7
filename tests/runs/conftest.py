"""Fixtures of the batch tests."""

import shutil

import pytest


@pytest.fixture
def images(pair, tmp_path):
    """A folder with the stereo pair (left.png, right.png) and a copy of right.png in a sub-folder."""
    folder = tmp_path / "images"
    (folder / "sub").mkdir(parents=True)
    shutil.copy(pair[0], folder / "left.png")
    shutil.copy(pair[1], folder / "right.png")
    shutil.copy(pair[1], folder / "sub" / "right.png")
    return folder
