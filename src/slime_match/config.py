"""Matcher configuration: one dataclass tree, named presets, and flat keyword overrides."""

from __future__ import annotations

import copy
import dataclasses
import numbers
from dataclasses import dataclass, field
from typing import Any

from .errors import ConfigError
from .io import MIN_IMAGE_SIDE
from .pipelines import BASE_NAMES, PIPELINES, BaseConfig, base_names, unimplemented
from .slime.levels import DETECTIONS
from .slime.pipeline import SlimeConfig
from .slime.refine import TILE_TESTS

METHODS = ("slime", "hz+", "rootsift", "keynet")
RANSAC_CHOICES = ("none", "homography", "fundamental", "magsac-homography", "magsac-fundamental",
                  "poselib-homography", "poselib-fundamental")


@dataclass
class MatchConfig:
    """Everything that defines a matching run.

    Attributes:
        method: "slime" (Slime on top of ``base``), or a base pipeline alone: "hz+" / "rootsift" / "keynet".
        base: the base pipeline options (for Slime: the pipeline run on blocks and tiles; ``base.name`` may
            name a pipeline added with ``slime_match.pipelines.register_pipeline``).
        slime: Slime's parameters (the paper's defaults).
        ransac: post-processing robust estimation: "none", "homography" / "fundamental" (the paper's
            RANSACs), "magsac-*" (OpenCV MAGSAC++) or "poselib-*".
        threshold: post-processing RANSAC inlier threshold in px (the paper tests 5, 3, 2, 1).
        seed: seed of every random choice (RANSAC sampling), for reproducible runs.
        device: "auto" (CUDA when available), "cpu" or "cuda".
        max_side: when set, images whose longest side is larger are shrunk to it (area interpolation)
            before matching, and the matches are mapped back to original-image pixels (None: as given).
    """

    method: str = "slime"
    base: BaseConfig = field(default_factory=BaseConfig)
    slime: SlimeConfig = field(default_factory=SlimeConfig)
    ransac: str = "none"
    threshold: float = 3.0
    seed: int = 0
    device: str = "auto"
    max_side: int | None = None

    def validate(self) -> MatchConfig:
        _choice("method", self.method, METHODS)
        _choice("base", self.base.name, base_names())
        if self.method == "slime" and (missing := unimplemented(PIPELINES[self.base.name], slime=True)):
            raise ConfigError(f"Slime cannot run on the {self.base.name} base pipeline: it does not implement "
                              f"{'; '.join(missing)}")
        _choice("ransac", self.ransac, RANSAC_CHOICES)
        _choice("descriptor", self.base.descriptor, ("auto", "hardnet", "tfeat", "rootsift"))
        _choice("shape", self.base.shape, ("affnet", "baumberg"))
        _choice("orientation", self.base.orientation, ("orinet", "gradient", "upright"))
        _choice("device", self.device, ("auto", "cpu", "cuda"))
        if self.max_side is not None and not (isinstance(self.max_side, numbers.Integral) and self.max_side >= MIN_IMAGE_SIDE):
            raise ConfigError(f"max_side must be an integer of at least {MIN_IMAGE_SIDE} px, got {self.max_side!r}")
        if not self.threshold > 0:
            raise ConfigError(f"threshold must be > 0 px, got {self.threshold}")
        if not (isinstance(self.seed, numbers.Integral) and self.seed >= 0):
            raise ConfigError(f"seed must be a non-negative integer, got {self.seed!r}")
        workers = self.slime.workers
        if workers is not None and not (isinstance(workers, numbers.Integral) and workers >= 1):
            raise ConfigError(f"workers must be an integer of at least 1 (None: one per available CPU), got {workers!r}")
        for name in ("detection", "tile_detection"):
            value = getattr(self.slime, name)
            if value is not None or name == "tile_detection":
                _choice(name, value, DETECTIONS)
            if value == "merged" and PIPELINES[self.base.name].slime_detection != "merged":
                raise ConfigError(f"{name} 'merged' needs the hz+ base (a detector apart from the descriptor); "
                                  f"the {self.base.name} base takes 'scale' or 'block'")
        _choice("tile_test", self.slime.tile_test, TILE_TESTS)
        return self

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


