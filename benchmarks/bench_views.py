"""What simulated views cost: Slime with ``views="auto"`` (the default) and ``views="off"`` on an easy pair
(graf img1 -> img3 at 640x480, where "auto" adds no view) and on the hard EVD pairs (where it may add them),
in one process, with the views each run tried and its EVD protocol mAA.

    python benchmarks/bench_views.py --data DATA [--pairs adam,girl] [--repeats 3] [--out results/bench_views.json]

``DATA`` holds ``oxford_graf`` and ``hard/evd``. Each configuration is timed ``--repeats`` times per pair (the
median is reported; a first untimed call loads the models and compiles the kernels). The JSON has per run the
seconds, the views record of ``summary.json`` and the mAA; the summary gives each hard pair's median over the
easy pair's median with views "auto" (the bar: at most 4) and the easy pair's auto / off ratio (at most 1.1).
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
from slime_match.eval.metrics.protocols import evd_protocol
from slime_match.io import load_image


def _graf(data: Path) -> tuple[np.ndarray, np.ndarray]:
    a, b = (load_image(data / "oxford_graf" / f) for f in ("img1.png", "img3.png"))
    return tuple(cv2.resize(im, (640, 480), interpolation=cv2.INTER_AREA) for im in (a, b))


def _timed(matcher: Matcher, a: np.ndarray, b: np.ndarray, repeats: int) -> tuple[float, object]:
    seconds, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = matcher(a, b)
        seconds.append(time.perf_counter() - start)
    return statistics.median(seconds), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True, help="folder with oxford_graf and hard/evd")
    parser.add_argument("--pairs", default="adam,cafe,dum,girl,shop", help="EVD pair names")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--out", type=Path, default=Path("results/bench_views.json"))
    args = parser.parse_args()
    matchers = {mode: Matcher(make_config("slime", views=mode, workers=args.workers), feature_cache_mb=0)
                for mode in ("auto", "off")}
    easy = _graf(args.data)
    matchers["auto"](*easy)  # models and kernels
    runs = []
    for mode, matcher in matchers.items():
        median, result = _timed(matcher, *easy, args.repeats)
        runs.append({"pair": "graf-1-3-640x480", "views": mode, "seconds": median,
                     "record": result.summary["decisions"]["views"], "matches": len(result)})
        print(json.dumps(runs[-1]), flush=True)
    evd = args.data / "hard" / "evd"
    for name in filter(None, args.pairs.split(",")):
        a, b = load_image(evd / "1" / f"{name}.png"), load_image(evd / "2" / f"{name}.png")
        h = np.loadtxt(evd / "h" / f"{name}.txt")
        for mode, matcher in matchers.items():
            median, result = _timed(matcher, a, b, args.repeats)
            maa = evd_protocol(result.keypoints0, result.keypoints1, h, a.shape[:2], b.shape[:2], 3.0, 10_000)["maa"] \
                if len(result) >= 4 else 0.0
            runs.append({"pair": f"evd-{name}", "views": mode, "seconds": median, "maa": maa,
                         "record": result.summary["decisions"]["views"], "matches": len(result)})
            print(json.dumps(runs[-1]), flush=True)
    seconds = {(r["pair"], r["views"]): r["seconds"] for r in runs}
    easy_auto = seconds["graf-1-3-640x480", "auto"]
    summary = {"easy_auto_over_off": easy_auto / seconds["graf-1-3-640x480", "off"],
               "hard_over_easy": {r["pair"]: r["seconds"] / easy_auto for r in runs
                                  if r["views"] == "auto" and r["pair"] != "graf-1-3-640x480"},
               "load_average": os.getloadavg()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"runs": runs, "summary": summary}, indent=1) + "\n")
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
