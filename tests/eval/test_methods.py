"""Method specs: parsing, labels, option errors and the registry."""

import pytest

from slime_match.errors import ConfigError
from slime_match.eval import methods
from slime_match.eval.bench_config import BenchConfig


def test_method_specs():
    assert methods.parse_method_spec("hz+:descriptor=tfeat,max_keypoints=500,upright=true") == (
        "hz+",
        {"descriptor": "tfeat", "max_keypoints": 500, "upright": True},
    )
    assert methods.method_label("keynet:max_keypoints=100") == "keynet_max_keypoints-100"
    with pytest.raises(ConfigError):
        methods.parse_method_spec("superglue")
    with pytest.raises(ConfigError):
        methods.make_method("hz+:no_such_option=1")
    with pytest.raises(ConfigError):
        methods.make_method("opencv-sift:ratio=2")
    with pytest.raises(ConfigError):
        BenchConfig(methods=["rootsift", "rootsift"]).validate()
    assert set(methods.PAPER_METHODS) <= set(methods.REGISTRY)
