"""What simulated views cost: a Slime preset with ``views="auto"`` (the default) and ``views="off"`` on the hard
pairs (where "auto" may add views) and on an easy pair of the same size (graf img1 -> img3 scaled to each hard
image's pixel count, where "auto" adds none), in one process, with the views each run tried and the pair's
protocol mAA.

    python benchmarks/bench_views.py --data DATA [--method slime-aliked] [--evd adam,girl] [--wxbs tyn]
        [--repeats 3] [--out results/bench_views.json]

``DATA`` holds ``oxford_graf``, ``hard/evd`` and ``hard/wxbs``. Each configuration is timed ``--repeats`` times
per pair (the median is reported; a first untimed call loads the models and compiles the kernels); the images
are matched at their own size, as ``slime match`` does. The JSON has per run the seconds, the views record of
``summary.json`` and the mAA; its summary gives, per hard pair, the time with views over the easy pair of the
same size with views (``over_easy``; the bar where views are kept: at most 2) and over its own time without
views (``over_off``; the bar where views are tried and dropped: a median of at most 1.3), and graf 1->3 at
640x480 with views "auto" over "off" (at most 1.1: a pair that needs no view pays nothing for them).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import cv2
import numpy as np

from slime_match import Matcher, make_config
from slime_match.eval.bench_config import BenchConfig
from slime_match.eval.datasets import load_dataset
from slime_match.eval.predictions import load_pair_images
from slime_match.eval.scoring import evaluate_protocol, pair_gt
from slime_match.io import load_image

PROTOCOL = BenchConfig(thresholds=["none"])


def _graf(data: Path, pixels: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """graf img1, img3 at 640x480, or each scaled (aspect kept) to the given pixel counts."""
    images = [load_image(data / "oxford_graf" / f) for f in ("img1.png", "img3.png")]
    if pixels is None:
        return tuple(cv2.resize(im, (640, 480), interpolation=cv2.INTER_AREA) for im in images)
    out = []
    for im, count in zip(images, pixels):
        scale = (count / (im.shape[0] * im.shape[1])) ** 0.5
        size = (round(im.shape[1] * scale), round(im.shape[0] * scale))
        out.append(cv2.resize(im, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR))
    return tuple(out)


def _timed(matcher: Matcher, a: np.ndarray, b: np.ndarray, repeats: int) -> tuple[float, object]:
    seconds, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = matcher(a, b)
        seconds.append(time.perf_counter() - start)
    return statistics.median(seconds), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True, help="folder with oxford_graf, hard/evd and hard/wxbs")
    parser.add_argument("--method", default="slime", help="a Slime preset (slime, slime-aliked, ...)")
    parser.add_argument("--evd", default="adam,cafe,dum,girl,shop", help="EVD pair names ('' for none)")
    parser.add_argument("--wxbs", default="", help="WxBS pair names, e.g. tyn,flood")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--out", type=Path, default=Path("results/bench_views.json"))
    args = parser.parse_args()
    matchers = {mode: Matcher(make_config(args.method, views=mode, workers=args.workers), feature_cache_mb=0)
                for mode in ("auto", "off")}
    runs, easy_seconds = [], {}

    def run(label: str, a: np.ndarray, b: np.ndarray, mode: str, pair=None) -> dict:
        median, result = _timed(matchers[mode], a, b, args.repeats)
        row = {"pair": label, "views": mode, "seconds": median, "matches": len(result),
               "record": result.summary["decisions"]["views"]}
        if pair is not None:
            raw = {"m": (result.keypoints0, result.keypoints1)}
            scores = evaluate_protocol(label.partition("/")[0], pair_gt(pair, (a, b)), raw, PROTOCOL)["m"]
            row["maa"], row["maa_mean"] = scores["maa"], scores["maa_mean"]
        runs.append(row)
        print(json.dumps(row), flush=True)
        return row

    easy = _graf(args.data)
    matchers["auto"](*easy)  # models and kernels
    for mode in ("auto", "off"):
        easy_seconds["640x480", mode] = run("graf-1-3-640x480", *easy, mode)["seconds"]
    summary = {"method": args.method, "easy_auto_over_off": easy_seconds["640x480", "auto"]
               / easy_seconds["640x480", "off"], "pairs": {}}
    hard = [(f"evd:{args.data / 'hard' / 'evd'}", args.evd), (f"wxbs:{args.data / 'hard' / 'wxbs'}", args.wxbs)]
    for spec, names in hard:
        wanted = [n for n in names.split(",") if n]
        pairs = {p.name: p for p in load_dataset(spec)} if wanted else {}
        for name in wanted:
            pair = pairs[name]
            a, b = load_pair_images(pair)
            label = f"{spec.partition(':')[0]}/{name}"
            auto, off = (run(label, a, b, mode, pair) for mode in ("auto", "off"))
            pixels = (a.shape[0] * a.shape[1], b.shape[0] * b.shape[1])
            if pixels not in easy_seconds:
                easy = _graf(args.data, pixels)
                easy_seconds[pixels] = run(f"graf-1-3-{pixels[0]}+{pixels[1]}px", *easy, "auto")["seconds"]
            summary["pairs"][label] = {"decision": auto["record"].get("decision"),
                                       "over_easy": auto["seconds"] / easy_seconds[pixels],
                                       "over_off": auto["seconds"] / off["seconds"]}
    summary["load_average"] = os.getloadavg()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"runs": runs, "summary": summary}, indent=1) + "\n")
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
