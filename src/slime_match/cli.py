"""Command line: ``slime match``, ``slime viz`` (and ``slime bench`` from slime_match.eval)."""

from __future__ import annotations

import argparse
import logging
import os
import shutil
import sys
import tempfile
from pathlib import Path

from .errors import SlimeMatchError

logger = logging.getLogger("slime_match")


def _add_match_options(parser: argparse.ArgumentParser) -> None:
    from .config import RANSAC_CHOICES

    parser.add_argument("--method", default="slime", choices=["slime", "hz+", "rootsift"],
                        help="Slime (default) or a base pipeline alone")
    parser.add_argument("--base", default=None, choices=["hz+", "rootsift"],
                        help="base pipeline run inside Slime (default hz+)")
    parser.add_argument("--descriptor", default=None, choices=["auto", "hardnet", "tfeat", "rootsift"],
                        help="Hz+ descriptor; auto = HardNet when its weights are available, else RootSIFT")
    parser.add_argument("--shape", default=None, choices=["affnet", "baumberg"], help="Hz+ affine shape")
    parser.add_argument("--orientation", default=None, choices=["orinet", "gradient", "upright"],
                        help="Hz+ patch orientation")
    parser.add_argument("--upright", action="store_true", default=None,
                        help="no orientation estimation (the paper's upright variants)")
    parser.add_argument("--ransac", default="none", choices=RANSAC_CHOICES, help="post-processing RANSAC")
    parser.add_argument("--threshold", type=float, default=3.0, help="RANSAC inlier threshold in px")
    parser.add_argument("--seed", type=int, default=0, help="random seed (RANSAC sampling)")
    parser.add_argument("--device", default="auto", choices=["auto", "cpu", "cuda"])
    parser.add_argument("--weights-dir", default=None, help="folder with model weights (else TORCH_HOME cache)")
    parser.add_argument("--magnification", type=float, default=None, help="patch magnification over regions")


def _options(args: argparse.Namespace) -> dict:
    keys = ("base", "descriptor", "shape", "orientation", "upright", "ransac", "threshold", "seed", "device",
            "weights_dir", "magnification")
    return {key: getattr(args, key) for key in keys}


def cmd_match(args: argparse.Namespace) -> int:
    from .config import make_config
    from .io import load_image, save_json, save_npz
    from .matcher import Matcher
    from .viz import plot_matches

    preset = args.method
    options = _options(args)
    if args.method == "slime" and options["base"] == "rootsift":
        preset, options["base"] = "slime-rootsift", None
    config = make_config(preset, **options)
    if args.save_stages:
        config.slime.keep_stages = True
    result = Matcher(config)(args.image0, args.image1)
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=out, prefix=".staging-"))
    try:
        save_npz(staging / "matches.npz", **result.arrays())
        save_json(staging / "summary.json", result.summary)
        if not args.no_plot:
            plot_matches(load_image(args.image0), load_image(args.image1), result, staging / "matches.png")
        if args.save_stages and result.stages is not None:
            save_npz(staging / "stages.npz", **result.stages)
        for item in staging.iterdir():
            os.replace(item, out / item.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    counts = result.summary["counts"]
    line = f"{counts['matches']} matches"
    if "inliers" in counts:
        line += f", {counts['inliers']} inliers ({result.geometry_kind})"
    print(f"{line} in {result.summary['seconds']['total']:.2f} s -> {out}/matches.npz")
    for warning in result.summary.get("warnings", []):
        print(f"warning: {warning}", file=sys.stderr)
    return 0


def cmd_viz(args: argparse.Namespace) -> int:
    from .slime.visualize import render_stages

    written = render_stages(args.stages, args.image0, args.image1, args.output, stages=args.stage)
    for path in written:
        print(path)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="slime", description="Image matching by bare homography (Slime)")
    parser.add_argument("--debug", action="store_true", help="show tracebacks and debug logs")
    sub = parser.add_subparsers(dest="command", required=True)

    match = sub.add_parser("match", help="match two images")
    match.add_argument("image0")
    match.add_argument("image1")
    match.add_argument("-o", "--output", required=True, help="output folder")
    match.add_argument("--save-stages", action="store_true", help="also write Slime's stage sets (stages.npz)")
    match.add_argument("--no-plot", action="store_true", help="skip matches.png")
    _add_match_options(match)
    match.set_defaults(func=cmd_match)

    viz = sub.add_parser("viz", help="draw Slime stages saved by `slime match --save-stages`")
    viz.add_argument("stages", help="stages.npz")
    viz.add_argument("image0")
    viz.add_argument("image1")
    viz.add_argument("-o", "--output", required=True, help="output folder for the PNGs")
    viz.add_argument("--stage", action="append", default=None, help="stage name(s) to draw (default: all)")
    viz.set_defaults(func=cmd_viz)

    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.debug else logging.WARNING,
                        format="%(levelname)s: %(message)s")
    try:
        return int(args.func(args) or 0)
    except SlimeMatchError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as error:  # noqa: BLE001 - the CLI never shows a traceback unless --debug
        if args.debug:
            raise
        print(f"error: {type(error).__name__}: {error} (rerun with --debug for details)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
