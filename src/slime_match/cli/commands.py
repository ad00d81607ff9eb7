"""The commands: ``slime match``, ``slime pairs``, ``slime make-pairs``, ``slime demo``, ``slime viz``,
``slime colmap``, ``slime hloc``, ``slime web`` (and ``slime bench`` from slime_match.eval)."""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .. import __version__
from .._runtime import openmp, progress
from ..auto_method import passed_over
from ..choices import CAMERA_MODES
from ..errors import ConfigError, SlimeMatchError, caused_by_interrupt
from .match_options import add_match_options, add_workers_option, config_of, parse_shard_option, positive_int

logger = logging.getLogger("slime_match")


def _report(result, out: Path) -> None:
    choice = result.summary.get("decisions", {}).get("method")
    if choice and not passed_over(choice):  # a passed-over choice was a warning already
        print(choice)
    counts = result.summary["counts"]
    line = f"{counts['matches']} matches"
    if "inliers" in counts:
        line += f", {counts['inliers']} inliers ({result.geometry_kind})"
    print(f"{line} in {result.summary['seconds']['total']:.2f} s -> {out}/matches.npz")


def cmd_match(args: argparse.Namespace) -> int:
    from ..io import load_image
    from ..matcher import Matcher
    from ..runs.outputs import write_pair_outputs

    config = config_of(args)
    image0, image1 = load_image(args.image0), load_image(args.image1)  # bad input fails before model loading
    progress.enable(not args.quiet)
    with _stage_lines(args):
        result = Matcher(config)(image0, image1)
    out = Path(args.output)
    write_pair_outputs(result, image0, image1, out, plot=not args.no_plot)
    if not args.quiet:
        _report(result, out)
    return 0


@contextmanager
def _stage_lines(args: argparse.Namespace) -> Iterator[None]:
    """Within the block, each matching stage on stderr as it finishes, with its seconds: by default; ``-v``
    logs them with the rest, ``-q`` prints nothing."""
    if args.quiet or args.verbose:
        yield
        return
    from .._runtime.timing import stage_listener

    def line(stage: str, seconds: float | None) -> None:
        if seconds is not None:
            print(f"{stage}: {seconds:.2f} s", file=sys.stderr, flush=True)

    with stage_listener(line):
        yield


def cmd_pairs(args: argparse.Namespace) -> int:
    from ..matcher import FEATURE_CACHE_MB
    from ..runs.batch import match_pairs, read_pairs, reindex
    from ..runs.index import INDEX_FILE

    if args.reindex and (args.overwrite or args.ray or args.shard):
        raise ConfigError("--reindex only rebuilds the index from the pair records and matches nothing: drop "
                          "--overwrite, --ray and --shard")
    jobs = read_pairs(args.pairs, args.images)  # a bad pairs file or a missing image fails before any work
    index_file = Path(args.output) / INDEX_FILE
    if args.reindex:
        index = reindex(jobs, args.output)
        count = {status: sum(r["status"] == status for r in index["pairs"]) for status in ("done", "failed")}
        if not args.quiet:
            print(f"{len(jobs)} pairs: {count['done']} done, {count['failed']} failed, "
                  f"{len(jobs) - len(index['pairs'])} not recorded -> {index_file}")
        return 0
    cache_mb = FEATURE_CACHE_MB if args.feature_cache_mb is None else args.feature_cache_mb
    records = match_pairs(config_of(args), jobs, args.output, workers=args.workers, overwrite=args.overwrite,
                          plot=args.plot, feature_cache_mb=cache_mb, progress=not args.quiet,
                          backend="local" if args.ray is None else "ray", ray_address=args.ray or "auto",
                          cpus_per_worker=args.cpus_per_worker, shard=args.shard)
    count = {status: sum(r["status"] == status for r in records) for status in ("done", "skipped", "failed")}
    if args.quiet:
        return 1 if count["failed"] else 0
    shard = f"shard {args.shard[0]}/{args.shard[1]}: " if args.shard else ""
    print(f"{shard}{len(records)} pairs: {count['done']} matched, {count['skipped']} already done, "
          f"{count['failed']} failed -> {index_file}")
    matched = [r for r in records if r["status"] == "done" and "feature_sets" in r]
    if matched:
        print(f"feature cache: {sum(r['cached_feature_sets'] for r in matched)} of "
              f"{sum(r['feature_sets'] for r in matched)} feature sets (an image's blocks or tiles) of the matched "
              "pairs were reused")
    return 1 if count["failed"] else 0


