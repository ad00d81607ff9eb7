"""Registry of the matching methods compared by the benchmark (the paper's set, where it runs offline).

A method is named by a spec ``name[:key=value,key=value...]``, e.g. ``"hz+:descriptor=tfeat"``; the
options go to the method's factory (``make_config`` for the package's own presets). :func:`make_method`
returns a callable ``(image0, image1) -> (xy0, xy1, scores, seconds)`` that builds its models lazily on the
first call (so listing methods costs nothing) and times only the matching itself.

Images are (H, W, 3) float32 RGB arrays in [0, 1]; keypoints are (K, 2) float64 pixels in the frame of the
given images (centre of the top-left pixel = (0, 0)); scores are (K,) float64 dissimilarities (lower is
better); seconds is the wall-clock time of the call, models excluded.
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from slime_match.choices import LEARNED_BASES
from slime_match.errors import ConfigError
from slime_match.eval.kornia_peers import KorniaLoFTR, LoFTRConfig
from slime_match.eval.method_base import MethodFn, MethodOutput, dataclass_from, empty_output, to_grey

logger = logging.getLogger("slime_match")

class MatcherMethod:
    """A package preset ("slime", "hz+", "rootsift", ...) run through :class:`slime_match.Matcher`.

    Args:
        preset: a preset of :func:`slime_match.config.make_config`.
        options: flat overrides (``descriptor``, ``shape``, ``orientation``, ``device``...).
    """

    def __init__(self, preset: str, **options: Any) -> None:
        from slime_match.config import make_config

        options.setdefault("ransac", "none")
        self.config = make_config(preset, **options)  # validates option names now
        self._matcher = None
        self.last_decisions: dict[str, Any] = {}  # the adaptive choices of the last pair (summary "decisions")

    def __call__(self, image0: np.ndarray, image1: np.ndarray) -> MethodOutput:
        from slime_match.matcher import Matcher

        if self._matcher is None:  # no feature cache: each pair's seconds count all of its work, in any order
            self._matcher = Matcher(self.config, feature_cache_mb=0)
        start = time.perf_counter()
        result = self._matcher(image0, image1)
        seconds = time.perf_counter() - start
        self.last_decisions = result.summary.get("decisions", {})
        return result.keypoints0, result.keypoints1, result.scores, seconds


@dataclass
class SiftConfig:
    """OpenCV SIFT + Lowe's ratio test (a peer runnable offline).

    Attributes:
        ratio: keep a match when d1 / d2 < ratio.
        num_features: SIFT keypoints per image (0 = all).
        rootsift: match RootSIFT descriptors (L1-normalised, square-rooted) instead of SIFT.
        mutual: also require the match to be the nearest neighbour of its keypoint in image 1.
    """

    ratio: float = 0.8
    num_features: int = 0
    rootsift: bool = False
    mutual: bool = False


@dataclass
class AsiftConfig(SiftConfig):
    """OpenCV ASIFT (``cv2.AffineFeature`` over SIFT: SIFT on simulated affine tilts of each image) with
    RootSIFT descriptors and a one-way (not mutual) ratio test; the fields are those of :class:`SiftConfig`,
    ``num_features`` counting the SIFT keypoints of each simulated view."""

    ratio: float = 0.85
    num_features: int = 2000
    rootsift: bool = True


def _root_sift(desc: np.ndarray) -> np.ndarray:
    """(N, 128) SIFT -> RootSIFT: L1-normalise, square root (unit L2 norm)."""
    desc = desc.astype(np.float32)
    return np.sqrt(desc / np.maximum(desc.sum(1, keepdims=True), 1e-12))


def ratio_matches(
    pts0: np.ndarray, d0: np.ndarray, pts1: np.ndarray, d1: np.ndarray, ratio: float, mutual: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Brute-force L2 2-NN matches of (N0, D) descriptors to (N1, D) ones kept by Lowe's ratio test (and the
    mutual nearest-neighbour check when ``mutual``): xy0 (K, 2), xy1 (K, 2), scores (K,) distance ratios;
    the empty output when either image has too few descriptors (N0 < 1 or N1 < 2)."""
    if len(d0) < 1 or len(d1) < 2:
        return empty_output()
    bf = cv2.BFMatcher(cv2.NORM_L2)
    knn = bf.knnMatch(d0, d1, k=2)
    pairs = np.array([(m[0].queryIdx, m[0].trainIdx, m[0].distance, m[1].distance) for m in knn])
    i0, i1 = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
    scores = pairs[:, 2] / np.maximum(pairs[:, 3], 1e-12)
    keep = scores < ratio
    if mutual:
        back = np.array([m.trainIdx for m in bf.match(d1, d0)], np.int64)  # nearest of each image-1 descriptor
        keep &= back[i1] == i0
    return pts0[i0[keep]], pts1[i1[keep]], scores[keep]


