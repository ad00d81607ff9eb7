"""What a method finds between simulated views, view by view: on pairs with a ground-truth homography (an
EVD-style folder), the method between each view of image 0 and each of image 1 at one tilt (``--images both``, as
ASIFT pairs its views), or between each view of one image and the other image as it is (``image0``, ``image1``),
with the matches correct within ``--px`` of the ground truth (both ways, as ``slime bench`` counts them) and the
EVD protocol's mAA per view (pair).

    python benchmarks/view_pairs_oracle.py synth5 --pairs v_wormhole_1_crossed32 --tilt 4 [--step 18]
        [--images both|image0|image1] [--method aliked-lg] [--out results/view_pairs_oracle.json]

Each view is ``slime_match.views.simulate_view`` of the image (its rotation, blur and subsampling); the method
runs on the view images with its own views and rotation fallback off, its matches are mapped back to the original
images and kept where they lie inside them (a view's corners show the warp's reflected border). The best view
(pair) is an upper bound on what one view (pair) gives the method, since the ground truth picks it.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from slime_match import Matcher, make_config
from slime_match.eval.bench_config import BenchConfig
from slime_match.eval.datasets import load_dataset
from slime_match.eval.metrics.correctness import correct_matches_homography
from slime_match.eval.predictions import load_pair_images
from slime_match.eval.scoring import evaluate_protocol, pair_gt
from slime_match.views import simulate_view


def _views(image: np.ndarray, viewed: bool, tilt: float, angles: np.ndarray) -> list[tuple[float | None, tuple]]:
    """The (angle, (pixels, view)) to match of one image: its views, or the image itself (angle None)."""
    if not viewed:
        return [(None, (image, None))]
    return [(float(angle), simulate_view(image, tilt, float(angle))) for angle in angles]


def _to_original(xy: np.ndarray, view) -> tuple[np.ndarray, np.ndarray]:
    """(K, 2) view px -> original px, and (K,) whether each lies inside the original image."""
    xy = xy.astype(np.float64)
    if view is None:
        return xy, np.ones(len(xy), bool)
    original = view.frame.to_original(xy)
    return original, view.inside(original)


def view_pairs(matcher: Matcher, pair, images: str, tilt: float, step: float, px: float) -> list[dict]:
    """Per view (pair), the method's matches inside both images, those within ``px`` of the pair's homography
    and the EVD protocol's mAA, best first."""
    image0, image1 = load_pair_images(pair)
    gt = pair_gt(pair, (image0, image1))
    angles = np.arange(0.0, 180.0, step)
    rows = []
    for angle0, (pixels0, view0) in _views(image0, images in ("both", "image0"), tilt, angles):
        for angle1, (pixels1, view1) in _views(image1, images in ("both", "image1"), tilt, angles):
            result = matcher(pixels0, pixels1)
            xy0, inside0 = _to_original(result.keypoints0, view0)
            xy1, inside1 = _to_original(result.keypoints1, view1)
            xy0, xy1 = xy0[inside0 & inside1], xy1[inside0 & inside1]
            scores = evaluate_protocol("evd", gt, {"m": (xy0, xy1)}, BenchConfig(thresholds=["none"]))["m"]
            correct = int(correct_matches_homography(xy0, xy1, pair.H, px).sum())
            rows.append({"angle0": angle0, "angle1": angle1, "matches": len(xy0), "correct": correct,
                         "maa": round(float(scores["maa"]), 3)})
    return sorted(rows, key=lambda row: (-row["correct"], -row["matches"]))


def _angles(row: dict) -> str:
    return "/".join("-" if angle is None else f"{angle:g}" for angle in (row["angle0"], row["angle1"]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", help="EVD-style folder (1/, 2/, h/), e.g. one written by synthetic_viewpoints.py")
    parser.add_argument("--pairs", required=True, help="pair names, comma-separated")
    parser.add_argument("--tilt", type=float, default=4.0, help="the views' tilt")
    parser.add_argument("--step", type=float, default=18.0, help="degrees between the views' rotations")
    parser.add_argument("--images", choices=("both", "image0", "image1"), default="both",
                        help="whose views: both images' (every pair of views), or one image's against the other")
    parser.add_argument("--method", default="aliked-lg", help="the method run on each view (pair)")
    parser.add_argument("--px", type=float, default=10.0,
                        help="a match is correct within this many px of the GT (both ways)")
    parser.add_argument("--out", type=Path, default=None, help="JSON file to write (every view (pair) of each pair)")
    args = parser.parse_args()
    if args.tilt < 1.0 or args.step <= 0.0:
        parser.error("need --tilt >= 1 and --step > 0")
    pairs = {pair.name.split("/")[-1]: pair for pair in load_dataset(f"evd:{args.folder}")}
    names = [name.strip() for name in args.pairs.split(",") if name.strip()]
    if unknown := [name for name in names if name not in pairs]:
        parser.error(f"no pair {', '.join(unknown)} in {args.folder} (it has {', '.join(sorted(pairs))})")
    options = {"views.mode": "off"}
    if make_config(args.method).method == "slime":
        options["rotation_fallback"] = "off"
    matcher = Matcher(make_config(args.method, **options))
    report = {"tilt": args.tilt, "step": args.step, "images": args.images, "method": args.method, "px": args.px,
              "pairs": {}}
    for name in names:
        rows = view_pairs(matcher, pairs[name], args.images, args.tilt, args.step, args.px)
        report["pairs"][name] = rows
        best = ", ".join(f"{r['correct']} of {r['matches']} (mAA {r['maa']:.2f}) at {_angles(r)}" for r in rows[:3])
        print(f"{name}: best views (correct of matches at angle0/angle1): {best}", flush=True)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1))
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
