"""Is a rotated pair hard for Slime because of the rotation or because of the rotated image's larger canvas?

    python benchmarks/canvas_probe.py hpatches/v_wormhole/1-3 hpatches/v_churchill/1-6 [--angle 45]
        [--methods "slime:descriptor=tfeat;hz+:descriptor=tfeat"] [--out results/canvas_probe.json]

A rotation by a non-multiple of 90 degrees puts image 2 on a larger canvas with black corners. Slime's block
scales follow the shorter side of the canvas (Sec. 3.1), so the content of that image is scaled down more
than image 1's in the block levels; the base pipelines detect over a scale space and do not care. For each
pair the methods run on three variants of image 2: the original, the original padded with black to the
rotated canvas (centred, no rotation), and the rotation. If padding alone costs Slime what the rotation
does, the canvas is the cause. Metrics: raw matches (no RANSAC), the paper's coverage and precision at
t = 15 px, padding and rotated-away corners outside the valid area.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from slime_match.eval.bench_config import BenchConfig
from slime_match.eval.datasets import Pair, rotated_pair, transform_view
from slime_match.eval.methods import make_method
from slime_match.eval.predictions import collect_pairs, load_pair_images, predict
from slime_match.eval.scoring import evaluate_pair, pair_gt
from slime_match.io import load_image


def padded_pair(pair: Pair, canvas: Pair) -> Pair:
    """``pair`` (image 1 an array) with image 1 centred, black around it, on the canvas of ``canvas``'s image 1
    (its rotation); the padding is excluded from the valid area through mask 1."""
    image = pair.image1
    h, w = image.shape[:2]
    nh, nw = canvas.image1.shape[:2]
    ox, oy = (nw - w) // 2, (nh - h) // 2
    padded = np.zeros((nh, nw) + image.shape[2:], image.dtype)
    padded[oy:oy + h, ox:ox + w] = image
    shift = np.array([[1.0, 0.0, ox], [0.0, 1.0, oy], [0.0, 0.0, 1.0]])
    mask1 = np.ones((nh, nw), bool)
    mask1[oy:oy + h, ox:ox + w] = False if pair.mask1 is None else pair.mask1
    name = canvas.name.replace("@rot", "@pad")
    return replace(transform_view(pair, 1, padded, shift), name=name, mask1=mask1)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("pairs", nargs="+", help="bench pair names, e.g. hpatches/v_wormhole/1-3")
    p.add_argument("--angle", type=float, default=45.0, help="rotation whose canvas is probed, degrees")
    p.add_argument("--methods", default="slime:descriptor=tfeat;hz+:descriptor=tfeat", help="';'-separated specs")
    p.add_argument("--out", type=Path, default=Path("results/canvas_probe.json"))
    args = p.parse_args()

    datasets = sorted({name.split("/")[0] for name in args.pairs})
    config = BenchConfig(datasets=datasets, methods=[], output=args.out.parent, thresholds=["none"])
    known = {pair.name: pair for _, pair in collect_pairs(config)}
    missing = [name for name in args.pairs if name not in known]
    if missing:
        p.error(f"unknown pairs {missing}; known: {sorted(known)}")
    methods = {spec: make_method(spec, seed=0) for spec in args.methods.split(";")}

    results: dict[str, dict[str, dict[str, float]]] = {}
    for name in args.pairs:
        original = replace(known[name], image1=load_image(known[name].image1))
        rotated = rotated_pair(original, args.angle)
        for variant in (original, padded_pair(original, rotated), rotated):
            images = load_pair_images(variant)
            raw = {}
            for spec, method in methods.items():
                pred = predict(method, variant, images)
                raw[spec] = (pred["keypoints0"], pred["keypoints1"])
            metrics, _ = evaluate_pair(pair_gt(variant, images), raw, config)
            results[variant.name] = {
                spec: {k: round(m["none"][k], 4) for k in ("coverage", "precision")} for spec, m in metrics.items()
            }
            print(variant.name, f"image 2 {images[1].shape[1]}x{images[1].shape[0]}",
                  "  ".join(f"{spec}: {r['coverage']:.3f} / {r['precision']:.3f}"
                            for spec, r in results[variant.name].items()), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"angle": args.angle, "methods": list(methods), "pairs": results}, indent=1))
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()
