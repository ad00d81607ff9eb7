"""Method specs: parsing, labels, option errors and the registry; the OpenCV SIFT and ASIFT matchers."""

import numpy as np
import pytest

from slime_match.choices import PAPER_METHODS
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
    assert set(PAPER_METHODS) <= set(methods.REGISTRY)


def _warped_pair():
    """skimage's camera at 192x192 (RGB float) and an exact affine warp of it (tilt 1.4, rotation 20 deg)."""
    import cv2
    from skimage.data import camera

    image = cv2.resize(camera(), (192, 192), interpolation=cv2.INTER_AREA).astype(np.float32) / 255
    A = cv2.getRotationMatrix2D((96, 96), 20, 1.0) @ np.diag([1 / 1.4, 1.0, 1.0])
    A[:, 2] += [40, 0]
    warped = cv2.warpAffine(image, A, (192, 192), flags=cv2.INTER_LINEAR)
    return np.dstack([image] * 3), np.dstack([warped] * 3), A


def test_asift_matches_an_affine_pair_and_is_empty_without_features():
    image0, image1, A = _warped_pair()
    method = methods.make_method("asift:num_features=500", device="cpu", seed=0)
    assert method.config == methods.AsiftConfig(num_features=500)
    xy0, xy1, scores, seconds = method(image0, image1)
    assert xy0.shape == xy1.shape == (len(scores), 2) and len(scores) > 50 and seconds > 0
    assert scores.max() < 0.85
    error = np.linalg.norm(xy0 @ A[:, :2].T + A[:, 2] - xy1, axis=1)
    assert np.median(error) < 1.0
    blank = np.full((64, 64, 3), 0.5, np.float32)
    for pair in ((blank, image1), (image0, blank)):
        xy0, xy1, scores, _ = method(*pair)
        assert xy0.shape == xy1.shape == (0, 2) and scores.shape == (0,)


def test_sift_rootsift_and_mutual_options():
    image0, image1, _ = _warped_pair()
    one_way = methods.make_method("opencv-sift:rootsift=true")(image0, image1)
    mutual = methods.make_method("opencv-sift:rootsift=true,mutual=true")(image0, image1)
    pairs = {tuple(p) for p in np.c_[one_way[0], one_way[1]]}
    assert 0 < len(mutual[0]) <= len(one_way[0])
    assert {tuple(p) for p in np.c_[mutual[0], mutual[1]]} <= pairs
    with pytest.raises(ConfigError):
        methods.make_method("asift:features=2000")
    with pytest.raises(ConfigError):
        methods.make_method("asift:ratio=0")
    assert methods.method_label("asift:num_features=2000,ratio=0.85") == "asift_num_features-2000_ratio-0.85"
    assert methods.method_title("asift") == "OpenCV ASIFT"
    assert methods.method_title("slime") == "Slimed Hz+"
    assert methods.method_title("slime:base=aliked-lg,views=off") == "Slimed ALIKED + LightGlue [views=off]"
