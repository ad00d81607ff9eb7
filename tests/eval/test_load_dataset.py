"""Dataset specs: unknown names, missing folders, unknown pair kinds."""

import pytest

from slime_match.errors import ConfigError
from slime_match.eval.datasets import load_dataset
from slime_match.eval.datasets.pair import Pair


def test_load_dataset_errors(tmp_path):
    with pytest.raises(ConfigError):
        load_dataset("nonsense")
    with pytest.raises(FileNotFoundError):
        load_dataset(f"wxbs:{tmp_path}")
    with pytest.raises(FileNotFoundError):
        load_dataset(f"evd:{tmp_path / 'nope'}")
    with pytest.raises(ConfigError):
        Pair("x", tmp_path, tmp_path, "stereo")