def cmd_make_pairs(args: argparse.Namespace) -> int:
    from ..runs.pair_lists import make_pairs, write_pairs

    path = Path(args.pairs_file)
    _check_output_folder(str(path.parent))
    if path.is_dir():
        raise ConfigError(f"{path} is a folder; -o names the pairs file to write")
    if path.exists() and not args.overwrite:
        raise ConfigError(f"{path} exists; pass --overwrite to replace it")
    mode = "exhaustive" if args.sequential is None else "sequential"
    pairs = make_pairs(args.images, mode, window=args.sequential or 1)
    images = len({name for pair in pairs for name in pair})
    how = "every pair" if mode == "exhaustive" else f"each image and the next {args.sequential} by name"
    what = f"{len(pairs)} pairs of {images} images ({how})"
    write_pairs(path, pairs, comment=f"slime make-pairs: {what} under {args.images}")
    print(f"{what} -> {path}")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    """Match scikit-image's Middlebury motorcycle stereo pair and score it with its disparity map."""
    from functools import partial

    import numpy as np

    from ..eval.datasets.motorcycle import stereo_motorcycle
    from ..eval.metrics import disparity_error
    from ..matcher import Matcher
    from ..runs.outputs import write_pair_outputs

    left, right, disparity = stereo_motorcycle()
    out = Path(args.output)
    image0, image1 = left.astype(np.float32) / 255.0, right.astype(np.float32) / 255.0
    progress.enable(not args.quiet)
    with _stage_lines(args):
        result = Matcher(config_of(args))(image0, image1)
    error = disparity_error(result.keypoints0, result.keypoints1, disparity)
    known = np.isfinite(error)
    correct = known & (error < 15.0)
    result.summary["ground_truth"] = {
        "matches_with_known_disparity": int(known.sum()),
        "correct_15px": int(correct.sum()),
        "precision": float(correct.sum() / max(int(known.sum()), 1)),
    }
    pictures = {"motorcycle_left.png": left, "motorcycle_right.png": right}
    write_pair_outputs(result, image0, image1, out,
                       extra={name: partial(_write_rgb, rgb=rgb) for name, rgb in pictures.items()})
    if args.quiet:
        return 0
    _report(result, out)
    gt = result.summary["ground_truth"]
    print(f"ground truth (disparity): {gt['correct_15px']} of {gt['matches_with_known_disparity']} matches "
          f"correct within 15 px, precision {gt['precision']:.3f}")
    return 0


def _write_rgb(path: Path, rgb) -> None:
    """Write an (H, W, 3) uint8 RGB array as an image file."""
    import cv2

    if not cv2.imwrite(str(path), rgb[:, :, ::-1]):
        raise OSError(f"could not write {path}")


def cmd_warmup(args: argparse.Namespace) -> int:
    """Compile every compiled loop of the package ahead of the first match (or load them from numba's disk
    cache): each group's warm-up, then one weight-free Slime match of a small synthetic pair, which runs the
    loops of every Slime stage in this process."""
    import os
    import time

    from .._runtime import compiled
    from ..config import make_config
    from ..matcher import Matcher

    start = time.perf_counter()
    seconds = compiled.warm_up()
    image0, image1 = _synthetic_pair()
    config = make_config("slime", shape="baumberg", orientation="gradient", descriptor="rootsift", device="cpu",
                         workers=1)
    result = Matcher(config)(image0, image1)
    total = time.perf_counter() - start
    groups = ", ".join(f"{group} {value:.1f} s" for group, value in seconds.items())
    cache = os.environ.get("NUMBA_CACHE_DIR") or "numba's default: __pycache__ beside the package's modules"
    print(f"compiled loops ready in {total:.1f} s ({groups}; a Slime match of a synthetic pair with "
          f"{len(result)} matches, {total - sum(seconds.values()):.1f} s); cache: {cache}")
    return 0


