"""The ``slime bench`` command's arguments. Kept apart from :mod:`slime_match.eval.bench` and light (no torch,
numba or OpenCV), so that building the ``slime`` parser stays fast."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from slime_match.choices import PAPER_METHODS


def add_bench_parser(subparsers: argparse._SubParsersAction, run: Callable[[argparse.Namespace], int]
                     ) -> argparse.ArgumentParser:
    """Register ``bench`` on a ``subparsers`` object (``slime bench``), with ``run`` (the parsed arguments ->
    exit code; :func:`slime_match.eval.bench.cmd_bench`, or a function that imports it when called) as its
    ``func``."""
    p = subparsers.add_parser(
        "bench",
        help="run methods over datasets and write the paper's metric tables",
        description="Run methods over datasets, cache predictions (resumable) and write tables, charts "
        "and maps. Method specs: name[:key=value,...], e.g. 'hz+:descriptor=tfeat'.",
    )
    p.add_argument(
        "datasets",
        nargs="+",
        help="dataset specs: graf, hpatches, scannet-sample, motorcycle, "
        "planar:<dir>, hpatches:<dir>, oxford:<dir>, evd:<dir>, wxbs:<dir>, megadepth1500:<root>, "
        "scannet1500:<root>",
    )
    p.add_argument(
        "--methods",
        default=",".join(PAPER_METHODS),
        help="comma- or space-separated method specs (default: the paper's set); "
        "separate specs with options by ';'",
    )
    p.add_argument("-o", "--output", default="results", help="results folder")
    p.add_argument("--thresholds", default="none,5,3,2,1", help="post-processing RANSAC thresholds (px)")
    p.add_argument("--rotations", default="", help="rotated variants to add, degrees, e.g. 90,180,270")
    p.add_argument("--rotate-kinds", default="homography", help="pair kinds that get rotated variants")
    p.add_argument("--max-pairs", type=int, default=None, help="first N pairs of each dataset")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="auto", choices=["auto", "cpu", "cuda"])
    p.add_argument("--ransac-backend", default="slime", choices=["slime", "magsac", "poselib"])
    p.add_argument("--map-pairs", type=int, default=2, help="pairs that get coverage/error maps")
    p.add_argument("--data-root", default=None, help="folder holding the named datasets (graf, hpatches, scannet-sample, ...; default: $SLIME_MATCH_DATA)")
    p.add_argument(
        "--protocol-datasets",
        default="evd,wxbs",
        help="dataset names whose pairs also get their standard protocol (EVD for homography pairs, WxBS for "
        "pairs with GT correspondences), e.g. evd,wxbs,planar; '' = none",
    )
    p.add_argument("--protocol-h-threshold", type=float, default=3.0, help="EVD protocol MAGSAC++ threshold (px)")
    p.add_argument("--protocol-f-threshold", type=float, default=3.0, help="WxBS protocol MAGSAC++ threshold (px)")
    p.add_argument("--protocol-max-iters", type=int, default=10000, help="MAGSAC++ iterations of the protocols")
    p.add_argument(
        "--protocol-orders",
        type=int,
        default=10,
        help="orders of the matches each protocol runs on (the given one and random permutations; MAGSAC++ "
        "samples by index): the tables add the mean pair mAA over them; 1 = the given order only",
    )
    p.set_defaults(func=run)
    return p
