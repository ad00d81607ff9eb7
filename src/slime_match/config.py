"""Matcher configuration: one dataclass tree, named presets, and overrides by flat or dotted option name.

Every option lives once, in the dataclass of the code that reads it (``MatchConfig`` here, ``BaseConfig`` of the
base pipelines, ``SlimeConfig`` and its stages' configs), with its default and its choices; each checks its
values in ``__post_init__``. Any option is reachable by its dotted path (``slime.tiles.t_xi``); the top-level
fields of the three main dataclasses also by their flat name (``descriptor``, ``workers``), and two nested
ones by a short name (:data:`SHORT_NAMES`).
"""

from __future__ import annotations

import copy
import dataclasses
import json
import numbers
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ._runtime.options import check_choice, check_integer, config_from_dict, set_option
from .auto_method import AUTO_PRESETS, resolve_auto
from .choices import DEVICES, LEARNED_BASES, QUARTER_TURN_MODES, RANSAC_CHOICES, ROTATION_FALLBACK_MODES
from .errors import ConfigError
from .io import MIN_IMAGE_SIDE
from .pipelines import PIPELINES, BaseConfig, base_names, unimplemented
from .slime.pipeline import SlimeConfig
from .views import ViewConfig

# working-size limits (px) of "auto": Slime upsamples images whose shorter side is under 480 px (its 256 px
# tiles and the Sec. 3.6 vote need several tiles per image) and shrinks those whose longer side is over 1200
# px (the paper's image sizes; tiles and time grow with the image); a handcrafted base pipeline alone runs at
# full size; a learned base alone shrinks them to 1024 px on the longer side (where its networks were trained and
# measured)
AUTO_SIDES: dict[str, tuple[int | None, int | None]] = {"slime": (480, 1200),
                                                        **{name: (None, 1024) for name in LEARNED_BASES}}
SHORT_NAMES = {"scales": "slime.blocks.scales", "same_homography": "slime.tiles.same_homography",
               "views": "views.mode"}


def methods() -> tuple[str, ...]:
    """What ``MatchConfig.method`` may be: Slime, or a registered base pipeline alone."""
    return ("slime", *base_names())