def _synthetic_pair(size: tuple[int, int] = (480, 640)):
    """A textured (H, W, 3) float32 image and the same image under a known mild homography (a rotation by 8
    degrees and a 0.9 scaling about the centre): enough matches for every Slime stage to run."""
    import cv2
    import numpy as np

    height, width = size
    noise = np.random.default_rng(0).random((height, width, 3), dtype=np.float32)
    image0 = cv2.GaussianBlur(noise, (0, 0), 2.0)
    image0 = (image0 - image0.min()) / (image0.max() - image0.min())
    rotation = cv2.getRotationMatrix2D((width / 2, height / 2), 8.0, 0.9)
    image1 = cv2.warpAffine(image0, rotation, (width, height), flags=cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_REFLECT)
    return image0, image1


def cmd_viz(args: argparse.Namespace) -> int:
    from ..slime.visualize import render_stages

    written = render_stages(args.stages, args.image0, args.image1, args.output, stages=args.stage)
    for path in written:
        print(path)
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from ..eval.bench import cmd_bench as run_bench

    return run_bench(args)


def cmd_colmap(args: argparse.Namespace) -> int:
    from ..runs.colmap import DATABASE_FILE, SPARSE_FOLDER, export_run

    summary = export_run(args.run, args.images, args.output, merge_radius=args.merge_radius,
                         inliers_only=args.inliers_only, camera_mode=args.camera_mode,
                         reconstruct=not args.no_reconstruct, seed=args.seed, threads=args.threads,
                         overwrite=args.overwrite)
    print(f"{summary['images']} images, {summary['keypoints']} keypoints, {summary['matches']} matches, "
          f"{summary['verified_pairs']} of {summary['pairs']} pairs verified -> {Path(args.output) / DATABASE_FILE}")
    for index, model in enumerate(summary.get("models", [])):
        print(f"model {index}: {model['registered_images']} of {summary['images']} images registered, "
              f"{model['points3D']} 3D points, track length {model['mean_track_length']:.2f}, reprojection "
              f"error {model['mean_reprojection_error']:.2f} px -> {Path(args.output) / SPARSE_FOLDER / str(index)}")
    if "models" in summary and not summary["models"]:
        print("COLMAP reconstructed no model (it found no image pair with enough verified matches and baseline "
              "to start from)")
    return 0


def cmd_hloc(args: argparse.Namespace) -> int:
    from ..runs.hloc import FEATURES_FILE, MATCHES_FILE, export_hloc

    summary = export_hloc(args.run, args.images, args.output, merge_radius=args.merge_radius,
                          inliers_only=args.inliers_only, overwrite=args.overwrite)
    out = Path(args.output)
    print(f"{summary['images']} images, {summary['keypoints']} keypoints, {summary['matches']} matches in "
          f"{summary['pairs']} pairs -> {out / FEATURES_FILE}, {out / MATCHES_FILE}")
    return 0


def cmd_web(args: argparse.Namespace) -> int:
    from ..web import serve  # FastAPI and uvicorn load only here

    serve(args.host, args.port, args.images, args.run, args.annotations, args.max_upload_mb, args.max_megapixels)
    return 0


