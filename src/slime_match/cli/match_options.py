"""The matching options of ``slime match``, ``slime pairs`` and ``slime demo``, and the configuration they
build (a preset or a recorded configuration, then the options given)."""

from __future__ import annotations

import argparse

from ..choices import (
    BUILTIN_BASES,
    DESCRIPTOR_CHOICES,
    DETECTIONS,
    DEVICES,
    LEARNED_BASES,
    MATCH_OPTIONS,
    METHOD_CHOICES,
    ORIENTATION_CHOICES,
    QUARTER_TURN_MODES,
    RANSAC_CHOICES,
    ROTATION_FALLBACK_MODES,
    SHAPE_METHODS,
    TILE_TESTS,
    VIEW_MODES,
)
from ..errors import ConfigError


def add_match_options(parser: argparse.ArgumentParser) -> None:
    """The matching options, in help groups: the everyday ones, the output's loudness, and Slime's and the base
    pipelines' internals (the paper's parameters)."""
    everyday = parser.add_argument_group("matching")
    internals = parser.add_argument_group(
        "Slime and base pipeline internals", "the paper's parameters and their variants; any other by --set")
    everyday.add_argument("--method", default=None, choices=METHOD_CHOICES,
                          help="a preset: Slime and its variants, or a base pipeline alone (the learned ones: "
                               "ALIKED, DISK or XFeat with LightGlue (-lg) or mutual nearest neighbours (-nn)); the "
                               "README's table says what each is. Default auto: slime-aliked when ALIKED's and "
                               "LightGlue's weights are available, else slime (Hz+); the summary says which")
    internals.add_argument("--base", default=None, choices=(*BUILTIN_BASES, *LEARNED_BASES),
                           help="base pipeline run inside Slime (default: the preset's; naming one makes --method auto take slime)")
    everyday.add_argument("--descriptor", default=None, choices=DESCRIPTOR_CHOICES,
                          help="Hz+ / Key.Net descriptor; auto = the best whose weights are available: HardNet, "
                               "HardTFeat (TFeat trained with HardNet's loss), TFeat, then RootSIFT (weight-free; "
                               "not for Key.Net)")
    internals.add_argument("--shape", default=None, choices=SHAPE_METHODS, help="Hz+ affine shape")
    internals.add_argument("--orientation", default=None, choices=ORIENTATION_CHOICES,
                           help="Hz+ patch orientation")
    internals.add_argument("--upright", action="store_true", default=None,
                           help="no orientation estimation (the paper's upright variants)")
    everyday.add_argument("--ransac", default=None, choices=RANSAC_CHOICES, help="post-processing RANSAC (default none)")
    everyday.add_argument("--threshold", type=float, default=None,
                          help="inlier threshold in px of the --ransac post-processing (default 3)")
    everyday.add_argument("--seed", type=int, default=None, help="random seed (RANSAC sampling; default 0)")
    everyday.add_argument("--device", default=None, choices=DEVICES, help="default auto: CUDA when available")
    everyday.add_argument("--weights-dir", default=None, help="folder with model weights (else TORCH_HOME cache)")
    loudness = parser.add_argument_group("output").add_mutually_exclusive_group()
    loudness.add_argument("-v", "--verbose", action="store_true",
                          help="log every step: the stages with their seconds, Slime's block and tile layout, "
                               "the views and the vote (by default only each stage's seconds)")
    loudness.add_argument("-q", "--quiet", action="store_true",
                          help="print nothing but errors: no warnings, no progress bar, no result line")
    everyday.add_argument("--min-side", type=parse_side, default=None, metavar="PX|none",
                          help="upsample (Lanczos3) images whose shorter side is smaller to this many px before "
                               "matching (default auto: 480 for Slime, whose tiles need it; none for a base "
                               "pipeline alone); matches come back in original pixels")
    everyday.add_argument("--max-side", type=parse_side, default=None, metavar="PX|none",
                          help="shrink images whose longer side is larger to this many px before matching "
                               "(default auto: 1200 for Slime, as the paper's images; 1024 for a learned base "
                               "alone; none for the other base pipelines alone); wins over --min-side; matches "
                               "come back in original pixels")
    internals.add_argument("--magnification", type=float, default=None,
                           help="patch size over the detected region (default 6 over HarrisZ+ ellipses, 1 over "
                                "Key.Net frames); smaller patches give a weaker base")
    internals.add_argument("--scales", type=parse_scales, default=None,
                           help="Slime block scales, blocks along the shorter side (default 1,2,3 as the paper; "
                                "1,2 is about 2.5x faster, 1,2,3,4 covers more at about 2.5x the time)")
    internals.add_argument("--detection", default=None, choices=DETECTIONS,
                           help="Slime: how blocks get keypoints: 'merged' (the hz+ default) detects every block "
                                "crop on its own and describes shared keypoints once, 'block' also describes per "
                                "crop (the paper's prototype, slower), 'scale' detects once per block scale "
                                "(fastest, the RootSIFT and Key.Net default; fewer matches in low-texture scenes)")
    internals.add_argument("--tile-test", default=None, choices=TILE_TESTS,
                           help="Slime: which full-resolution tile matches to keep: 'plane' (the default: fits the "
                                "plane's homography over the whole tile pair, more coverage), 'flow' (the paper's: "
                                "near a match of the selected planes)")
    internals.add_argument("--quarter-turns", default=None, choices=QUARTER_TURN_MODES,
                           help="Slime on a base upright by design (ALIKED, DISK, XFeat): 'auto' (default) first "
                                "checks which quarter turn of image 1 the matches agree with most and matches it "
                                "turned when one is the clear winner; 'off': never")
    internals.add_argument("--rotation-fallback", default=None, choices=ROTATION_FALLBACK_MODES,
                           help="Slime on a base upright by design: 'auto' (default) runs Slime again on hz+ "
                                "(orientation estimated, affine-shaped patches) where it finds no match, as "
                                "between images rolled by other than quarter turns, and returns those matches "
                                "where they hold consistent geometry (views.min_support); 'edge-on' also where "
                                "its views were kept while its plain matches show no tilt, as on a plane seen "
                                "nearly edge-on (hz+'s plain stage first; its matches where they also outnumber "
                                "the first run's at its density); 'off': never")
    everyday.add_argument("--views", default=None, choices=VIEW_MODES,
                          help="simulated views for extreme viewpoints (ASIFT tilts 2 then 4 of both images; "
                               "--set views.images=image0|image1 for one; for Slime and a base pipeline alone): "
                               "'auto' (default) only when the plain run finds too little consistent geometry, "
                               "'always', 'off'; summary.json records the views tried")
    internals.add_argument("--set", dest="settings", action="append", default=[], type=parse_setting,
                           metavar="OPTION=VALUE",
                           help="any option by its dotted path, e.g. slime.tiles.t_xi=12 or base.blob.shortlist_k=5 "
                                "(repeatable; every path is in a run's summary.json, under config)")
    internals.add_argument("--config", default=None, metavar="SUMMARY.json",
                           help="start from the configuration a run recorded (its summary.json) instead of the "
                                "method's preset; the options given here change it")