@dataclass
class MatchConfig:
    """Everything that defines a matching run.

    Attributes:
        method: "slime" (Slime on top of ``base``), or a base pipeline alone: "hz+" / "rootsift" / "keynet", a
            learned one ("aliked-lg", "disk-nn"...: ``choices.LEARNED_BASES``), or one added with
            ``slime_match.pipelines.register_pipeline``.
        base: the base pipeline options (for Slime: the pipeline run on blocks and tiles; ``base.name`` may
            name a pipeline added with ``slime_match.pipelines.register_pipeline``).
        slime: Slime's parameters (the paper's defaults).
        ransac: post-processing robust estimation: "none", "homography" / "fundamental" (the paper's
            RANSACs), "magsac-*" (OpenCV MAGSAC++) or "poselib-*" (``RANSAC_CHOICES``).
        threshold: post-processing RANSAC inlier threshold in px (the paper tests 5, 3, 2, 1).
        seed: seed of every random choice (RANSAC sampling), for reproducible runs.
        device: "auto" (CUDA when available), "cpu" or "cuda".
        min_side: images whose shorter side is smaller are upsampled (Lanczos3) so that it reaches this many px
            before matching; "auto": the method's default (:data:`AUTO_SIDES`: 480 for Slime, off for a base
            pipeline alone); 0, "none" or None: off (``make_config`` skips None values: pass 0 there).
        max_side: images whose longer side is larger are shrunk to this many px (area interpolation) before
            matching; it wins over ``min_side`` for an elongated image; "auto": the method's default (1200 for
            Slime, 1024 for a learned base alone, off for the other base pipelines alone); 0, "none" or None:
            off. The two images share one factor when one meets both images' limits, else each gets its own
            (``resize.pair_factors``); the matches are mapped back to original-image pixels.
        views: simulated views for extreme viewpoints (ASIFT tilts of image 0, image 1 or both,
            :class:`~slime_match.views.ViewConfig`): "auto" (default) only when the plain run finds too little
            consistent geometry, "always", "off"; for Slime and for a base pipeline alone.
        quarter_turns: "auto" (default): Slime on a base whose features are upright by design (ALIKED n16/n32,
            DISK, XFeat) first checks which quarter turn of image 1 its matches agree with most, and matches
            image 1 turned when one is the clear winner (:mod:`slime_match.quarter_turns`); "off": never.
        rotation_fallback: "auto" (default): where Slime on a base upright by design finds no match (images
            rolled against each other by other than quarter turns), Slime runs again on Hz+, which estimates
            orientations on affine-shaped patches, and its matches are returned where its F^theta holds
            ``views.min_support`` matches; "edge-on": also where the base's views were kept while its plain
            matches show no tilt (a plane seen nearly edge-on: Hz+'s plain stage first, the rest only where it
            measures one), Hz+'s matches returned where they also outnumber the first run's at its density
            (:mod:`slime_match.rotation_fallback`); "off": never.
        auto_choice: what the "auto" method took and what it passed over (:mod:`slime_match.auto_method`);
            empty when a preset was named.
    """

    method: str = "slime"
    base: BaseConfig = field(default_factory=BaseConfig)
    slime: SlimeConfig = field(default_factory=SlimeConfig)
    ransac: str = "none"
    threshold: float = 3.0
    seed: int = 0
    device: str = "auto"
    min_side: int | str | None = "auto"
    max_side: int | str | None = "auto"
    views: ViewConfig = field(default_factory=ViewConfig)
    quarter_turns: str = "auto"
    rotation_fallback: str = "auto"
    auto_choice: str = ""

    def __post_init__(self) -> None:
        self._check_fields()

    def _check_fields(self) -> None:
        check_choice("method", self.method, methods())
        check_choice("ransac", self.ransac, RANSAC_CHOICES)
        check_choice("device", self.device, DEVICES)
        check_choice("quarter_turns", self.quarter_turns, QUARTER_TURN_MODES)
        check_choice("rotation_fallback", self.rotation_fallback, ROTATION_FALLBACK_MODES)
        for name in ("min_side", "max_side"):
            value = getattr(self, name)
            if not (value in ("auto", None) or (isinstance(value, numbers.Integral) and not isinstance(value, bool)
                                                and (value == 0 or value >= MIN_IMAGE_SIDE))):
                raise ConfigError(f"{name} must be an integer of at least {MIN_IMAGE_SIDE} px, 0 or None (off), or "
                                  f"'auto' (the method's default), got {value!r}")
        if not (isinstance(self.threshold, numbers.Real) and self.threshold > 0):
            raise ConfigError(f"threshold must be > 0 px, got {self.threshold!r}")
        check_integer("seed", self.seed, 0)

    def side_limits(self) -> tuple[int | None, int | None]:
        """(min_side, max_side) in px that the matcher applies, "auto" resolved for the method (None: off)."""
        auto = AUTO_SIDES.get(self.method, (None, None))
        return tuple(default if value == "auto" else (int(value) if value else None)  # type: ignore[return-value]
                     for value, default in zip((self.min_side, self.max_side), auto, strict=True))

    def validate(self) -> MatchConfig:
        """Check every field again (they may have been set after construction) and what ties them together:
        the base pipeline is registered and can run inside Slime, "merged" detection has a base that
        detects apart from describing, an explicit ``min_side`` is not above ``max_side``."""
        self._check_fields()
        low, high = self.side_limits()
        if low and high and low > high and self.min_side != "auto":  # an auto min_side gives way to max_side
            raise ConfigError(f"min_side {low} px is larger than max_side {high} px"
                              f"{' (auto for ' + self.method + ')' if self.max_side == 'auto' else ''}: "
                              "an image cannot meet both; raise max_side or turn it off (none)")
        self.base.validate()
        self.slime.validate()
        self.views.validate()
        check_choice("base", self.base.name, base_names())
        if self.method != "slime" and self.base.name != self.method:
            raise ConfigError(f"method {self.method!r} runs the {self.method} pipeline alone, but base.name is "
                              f"{self.base.name!r}")
        if self.method == "slime" and (missing := unimplemented(PIPELINES[self.base.name], slime=True)):
            raise ConfigError(f"Slime cannot run on the {self.base.name} base pipeline: it does not implement "
                              f"{'; '.join(missing)}")
        if self.slime.pool is not None:
            self._check_pool()
        for name in ("detection", "tile_detection"):
            if getattr(self.slime, name) == "merged" and PIPELINES[self.base.name].slime_detection != "merged":
                raise ConfigError(f"{name} 'merged' needs the hz+ base (a detector apart from the descriptor); "
                                  f"the {self.base.name} base takes 'scale' or 'block'")
        return self

    def _check_pool(self) -> None:
        """The second base of ``slime.pool``: Slime only, a registered pipeline that can run inside Slime,
        not the base itself."""
        pool = self.slime.pool
        if self.method != "slime":
            raise ConfigError(f"pool is a Slime option, but method {self.method!r} runs the {self.method} "
                              f"pipeline alone (use method 'slime' with base {self.method!r})")
        check_choice("pool", pool, base_names())
        if pool == self.base.name:
            raise ConfigError(f"pool {pool!r} is the base itself: pool a different base pipeline, or none")
        if missing := unimplemented(PIPELINES[pool], slime=True):
            raise ConfigError(f"Slime cannot pool the {pool} base pipeline: it does not implement {'; '.join(missing)}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MatchConfig:
        """The configuration of ``to_dict`` (or of a result's ``summary.json``: its ``config``), validated."""
        if not isinstance(data, dict):
            raise ConfigError(f"a configuration is a JSON object, got {type(data).__name__}")
        return config_from_dict(cls, data.get("config", data)).validate()

    @classmethod
    def load(cls, path: str | Path) -> MatchConfig:
        """The configuration recorded in a JSON file: a run's ``summary.json``, or ``to_dict()`` saved."""
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, json.JSONDecodeError) as error:
            raise ConfigError(f"cannot read a configuration from {path}: {error}") from None
        return cls.from_dict(data)