class OpenCVSift:
    """OpenCV SIFT (or RootSIFT) descriptors, brute-force 2-NN, ratio test (optionally mutual); scores are the
    distance ratios."""

    config_class = SiftConfig
    what = "opencv-sift"

    def __init__(self, **options: Any) -> None:
        self.config = dataclass_from(self.config_class, options, self.what)
        if not 0 < self.config.ratio <= 1:
            raise ConfigError(f"{self.what} ratio must be in (0, 1], got {self.config.ratio}")

    def _detector(self) -> Any:
        return cv2.SIFT_create(nfeatures=self.config.num_features)

    def _features(self, detector: Any, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) keypoints and (N, 128) float32 descriptors of an RGB image (N = 0 without features)."""
        grey = np.clip(to_grey(image) * 255 + 0.5, 0, 255).astype(np.uint8)
        keypoints, desc = detector.detectAndCompute(grey, None)
        if desc is None or len(keypoints) == 0:
            return np.zeros((0, 2)), np.zeros((0, 128), np.float32)
        desc = _root_sift(desc) if self.config.rootsift else desc.astype(np.float32)
        return np.array([k.pt for k in keypoints], np.float64), desc

    def __call__(self, image0: np.ndarray, image1: np.ndarray) -> MethodOutput:
        start = time.perf_counter()
        detector = self._detector()
        (p0, d0), (p1, d1) = (self._features(detector, im) for im in (image0, image1))
        xy0, xy1, scores = ratio_matches(p0, d0, p1, d1, self.config.ratio, self.config.mutual)
        return xy0, xy1, scores, time.perf_counter() - start


class OpenCVAsift(OpenCVSift):
    """OpenCV ASIFT (:class:`AsiftConfig`): ``cv2.AffineFeature`` over ``cv2.SIFT_create(num_features)``,
    RootSIFT descriptors, brute-force 2-NN, ratio test 0.85 (one-way by default); scores are the distance
    ratios."""

    config_class = AsiftConfig
    what = "asift"

    def _detector(self) -> Any:
        return cv2.AffineFeature_create(cv2.SIFT_create(nfeatures=self.config.num_features))


def _preset(preset: str, **fixed: Any) -> Callable[..., MethodFn]:
    return lambda **options: MatcherMethod(preset, **{**fixed, **options})


LEARNED_TITLES = {"aliked-lg": "ALIKED + LightGlue", "aliked-nn": "ALIKED + mutual NN", "disk-lg": "DISK + LightGlue",
                  "disk-nn": "DISK + mutual NN", "xfeat-lg": "XFeat + LighterGlue", "xfeat-nn": "XFeat + mutual NN"}

# name -> (the paper's label, factory(**options) -> MethodFn)
REGISTRY: dict[str, tuple[str, Callable[..., MethodFn]]] = {
    "slime": ("Slimed Hz+", _preset("slime")),
    "slime-upright": ("Slimed Hz+ (upright)", _preset("slime-upright")),
    "slime-rootsift": ("Slimed RootSIFT", _preset("slime-rootsift")),
    "slime-fast": ("Slimed Hz+ (block scales 1, 2)", _preset("slime-fast")),
    "slime-fine": ("Slimed Hz+ (block scales 1-4)", _preset("slime-fine")),
    "hz+": ("Hz+", _preset("hz+")),
    "hz+-upright": ("Hz+ (upright)", _preset("hz+-upright")),
    "rootsift": ("RootSIFT", _preset("rootsift")),
    "rootsift-upright": ("RootSIFT (upright)", _preset("rootsift-upright")),
    "keynet": ("Key.Net", _preset("keynet")),
    "keynet-upright": ("Key.Net (upright)", _preset("keynet-upright")),
    "slime-keynet": ("Slimed Key.Net", _preset("slime-keynet")),
    "slime-keynet-upright": ("Slimed Key.Net (upright)", _preset("slime-keynet-upright")),
    "slime-aliked": ("Slimed ALIKED + LightGlue", _preset("slime-aliked")),
    "slime-aliked-disk": ("Slimed ALIKED + LightGlue, DISK pooled", _preset("slime-aliked-disk")),
    "opencv-sift": ("OpenCV SIFT", lambda **o: OpenCVSift(**o)),
    "asift": ("OpenCV ASIFT", lambda **o: OpenCVAsift(**o)),
    "loftr": ("LoFTR", lambda **o: KorniaLoFTR(**o)),
    **{name: (LEARNED_TITLES[name], _preset(name)) for name in LEARNED_BASES},
}



def _value(text: str) -> Any:
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    if low == "none":
        return None
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return text


def parse_method_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``"hz+:descriptor=tfeat,shape=baumberg"`` -> ("hz+", {"descriptor": "tfeat", "shape": "baumberg"}).

    Values are parsed as bool / None / int / float when they look like one, else kept as strings.

    Raises:
        ConfigError: unknown method name or a malformed option.
    """
    name, _, rest = spec.strip().partition(":")
    if name not in REGISTRY:
        raise ConfigError(f"unknown method {name!r}; choose one of {', '.join(REGISTRY)}")
    options = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"method option {item!r} in {spec!r} is not 'key=value'")
        options[key.strip()] = _value(value.strip())
    return name, options


