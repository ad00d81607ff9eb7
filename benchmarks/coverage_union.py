"""How much coverage is left to win on planar pairs: each method's coverage and that of the union of their
correct matches, from the prediction cache of a ``slime bench`` run.

    slime bench graf hpatches --methods "hz+:descriptor=tfeat;slime:descriptor=tfeat" --thresholds none -o OUT
    python benchmarks/coverage_union.py OUT [--methods "hz+_descriptor-tfeat,slime_descriptor-tfeat"]
        [--out OUT/coverage_union.json]

If the union of two methods covers little more than one of them, no re-ranking of the other's matches can
lift its coverage far above it: the remaining valid area holds no correct match of either (mostly
textureless regions). Coverage = the paper's (t = 15 px, min of the two images, raw matches, no RANSAC).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from slime_match.eval.datasets import load_dataset
from slime_match.eval.metrics import correct_matches_homography, coverage, valid_area_homography
from slime_match.io import load_image


def pair_coverages(pair, predictions: list[dict[str, np.ndarray]]) -> list[float]:
    """Coverage of each prediction and, last, of the union of all of them."""
    a, b = load_image(pair.image0), load_image(pair.image1)
    valid0, valid1 = valid_area_homography(pair.H, a.shape[:2], b.shape[:2], pair.mask0, pair.mask1)

    def cov(x0: np.ndarray, x1: np.ndarray) -> float:
        ok = correct_matches_homography(x0, x1, pair.H)
        return coverage(x0[ok], x1[ok], a.shape[:2], b.shape[:2], valid0, valid1)

    each = [cov(p["keypoints0"], p["keypoints1"]) for p in predictions]
    union = cov(np.vstack([p["keypoints0"] for p in predictions]), np.vstack([p["keypoints1"] for p in predictions]))
    return each + [union]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", type=Path, help="slime bench output folder (with predictions/)")
    parser.add_argument("--methods", default="hz+_descriptor-tfeat,slime_descriptor-tfeat",
                        help="comma-separated prediction folder names under RESULTS/predictions")
    parser.add_argument("--datasets", default="graf,hpatches")
    parser.add_argument("--out", type=Path, help="JSON output (default RESULTS/coverage_union.json)")
    args = parser.parse_args()
    methods = args.methods.split(",")
    rows = {}
    for spec in args.datasets.split(","):
        for pair in load_dataset(spec):
            files = [args.results / "predictions" / m / f"{spec}__{pair.name.replace('/', '__')}.npz" for m in methods]
            if not all(f.is_file() for f in files):
                continue
            rows[pair.name] = pair_coverages(pair, [dict(np.load(f)) for f in files])
            print(pair.name, " ".join(f"{v:.3f}" for v in rows[pair.name]))
    if not rows:
        raise SystemExit(f"no pair has predictions of all of {methods} under {args.results / 'predictions'}")
    mean = np.mean(list(rows.values()), axis=0)
    print("mean", " ".join(f"{m}={v:.3f}" for m, v in zip(methods + ["union"], mean)))
    out = args.out or args.results / "coverage_union.json"
    out.write_text(json.dumps({"methods": methods, "pairs": rows, "mean": dict(zip(methods + ["union"], mean))},
                              indent=1))


if __name__ == "__main__":
    main()