PRESETS: dict[str, dict[str, Any]] = {
    "slime": {"method": "slime", "base": "hz+"},
    "slime-upright": {"method": "slime", "base": "hz+", "upright": True},
    "slime-rootsift": {"method": "slime", "base": "rootsift"},
    # the paper's SM suggests dropping block levels for speed: without the 3-blocks scale, 64 block pairs
    # instead of 400 (docs/performance.md, "Speed against quality", for what it does to speed and quality)
    "slime-fast": {"method": "slime", "base": "hz+", "scales": (1, 2)},
    # a fourth, finer block level for users who value coverage over time: 1600 block pairs instead of 400
    # (docs/performance.md, "Speed against quality")
    "slime-fine": {"method": "slime", "base": "hz+", "scales": (1, 2, 3, 4)},
    "slime-keynet": {"method": "slime", "base": "keynet"},
    "slime-keynet-upright": {"method": "slime", "base": "keynet", "upright": True},
    # Slime on ALIKED + LightGlue: the 3072 strongest ALIKED score maxima per block scale, LightGlue on each pair
    # of block scales' whole images (the learned base's default block matching): WxBS mAA 0.57 over three seeds,
    # as with 8000 keypoints, at 1.8x instead of 2.6x the time of `slime` on graf (docs/evaluation.md)
    "slime-aliked": {"method": "slime", "base": "aliked-lg", "aliked_threshold": 0.0, "max_keypoints": 3072},
    # the same with DISK's block planes pooled in (the same keypoints per block scale): more wide-baseline
    # block pairs found (WxBS mAA 0.62 over three seeds against 0.57) at 1.4-2x the time (docs/evaluation.md)
    "slime-aliked-disk": {"method": "slime", "base": "aliked-lg", "aliked_threshold": 0.0, "max_keypoints": 3072,
                          "pool": "disk-lg"},
    "hz+": {"method": "hz+"},
    "hz+-upright": {"method": "hz+", "upright": True},
    "rootsift": {"method": "rootsift"},
    "rootsift-upright": {"method": "rootsift", "upright": True},
    "keynet": {"method": "keynet"},
    "keynet-upright": {"method": "keynet", "upright": True},
    # the learned bases alone, with LightGlue's usual 4096 keypoints (working size: AUTO_SIDES)
    **{name: {"method": name, "max_keypoints": 4096} for name in LEARNED_BASES},
}