def _add_export_options(parser: argparse.ArgumentParser, files: str, tool: str) -> None:
    """The options that ``slime colmap`` and ``slime hloc`` share: the run, its images, the output folder and
    how the run's keypoints are merged."""
    parser.add_argument("run", help="run folder of `slime pairs`")
    parser.add_argument("--images", default=".", help="the image folder of the run (default: the current folder)")
    parser.add_argument("-o", "--output", required=True, help=f"output folder: {files}")
    parser.add_argument("--merge-radius", type=float, default=1.0,
                        help="px: keypoints of an image within this distance (in x and in y) become one "
                             "(default 1; 0: only identical positions)")
    parser.add_argument("--inliers-only", action="store_true",
                        help="export only the run's RANSAC inliers (the run must have used --ransac)")
    parser.add_argument("--overwrite", action="store_true", help=f"replace an earlier {tool} export in the output "
                                                                  "folder")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="slime", description="Image matching by bare homography (Slime)")
    parser.add_argument("--debug", action="store_true", help="show tracebacks and debug logs")
    parser.add_argument("--version", action="version", version=f"slime-match {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    match = sub.add_parser("match", help="match two images")
    match.add_argument("image0")
    match.add_argument("image1")
    match.add_argument("-o", "--output", required=True, help="output folder")
    match.add_argument("--save-stages", action="store_true", help="also write Slime's stage sets (stages.npz)")
    match.add_argument("--no-plot", action="store_true", help="skip matches.png")
    add_match_options(match)
    add_workers_option(match)
    match.set_defaults(func=cmd_match)

    pairs = sub.add_parser("pairs", help="match many pairs listed in a file (resumable, optional workers)")
    pairs.add_argument("pairs", help="text file, one 'image0 image1' pair per line (# comments)")
    pairs.add_argument("--images", default=".", help="folder that relative image names are resolved against "
                                                     "(default: the current folder)")
    pairs.add_argument("-o", "--output", required=True,
                       help="run folder: one sub-folder per pair, records/ (one record per finished pair), "
                            "pairs.json (their index), run.json (configuration)")
    pairs.add_argument("--workers", type=int, default=None, metavar="N",
                       help="pairs matched at once: local processes sharing the CPUs (default 1), or with --ray "
                            "Ray actors (default: as many as the cluster's CPUs hold)")
    pairs.add_argument("--cpus-per-worker", type=positive_int, default=None, metavar="K",
                       help="CPUs of each worker or Ray actor: its torch threads and Slime's forked workers "
                            "(default: an equal share of this process's CPUs; with --ray 1)")
    pairs.add_argument("--ray", nargs="?", const="auto", default=None, metavar="auto|ADDRESS",
                       help="match the pairs on the actors of a Ray cluster (needs the ray extra): 'auto' (the "
                            "default) joins the cluster started on this machine by `ray start` or named by "
                            "RAY_ADDRESS, ADDRESS is its head's host:port; the image and run folders must have "
                            "the same path on every node")
    pairs.add_argument("--shard", type=parse_shard_option, default=None, metavar="I/N",
                       help="match only part I of N of the pairs (pairs sharing images kept together), e.g. "
                            "one part per task of a job array, all writing into the same run folder")
    pairs.add_argument("--reindex", action="store_true",
                       help="only rebuild pairs.json from the run folder's pair records, and match nothing")
    pairs.add_argument("--overwrite", action="store_true", help="recompute the pairs already done in the folder")
    pairs.add_argument("--plot", action="store_true", help="also draw each pair's matches.png")
    pairs.add_argument("--feature-cache-mb", type=float, default=None, metavar="MB",
                       help="memory for Slime's block and tile features of recent images, reused by later pairs "
                            "with the same image (the same matches; default 512; 0: off)")
    add_match_options(pairs)
    pairs.set_defaults(func=cmd_pairs)

    make = sub.add_parser("make-pairs", help="write a pairs file for `slime pairs` from an image folder (every "
                                             "pair, or each image with the next N)")
    make.add_argument("images", help="image folder, sub-folders included (names are written relative to it)")
    make.add_argument("-o", "--output", dest="pairs_file", required=True, help="the pairs file to write")
    make.add_argument("--sequential", type=positive_int, default=None, metavar="N",
                      help="pair each image with the N after it in name order (video frames) instead of every "
                           "pair (N (N - 1) / 2 of N images)")
    make.add_argument("--overwrite", action="store_true", help="replace an existing pairs file")
    make.set_defaults(func=cmd_make_pairs)

    demo = sub.add_parser("demo", help="match a real stereo pair (Middlebury motorcycle, from scikit-image: the "
                                          "demo extra) and score it by its disparity")
    demo.add_argument("-o", "--output", default="slime_demo", help="output folder (default slime_demo/)")
    add_match_options(demo)
    add_workers_option(demo)
    demo.set_defaults(func=cmd_demo)

    warmup = sub.add_parser("warmup", help="compile the package's loops (numba) ahead of the first match; they "
                                           "are cached in NUMBA_CACHE_DIR when set")
    warmup.add_argument("-v", "--verbose", action="store_true", help="log the warm-up match's stages")
    warmup.set_defaults(func=cmd_warmup)

    viz = sub.add_parser("viz", help="draw Slime stages saved by `slime match --save-stages`")
    viz.add_argument("stages", help="stages.npz")
    viz.add_argument("image0")
    viz.add_argument("image1")
    viz.add_argument("-o", "--output", required=True, help="output folder for the PNGs")
    viz.add_argument("--stage", action="append", default=None, help="stage name(s) to draw (default: all)")
    viz.set_defaults(func=cmd_viz)

    colmap = sub.add_parser("colmap", help="a `slime pairs` run as a COLMAP database and its sparse "
                                           "reconstruction (needs pycolmap)")
    _add_export_options(colmap, "database.db, pairs.txt, summary.json, sparse/N/ (COLMAP models)", "COLMAP")
    colmap.add_argument("--camera-mode", choices=CAMERA_MODES, default="auto",
                        help="COLMAP's camera sharing among images (default auto)")
    colmap.add_argument("--no-reconstruct", action="store_true",
                        help="only write and verify the database (no incremental mapping)")
    colmap.add_argument("--seed", type=int, default=0, help="COLMAP's random seed (default 0)")
    colmap.add_argument("--threads", type=positive_int, default=1,
                        help="COLMAP's mapping threads (default 1: the same models on every run; more is faster "
                             "on large runs but not reproducible)")
    colmap.add_argument("-v", "--verbose", action="store_true", help="log each step and COLMAP's own output")
    colmap.set_defaults(func=cmd_colmap)

    hloc = sub.add_parser("hloc", help="a `slime pairs` run as hloc's features.h5 and matches.h5 (needs h5py)")
    _add_export_options(hloc, "features.h5, matches.h5, pairs.txt, summary.json", "hloc")
    hloc.add_argument("-v", "--verbose", action="store_true", help="log what was written")
    hloc.set_defaults(func=cmd_hloc)

    web = sub.add_parser("web", help="a local web app: match two images and view the matches, Slime's stages and "
                                     "runs; annotate ground-truth correspondences (needs the web extra)")
    web.add_argument("--host", default="127.0.0.1",
                     help="address to listen on (default 127.0.0.1: this machine only)")
    web.add_argument("--port", type=positive_int, default=8000, help="port (default 8000)")
    web.add_argument("--images", action="append", default=[], metavar="DIR",
                     help="an image folder the app may read (repeatable); it serves no file outside its folders")
    web.add_argument("--run", action="append", default=[], metavar="RUNDIR",
                     help="a `slime pairs` run folder to browse (repeatable; its images are found in --images)")
    web.add_argument("--annotations", default=None, metavar="DIR",
                     help="folder where the annotation tool saves pairs as slime bench reads them "
                          "(DIR/wxbs/<name>/, DIR/planar/); without it, annotations are downloaded")
    web.add_argument("--max-upload-mb", type=float, default=None, metavar="MB",
                     help="largest image upload accepted (default 25)")
    web.add_argument("--max-megapixels", type=float, default=None, metavar="MP",
                     help="largest image taken, read from its header before decoding (default 40)")
    web.set_defaults(func=cmd_web)

    from ..eval.bench_args import add_bench_parser

    add_bench_parser(sub, cmd_bench)

    return parser


def _check_output_folder(path: str | None) -> None:
    """Refuse, before any work, an output folder (``-o``) that is, or lies under, an existing file."""
    if path is None:
        return
    existing = next(p for p in (Path(path), *Path(path).parents) if p.exists())  # "." or "/" at the latest
    if not existing.is_dir():
        where = "is" if existing == Path(path) else f"lies under {existing}, which is"
        raise SlimeMatchError(f"output folder {path} {where} a file, not a folder: choose another -o")


def main(argv: list[str] | None = None) -> int:
    openmp.set_default_spin_count()  # before the subcommands load torch
    parser = build_parser()
    args = parser.parse_args(argv)  # --help and --version end here, before numba and torch load
    from .._runtime import compiled

    compiled.install_notice()
    level = (logging.DEBUG if args.debug else logging.INFO if getattr(args, "verbose", False)
             else logging.ERROR if getattr(args, "quiet", False) else logging.WARNING)
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s")
    logging.getLogger("slime_match").setLevel(level)  # also when the root logger was configured before
    try:
        _check_output_folder(getattr(args, "output", None))
        return int(args.func(args) or 0)
    except SlimeMatchError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except BaseException as error:  # Ctrl-C: a KeyboardInterrupt, or an error that one caused (numba's)
        if caused_by_interrupt(error):
            print("interrupted", file=sys.stderr)
            return 130
        if args.debug or not isinstance(error, Exception):  # SystemExit and the like go on
            raise
        print(f"error: {type(error).__name__}: {error} (rerun with --debug for details)", file=sys.stderr)
        return 1