PRESETS: dict[str, dict[str, Any]] = {
    "slime": {"method": "slime", "base": "hz+"},
    "slime-upright": {"method": "slime", "base": "hz+", "upright": True},
    "slime-rootsift": {"method": "slime", "base": "rootsift"},
    # the paper's SM suggests dropping block levels for speed: without the 3-blocks scale, 64 block pairs
    # instead of 400 (see README, Performance, for what it does to speed and quality)
    "slime-fast": {"method": "slime", "base": "hz+", "scales": (1, 2)},
    # a fourth, finer block level for users who value coverage over time: 1600 block pairs instead of 400
    # (see README, Performance)
    "slime-fine": {"method": "slime", "base": "hz+", "scales": (1, 2, 3, 4)},
    "slime-keynet": {"method": "slime", "base": "keynet"},
    "slime-keynet-upright": {"method": "slime", "base": "keynet", "upright": True},
    "hz+": {"method": "hz+"},
    "hz+-upright": {"method": "hz+", "upright": True},
    "rootsift": {"method": "rootsift"},
    "rootsift-upright": {"method": "rootsift", "upright": True},
    "keynet": {"method": "keynet"},
    "keynet-upright": {"method": "keynet", "upright": True},
}


def make_config(preset: str = "slime", **options: Any) -> MatchConfig:
    """Build a validated MatchConfig from a preset name and flat overrides.

    Flat keys are looked up on MatchConfig, then BaseConfig (``descriptor``, ``shape``, ``upright``...),
    then SlimeConfig; ``base="rootsift"`` (or "keynet") selects the base pipeline and ``scales=(1, 2)`` sets
    the Slime block scales, ``same_homography="set"`` F-bar's literal two sets per tile (see
    ``TileConfig``). Unknown keys raise ConfigError, and so do keys the method would not read: Slime's options
    for a base pipeline run alone, a base pipeline's options for another base (``shape`` for RootSIFT), a
    ``threshold`` without a post-processing RANSAC.
    """
    if not isinstance(preset, str) or preset not in PRESETS:
        raise ConfigError(f"unknown method/preset {preset!r}: choose one of {', '.join(PRESETS)}")
    config = MatchConfig()
    settings = {**PRESETS[preset], **{k: v for k, v in options.items() if v is not None}}
    for key, value in settings.items():
        if key == "base" and isinstance(value, str):
            config.base.name = value
        elif key == "scales":
            config.slime.blocks = dataclasses.replace(config.slime.blocks, scales=tuple(value))
        elif key == "same_homography":
            config.slime.tiles = dataclasses.replace(config.slime.tiles, same_homography=value)
        elif key in ("base", "slime") and dataclasses.is_dataclass(value):
            setattr(config, key, copy.deepcopy(value))
        elif _has_field(config, key) and key not in ("base", "slime"):
            setattr(config, key, value)
        elif _has_field(config.base, key):
            setattr(config.base, key, value)
        elif _has_field(config.slime, key):
            setattr(config.slime, key, value)
        else:
            raise ConfigError(f"unknown option {key!r}")
    if config.method in BASE_NAMES:
        config.base.name = config.method
    config.validate()
    _refuse_unread(config, {key: value for key, value in options.items() if value is not None})
    return config


def _refuse_unread(config: MatchConfig, given: dict[str, Any]) -> None:
    """Raise ConfigError for a given option that the configured method would not read (it would be ignored
    silently, and the summary would record a setting that did nothing)."""
    slime = config.method == "slime"
    read = PIPELINES[config.base.name].options | ({"dtm"} if slime else set())  # Slime's global DTM reads dtm
    for key, value in given.items():
        if key == "base" and isinstance(value, str):
            if not slime and value != config.method:
                raise ConfigError(f"base {value!r} is the pipeline inside Slime, but method {config.method!r} runs "
                                  f"the {config.method} pipeline alone (use method 'slime' with base {value!r})")
        elif key == "threshold" and config.ransac == "none":
            raise ConfigError("threshold is the inlier threshold of the post-processing RANSAC, and ransac is "
                              "'none': choose a RANSAC (ransac=..., --ransac) or drop the threshold")
        elif key in ("scales", "same_homography", "slime") or (
                _has_field(config.slime, key) and not _has_field(config, key)):
            if not slime:
                raise ConfigError(f"{key!r} is a Slime option, but method {config.method!r} runs the "
                                  f"{config.method} pipeline alone (use method 'slime' with base {config.method!r})")
        elif _has_field(config.base, key) and key not in read | {"name"}:
            raise ConfigError(f"the {config.base.name} base pipeline does not use {key!r} (it reads "
                              f"{', '.join(sorted(read))})")


def _has_field(obj: Any, name: str) -> bool:
    return any(f.name == name for f in dataclasses.fields(obj))


def _choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ConfigError(f"invalid {name} {value!r}: choose one of {', '.join(choices)}")