def option_path(name: str) -> str:
    """The dotted path of an option given by its flat name (``descriptor`` -> ``base.descriptor``), its short
    name (:data:`SHORT_NAMES`) or its path; ConfigError for a name that is none of these."""
    if "." in name:
        return name
    if name in SHORT_NAMES:
        return SHORT_NAMES[name]
    for prefix, cls in (("", MatchConfig), ("base.", BaseConfig), ("slime.", SlimeConfig)):
        if name in {f.name for f in dataclasses.fields(cls)} - {"base", "slime"}:
            return prefix + name
    raise ConfigError(f"unknown option {name!r}: a field of MatchConfig, BaseConfig or SlimeConfig, one of "
                      f"{', '.join(SHORT_NAMES)}, or a dotted path such as slime.tiles.t_xi")


def make_config(preset: str = "auto", **options: Any) -> MatchConfig:
    """Build a validated MatchConfig from a preset name (or a registered base pipeline's name) and options.

    "auto" (the default) is the best preset whose weights are available (:mod:`slime_match.auto_method`:
    ``slime-aliked``, else ``slime``); ``auto_choice`` records what it took and passed over.

    Options are given by flat name (``descriptor="tfeat"``, ``workers=1``), short name (``scales=(1, 2)``,
    ``same_homography="set"``) or dotted path (``**{"slime.tiles.t_xi": 12}``); a string value is read by the
    option's type (as ``--set`` does). ``base="rootsift"`` selects the base pipeline; ``base=`` or ``slime=``
    given a dataclass replaces that whole part. None values are skipped. Unknown options raise ConfigError,
    and so do options the method would not read: Slime's options for a base pipeline run alone, a base
    pipeline's options for another base (``shape`` for RootSIFT), a ``threshold`` without a post-processing
    RANSAC, a ``views.*`` option with the views off, the criterion of "auto" views under "always", or the other
    kind of method's criterion (``views.min_support`` and ``views.min_tilt`` are Slime's, ``views.min_inliers``
    a base pipeline's).
    """
    if not isinstance(preset, str) or (preset not in PRESETS and preset != "auto" and preset not in base_names()):
        raise ConfigError(f"unknown method/preset {preset!r}: choose auto or one of {', '.join(PRESETS)}")
    note = ""
    if preset == "auto":
        preset, note = resolve_auto(_options_of_another_base(options, PIPELINES[PRESETS[AUTO_PRESETS[0]]["base"]]
                                                             .options))
    config = with_options(_applied(MatchConfig(), PRESETS.get(preset, {"method": preset})), **options)
    if note:
        config.auto_choice = note
    return config


def _options_of_another_base(options: dict[str, Any], read: frozenset[str]) -> list[str]:
    """The given options (None values skipped) that name the base or set a base option outside ``read``."""
    found = []
    for key, value in options.items():
        if value is None:
            continue
        group, _, rest = ("base.name" if key == "base" else option_path(key)).partition(".")
        if group == "base" and (key == "base" or rest.split(".")[0] not in read):
            found.append(key)
    return found


def with_options(config: MatchConfig, **options: Any) -> MatchConfig:
    """A validated copy of ``config`` with ``options`` set (named as for :func:`make_config`)."""
    given = {key: value for key, value in options.items() if value is not None}
    config = _applied(config, given)
    config.validate()
    _refuse_unread(config, given)
    return config


def _applied(config: MatchConfig, settings: dict[str, Any]) -> MatchConfig:
    """``config`` with ``settings`` set; a method that runs a base pipeline alone names that pipeline."""
    settings = dict(settings)
    method = settings.pop("method", config.method)
    for key, value in settings.items():
        if key in ("base", "slime") and dataclasses.is_dataclass(value):
            config = dataclasses.replace(config, **{key: copy.deepcopy(value)})
        else:
            config = set_option(config, option_path("base.name" if key == "base" else key), value)
    config = dataclasses.replace(config, method=method)
    return config if method == "slime" else set_option(config, "base.name", method)