def add_workers_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--workers", dest="slime_workers", type=positive_int, default=None, metavar="N",
                        help="processes for Slime's parallel steps (default: one per CPU this process may use, "
                             "its affinity mask and cgroup quota; 1: no forks); the matches do not depend on it")


def positive_int(text: str) -> int:
    """An integer >= 1 (an argparse type: anything else raises ArgumentTypeError)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected at least 1, got {value}")
    return value


def parse_shard_option(text: str) -> tuple[int, int]:
    """``--shard I/N`` -> (I, N) (an argparse type: anything but 1 <= I <= N raises ArgumentTypeError)."""
    from ..runs.shards import parse_shard

    try:
        return parse_shard(text)
    except ConfigError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def parse_side(text: str) -> int | str:
    """A working-size limit of ``--min-side`` / ``--max-side``: px, ``auto`` or ``none`` (0: off) (an argparse
    type: other text raises ArgumentTypeError; MatchConfig checks the number)."""
    lowered = text.strip().lower()
    if lowered in ("none", "off"):
        return 0
    if lowered == "auto":
        return "auto"
    try:
        return int(lowered)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of px, 'auto' or 'none', got {text!r}") from None


def parse_scales(text: str) -> tuple[int, ...]:
    """Slime block scales from ``"1,2,3"`` (an argparse type: bad text raises ArgumentTypeError)."""
    try:
        scales = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"scales must be comma-separated integers, got {text!r}") from None
    if not scales or min(scales) < 1:
        raise argparse.ArgumentTypeError(f"scales must be positive block counts, got {text!r}")
    return scales


def parse_setting(text: str) -> tuple[str, str]:
    """``OPTION=VALUE`` of ``--set`` (an argparse type: text without '=' raises ArgumentTypeError)."""
    path, sep, value = text.partition("=")
    if not sep or not path.strip():
        raise argparse.ArgumentTypeError(f"expected OPTION=VALUE (e.g. slime.tiles.t_xi=12), got {text!r}")
    return path.strip(), value.strip()


def options_of(args: argparse.Namespace) -> dict:
    keys = ("method", "weights_dir", *(key for key in MATCH_OPTIONS if key != "workers"))
    return {key: getattr(args, key) for key in keys} | {"workers": getattr(args, "slime_workers", None)}


def config_of(args: argparse.Namespace):
    from ..config import MatchConfig, make_config, with_options

    options = options_of(args) | dict(args.settings)
    if args.config:
        config = with_options(MatchConfig.load(args.config), **options)
    else:
        config = make_config(options.pop("method") or "auto", **options)
    if getattr(args, "save_stages", False):
        if config.method != "slime":
            raise ConfigError(f"--save-stages writes Slime's stages, but --method {config.method} runs the "
                              "base pipeline alone")
        config.slime.keep_stages = True
    return config
