"""Base pipelines registered by name: a user's pipeline through make_config and Matcher, and what is refused."""

import math

import cv2
import numpy as np
import pytest
import torch

from slime_match.config import make_config
from slime_match.errors import ConfigError
from slime_match.matcher import Matcher
from slime_match.pipelines import (
    BASE_NAMES,
    PIPELINES,
    BaseConfig,
    BasePipeline,
    base_names,
    make_base_pipeline,
    register_pipeline,
)
from slime_match.pipelines.hzplus import HzPlusPipeline
from slime_match.pipelines.rootsift import RootSiftPipeline
from slime_match.types import Features, Matches


def _grey(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor((np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8), cv2.COLOR_RGB2GRAY)


def _sift_features(grey: np.ndarray, keypoints: list) -> Features:
    """SIFT descriptors of OpenCV keypoints, with their LAFs (N, 2, 3) and upright shape frames."""
    keypoints, descriptors = cv2.SIFT_create().compute(grey, keypoints)
    scale = np.array([k.size / 2 for k in keypoints], np.float32)
    angle = np.radians([k.angle for k in keypoints]).astype(np.float32)
    xy = np.array([k.pt for k in keypoints], np.float32)
    rotation = np.stack([np.stack([np.cos(angle), -np.sin(angle)], 1), np.stack([np.sin(angle), np.cos(angle)], 1)], 1)
    laf = np.concatenate([rotation * scale[:, None, None], xy[:, :, None]], 2)
    shape = laf.copy()
    shape[:, :, :2] = np.eye(2, dtype=np.float32) * scale[:, None, None]
    return Features(torch.from_numpy(laf), torch.from_numpy(descriptors), torch.ones(len(laf)), torch.from_numpy(shape))


class MinimalSift(BasePipeline):
    """A user's pipeline with the required part only: OpenCV SIFT features and mutual nearest neighbours."""

    name = "minimal-sift"

    def extract(self, image: np.ndarray) -> Features:
        grey = _grey(image)
        return _sift_features(grey, cv2.SIFT_create(nfeatures=2000).detect(grey, None))

    def match(self, features0, features1, size0, size1, candidate_filter=None) -> Matches:
        if len(features0) == 0 or len(features1) == 0:
            return Matches.empty()
        distance = torch.cdist(features0.descriptors, features1.descriptors)
        nn01, nn10 = distance.argmin(1), distance.argmin(0)
        idx0 = torch.nonzero(nn10[nn01] == torch.arange(len(nn01))).flatten()
        matches = Matches(idx0.numpy(), nn01[idx0].numpy(), distance[idx0, nn01[idx0]].numpy())
        if candidate_filter is not None and len(matches):
            xy0, xy1 = (f.xy.numpy().astype(np.float64) for f in (features0, features1))
            matches = matches.subset(candidate_filter(xy0[matches.idx0], xy1[matches.idx1]))
        return matches


class FixedSift(MinimalSift):
    """MinimalSift with the one hook that Slime needs and cannot default: describe_fixed."""

    name = "fixed-sift"

    def describe_fixed(self, context: np.ndarray, features: Features, angle: float) -> Features:
        keypoints = [cv2.KeyPoint(float(x), float(y), float(2 * s), math.degrees(angle) % 360)
                     for (x, y), s in zip(features.xy.numpy(), features.scale.numpy())]
        return _sift_features(_grey(context), keypoints)


class CountingRootSift(RootSiftPipeline):
    """RootSIFT that counts its detections: a user's pipeline on top of a built-in one."""

    name = "counting-rootsift"
    detections = 0

    def detect(self, context):
        type(self).detections += 1
        return super().detect(context)


@pytest.fixture
def register():
    """register_pipeline, with every name it registered removed after the test."""
    names = []

    def register(name, cls, **options):
        register_pipeline(name, cls, **options)
        names.append(name)

    yield register
    for name in names:
        PIPELINES.pop(name, None)


@pytest.fixture(scope="module")
def rgb_pair(pair):
    """(H, W, 3) float images of the real stereo pair (rectified: matches share their row)."""
    return [cv2.imread(path)[:, :, ::-1].astype(np.float32) / 255 for path in pair]


def test_built_in_names_come_from_the_registry():
    assert BASE_NAMES == base_names() == ("hz+", "rootsift", "keynet", "aliked-lg", "aliked-nn", "disk-lg", "disk-nn",
                                          "xfeat-lg", "xfeat-nn")
    assert PIPELINES["hz+"] is HzPlusPipeline and PIPELINES["rootsift"] is RootSiftPipeline


def test_a_pipeline_on_top_of_rootsift_runs_in_slime_as_rootsift_does(register, rgb_pair):
    register("counting", CountingRootSift)
    assert "counting" in base_names() and "counting" not in BASE_NAMES
    matcher = Matcher(make_config("slime", base="counting", workers=1, device="cpu"))
    assert isinstance(matcher.pipeline, CountingRootSift)
    ours = matcher(*rgb_pair)
    reference = Matcher(make_config("slime-rootsift", workers=1, device="cpu"))(*rgb_pair)
    assert CountingRootSift.detections > 0 and len(ours) > 100
    for key in ("keypoints0", "keypoints1", "scores"):
        assert np.array_equal(getattr(ours, key), getattr(reference, key)), key
    with pytest.raises(ConfigError, match="counting base pipeline does not use 'descriptor'"):
        make_config("slime", base="counting", descriptor="tfeat")  # the options it inherits from RootSIFT


def test_a_minimal_pipeline_runs_alone_and_in_slime_on_the_hooks_defaults(register, rgb_pair):
    register("fixed-sift", FixedSift)
    pipeline = make_base_pipeline(BaseConfig(name="fixed-sift"))
    context = pipeline.prepare(rgb_pair[0])
    assert context is rgb_pair[0] and pipeline.describe_batch() is None and not pipeline.own_frames_upright()
    features = pipeline.detect(context)
    assert torch.equal(pipeline.detect_regions(context).laf, features.laf)
    assert len(pipeline.match(features, pipeline.extract(rgb_pair[1]), (250, 370), (250, 370))) > 100
    result = Matcher(make_config("slime", base="fixed-sift", workers=1, device="cpu"))(*rgb_pair)
    assert len(result) > 100 and result.summary["counts"]["tile_matches"] > 0
    dy = np.abs(result.keypoints0[:, 1] - result.keypoints1[:, 1])
    assert np.median(dy) < 1.0 and np.mean(dy < 3) > 0.9, (np.median(dy), np.mean(dy < 3))


def test_slime_refuses_a_base_without_describe_fixed(register):
    register("minimal-sift", MinimalSift)
    assert isinstance(make_base_pipeline(BaseConfig(name="minimal-sift")), MinimalSift)
    with pytest.raises(ConfigError, match=r"minimal-sift base pipeline: it does not implement describe_fixed"):
        make_config("slime", base="minimal-sift")


def test_duplicate_names_are_refused_unless_replacing(register, monkeypatch):
    with pytest.raises(ConfigError, match="non-empty string"):
        register_pipeline("", FixedSift)
    register("fixed-sift", FixedSift)
    with pytest.raises(ConfigError, match="already registered as 'fixed-sift' .FixedSift."):
        register_pipeline("fixed-sift", MinimalSift)
    with pytest.raises(ConfigError, match="already registered as 'rootsift'"):
        register_pipeline("rootsift", CountingRootSift)
    monkeypatch.setitem(PIPELINES, "rootsift", RootSiftPipeline)  # restored after the test
    register_pipeline("rootsift", CountingRootSift, replace=True)
    assert isinstance(make_base_pipeline(BaseConfig(name="rootsift")), CountingRootSift)


class OnlyMatch(BasePipeline):
    def match(self, features0, features1, size0, size1, candidate_filter=None):
        return Matches.empty()


class OnlyExtract(BasePipeline):
    def extract(self, image):
        return MinimalSift.extract(self, image)


class PrepareWithoutDetect(MinimalSift):
    def prepare(self, image):
        return _grey(image)


class MergedWithoutKeypoints(FixedSift):
    slime_detection = "merged"


class UnknownOption(FixedSift):
    options = frozenset({"upright", "sigma"})


@pytest.mark.parametrize(("cls", "error", "message"), [
    (OnlyMatch, TypeError, r"OnlyMatch must implement extract\(image\) \(or prepare\(image\) and detect"),
    (OnlyExtract, TypeError, r"OnlyExtract must implement match\(features0, features1"),
    (PrepareWithoutDetect, TypeError, r"must implement detect\(context\), which reads what its prepare"),
    (MergedWithoutKeypoints, TypeError, r"must implement detect_keypoints\(image, device=None\); describe_keyp"),
    (UnknownOption, TypeError, "options names sigma, which BaseConfig does not have"),
    (Matches, TypeError, "is not a subclass of BasePipeline"),
    (FixedSift(BaseConfig(), torch.device("cpu")), TypeError, "is not a subclass of BasePipeline"),
])
def test_incomplete_classes_are_refused(cls, error, message):
    with pytest.raises(error, match=message):
        register_pipeline("incomplete", cls)
    assert "incomplete" not in PIPELINES


def test_the_interface_alone_names_what_to_implement(rgb_pair):
    pipeline = BasePipeline(BaseConfig(), torch.device("cpu"))
    with pytest.raises(NotImplementedError, match=r"neither extract\(image\) nor prepare\(image\) and detect"):
        pipeline.extract(rgb_pair[0])
    with pytest.raises(NotImplementedError, match="does not implement match"):
        pipeline.match(None, None, (1, 1), (1, 1))
    with pytest.raises(ConfigError, match="detect_keypoints and describe_keypoints"):
        RootSiftPipeline(BaseConfig(name="rootsift"), torch.device("cpu")).detect_keypoints(rgb_pair[0])
    with pytest.raises(ConfigError, match="invalid base 'nothing'"):
        make_config("slime", base="nothing")