def _refuse_unread(config: MatchConfig, given: dict[str, Any]) -> None:
    """Raise ConfigError for a given option that the configured method would not read (it would be ignored
    silently, and the summary would record a setting that did nothing)."""
    slime = config.method == "slime"
    read = PIPELINES[config.base.name].options | ({"dtm"} if slime else set())  # Slime's global DTM reads dtm
    if slime and config.slime.pool is not None:  # the pooled base runs with the base's options
        read |= PIPELINES[config.slime.pool].options
    for key, value in given.items():
        if key == "base" and not dataclasses.is_dataclass(value):
            if not slime and value != config.method:
                raise ConfigError(f"base {value!r} is the pipeline inside Slime, but method {config.method!r} runs "
                                  f"the {config.method} pipeline alone (use method 'slime' with base {value!r})")
            continue
        path = key if key in ("base", "slime") else option_path(key)
        group, _, rest = path.partition(".")
        if path == "threshold" and config.ransac == "none":
            raise ConfigError("threshold is the inlier threshold of the post-processing RANSAC, and ransac is "
                              "'none': choose a RANSAC (ransac=..., --ransac) or drop the threshold")
        if (group == "slime" or path in ("quarter_turns", "rotation_fallback")) and not slime:
            raise ConfigError(f"{key!r} is a Slime option, but method {config.method!r} runs the "
                              f"{config.method} pipeline alone (use method 'slime' with base {config.method!r})")
        if group == "base" and rest and rest.split(".")[0] not in read | {"name"}:
            who, they = ((f"the {config.base.name} and {config.slime.pool} base pipelines do", "they read")
                         if slime and config.slime.pool is not None else
                         (f"the {config.base.name} base pipeline does", "it reads"))
            raise ConfigError(f"{who} not use {key!r} ({they} {', '.join(sorted(read))})")
        if group == "views" and rest != "mode":
            _refuse_unread_view_option(config, key, rest)


# the view options read only in mode "auto", by Slime or by a base pipeline alone: what each criterion counts
VIEW_CRITERIA = {"min_support": ("slime", "matches of F^theta, the planes Slime's epipolar vote keeps"),
                 "min_tilt": ("slime", "the tilt of F^theta's matches' affine map"),
                 "max_tilt": ("slime", "the tilt of F^theta's matches' affine map"),
                 "steep_tilts": ("slime", "the tilt of F^theta's matches' affine map"),
                 "min_inliers": ("base", "matches consistent with one fundamental matrix")}


def _refuse_unread_view_option(config: MatchConfig, key: str, name: str) -> None:
    """Raise ConfigError for a ``views.*`` option (other than the mode) that the run would not read: any with
    the views off, a criterion of "auto" under "always", the other kind of method's criterion, or the views'
    probe where Slime does not match whole levels."""
    mode = config.views.mode
    if mode == "off":
        raise ConfigError(f"{key!r} sets the simulated views, and they are off: drop it or turn the views on "
                          "(views=auto|always, --views)")
    if name in ("min_probe", "screen_keypoints"):
        matching = config.slime.block_matching or PIPELINES[config.base.name].slime_block_matching
        if config.method != "slime" or matching != "levels":
            runs = (f"Slime on {config.base.name} matches block pairs one by one (block_matching 'pairs')"
                    if config.method == "slime" else f"method {config.method!r} runs the {config.method} pipeline alone")
            raise ConfigError(f"{key!r} sets the probe Slime runs on each view when it matches whole levels "
                              f"(block_matching 'levels'), and {runs}: drop it or set block_matching=levels")
        return
    if name not in VIEW_CRITERIA:
        return
    reader, counted = VIEW_CRITERIA[name]
    other = next(n for n, (kind, _) in VIEW_CRITERIA.items() if kind != reader)
    if (reader == "slime") != (config.method == "slime"):
        runs = "Slime" if config.method == "slime" else f"the {config.method} pipeline alone"
        raise ConfigError(f"{key!r} is the threshold of {'Slime' if reader == 'slime' else 'a base pipeline alone'} "
                          f"for adding views ({counted}), but method {config.method!r} runs {runs}: set views.{other} "
                          "instead")
    if mode != "auto":
        raise ConfigError(f"{key!r} decides when views mode 'auto' adds views, and the mode is {mode!r}, which "
                          "adds them all: drop it or use views=auto")