def method_label(spec: str) -> str:
    """File-system safe, unique name of a method spec (used for the prediction cache folders)."""
    name, options = parse_method_spec(spec)
    text = name + "".join(f"_{k}-{v}" for k, v in sorted(options.items()))
    return re.sub(r"[^A-Za-z0-9+._-]", "_", text)


def method_title(spec: str) -> str:
    """Human-readable name of a spec: the paper's label plus any options ("Slimed <base>" for Slime with a
    ``base`` option)."""
    name, options = parse_method_spec(spec)
    title = REGISTRY[name][0]
    if name == "slime" and options.get("base") in REGISTRY:
        options = dict(options)
        title = f"Slimed {REGISTRY[options.pop('base')][0]}"
    return title + (f" [{', '.join(f'{k}={v}' for k, v in options.items())}]" if options else "")


def make_method(spec: str, **defaults: Any) -> MethodFn:
    """Build the callable of a method spec; ``defaults`` (e.g. ``device``, ``seed``) apply unless the spec
    sets them, and only where the method accepts them.

    Raises:
        ConfigError: unknown method or option.
    """
    name, options = parse_method_spec(spec)
    factory = REGISTRY[name][1]
    accepted = _accepted(name)
    merged = {**{k: v for k, v in defaults.items() if k in accepted}, **options}
    return factory(**merged)


def _accepted(name: str) -> set[str]:
    if name == "opencv-sift":
        return set(SiftConfig.__dataclass_fields__)
    if name == "asift":
        return set(AsiftConfig.__dataclass_fields__)
    if name == "loftr":
        return set(LoFTRConfig.__dataclass_fields__)
    return {"device", "seed"}
