"""How far views of both images, matched against each other as ASIFT matches them, take a base pipeline alone: on
pairs with a ground-truth homography (an EVD-style folder), the base between each simulated view of image 0 and
each of image 1 at one tilt, and the matches within ``--px`` of the ground truth per pair of view angles.

    python benchmarks/view_pairs_oracle.py synth5 --pairs v_wormhole_1_crossed32 --tilt 4 [--step 18]
        [--method aliked-lg] [--out results/view_pairs_oracle.json]

Each view is ``slime_match.views.simulate_view`` of the image (its rotation, blur and subsampling); the base runs
on the two view images with its own views off, its matches are mapped back to the original images and kept
where they lie inside both (a view's corners show the warp's reflected border). The best angle pair is an upper
bound on what one pair of views gives the base, since the ground truth picks it.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from slime_match import Matcher, make_config
from slime_match.eval.datasets import load_dataset
from slime_match.eval.predictions import load_pair_images
from slime_match.geometry.homography import project
from slime_match.views import simulate_view


def angle_pairs(matcher: Matcher, image0: np.ndarray, image1: np.ndarray, H: np.ndarray, tilt: float, step: float,
                px: float) -> list[dict]:
    """Per pair of view angles (degrees), the base's matches inside both images and those within ``px`` of
    ``H`` (image 0 -> image 1), best first."""
    angles = np.arange(0.0, 180.0, step)
    views0 = [simulate_view(image0, tilt, float(a)) for a in angles]
    views1 = [simulate_view(image1, tilt, float(a)) for a in angles]
    rows = []
    for angle0, (pixels0, view0) in zip(angles, views0):
        for angle1, (pixels1, view1) in zip(angles, views1):
            result = matcher(pixels0, pixels1)
            xy0 = view0.frame.to_original(result.keypoints0.astype(np.float64))
            xy1 = view1.frame.to_original(result.keypoints1.astype(np.float64))
            inside = view0.inside(xy0) & view1.inside(xy1)
            xy0, xy1 = xy0[inside], xy1[inside]
            error = np.linalg.norm(project(H, xy0)[0] - xy1, axis=1) if len(xy0) else np.zeros(0)
            rows.append({"angle0": float(angle0), "angle1": float(angle1), "matches": len(xy0),
                         "correct": int((error < px).sum())})
    return sorted(rows, key=lambda row: (-row["correct"], -row["matches"]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", help="EVD-style folder (1/, 2/, h/), e.g. one written by synthetic_viewpoints.py")
    parser.add_argument("--pairs", required=True, help="pair names, comma-separated")
    parser.add_argument("--tilt", type=float, default=4.0, help="the views' tilt (both images)")
    parser.add_argument("--step", type=float, default=18.0, help="degrees between the views' rotations")
    parser.add_argument("--method", default="aliked-lg", help="the base pipeline (a method's name)")
    parser.add_argument("--px", type=float, default=10.0, help="a match is correct within this many px of the GT")
    parser.add_argument("--out", type=Path, default=None, help="JSON file to write (every angle pair of each pair)")
    args = parser.parse_args()
    if args.tilt < 1.0 or args.step <= 0.0:
        parser.error("need --tilt >= 1 and --step > 0")
    pairs = {pair.name.split("/")[-1]: pair for pair in load_dataset(f"evd:{args.folder}")}
    names = [name.strip() for name in args.pairs.split(",") if name.strip()]
    if unknown := [name for name in names if name not in pairs]:
        parser.error(f"no pair {', '.join(unknown)} in {args.folder} (it has {', '.join(sorted(pairs))})")
    matcher = Matcher(make_config(args.method, **{"views.mode": "off"}))
    report = {"tilt": args.tilt, "step": args.step, "method": args.method, "px": args.px, "pairs": {}}
    for name in names:
        image0, image1 = load_pair_images(pairs[name])
        rows = angle_pairs(matcher, image0, image1, pairs[name].H, args.tilt, args.step, args.px)
        report["pairs"][name] = rows
        best = ", ".join(f"{r['correct']} of {r['matches']} at {r['angle0']:g}/{r['angle1']:g}" for r in rows[:3])
        print(f"{name}: best view pairs (correct of matches at angle0/angle1): {best}", flush=True)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1))
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
