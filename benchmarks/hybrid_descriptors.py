"""Hybrid features on the hard pairs: HarrisZ+ keypoints described by ALIKED's descriptor head (on its dense map),
against ALIKED's own keypoints and Hz+ alone, each matched once on the whole images (no Slime, no views).

    python benchmarks/hybrid_descriptors.py DATA/hard [--max-side 1024] [--keypoints 4096]
        [--out results/hybrid_descriptors.json]

Variants, all on the images shrunk to ``--max-side`` px on the longer side:
- ``aliked-lg`` / ``aliked-nn``: ALIKED's keypoints and descriptors, LightGlue (ALIKED weights) / mutual nearest
  neighbours with the ratio test (0.9).
- ``hz+``: the Hz+ base pipeline alone (HarrisZ+, AffNet, OriNet, its descriptor, Blob matching, DTM).
- ``hybrid-lg`` / ``hybrid-nn``: HarrisZ+'s keypoints (upright, at most ``--keypoints``) described by ALIKED at
  their positions, then LightGlue / mutual NN as above.
- ``union-lg``: ALIKED's keypoints and the hybrid's together, LightGlue.

Each is scored by the datasets' protocols as ``slime bench`` scores them, at its defaults (``BenchConfig``:
OpenCV MAGSAC++ at 3 px, 10,000 iterations; mAA of the given order and the mean over 10 orders of the matches). The summary is the mean over
the pairs of each set.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from slime_match.eval.bench_config import BenchConfig
from slime_match.eval.datasets.load import load_dataset
from slime_match.eval.scoring import evaluate_protocol, pair_gt
from slime_match.io import load_image
from slime_match.pipelines import BaseConfig
from slime_match.pipelines.learned import unit_frames
from slime_match.pipelines.registry import make_base_pipeline
from slime_match.resize import resize_image, working_factor
from slime_match.types import Features

VARIANTS = ("aliked-lg", "aliked-nn", "hz+", "hybrid-lg", "hybrid-nn", "union-lg")


def joined(a: Features, b: Features) -> Features:
    """The keypoints of ``a`` followed by those of ``b`` (upright unit frames)."""
    laf = unit_frames(torch.cat([a.xy, b.xy]))
    return Features(laf, torch.cat([a.descriptors, b.descriptors]), torch.cat([a.response, b.response]), laf)


class Variants:
    """The pipelines of every variant, built once."""

    def __init__(self, keypoints: int) -> None:
        self.aliked = make_base_pipeline(BaseConfig(name="aliked-lg", max_keypoints=keypoints))
        self.aliked_nn = make_base_pipeline(BaseConfig(name="aliked-nn", max_keypoints=keypoints))
        self.hz = make_base_pipeline(BaseConfig(name="hz+", descriptor="hardtfeat", max_keypoints=keypoints))
        self.harrisz = make_base_pipeline(BaseConfig(name="hz+", descriptor="hardtfeat", upright=True,
                                                     max_keypoints=keypoints))

    def hybrid(self, image: np.ndarray) -> Features:
        """HarrisZ+ keypoints of an (H, W, 3) image with ALIKED's descriptors at them."""
        keypoints = self.harrisz.extract(image)
        laf = unit_frames(keypoints.xy)
        return Features(laf, self.aliked.describe_at(image, keypoints.xy.float()), keypoints.response, laf)

    def matches(self, image0: np.ndarray, image1: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Variant -> (K, 2), (K, 2) matched keypoints in the pixels of the two images."""
        size0, size1 = image0.shape[:2], image1.shape[:2]
        own = self.aliked.extract(image0), self.aliked.extract(image1)
        hz = self.hz.extract(image0), self.hz.extract(image1)
        hybrid = self.hybrid(image0), self.hybrid(image1)
        union = joined(own[0], hybrid[0]), joined(own[1], hybrid[1])
        runs = {"aliked-lg": (self.aliked, own), "aliked-nn": (self.aliked_nn, own), "hz+": (self.hz, hz),
                "hybrid-lg": (self.aliked, hybrid), "hybrid-nn": (self.aliked_nn, hybrid),
                "union-lg": (self.aliked, union)}
        out = {}
        for name, (pipeline, (f0, f1)) in runs.items():
            m = pipeline.match(f0, f1, size0, size1)
            out[name] = (f0.xy[torch.from_numpy(m.idx0)].double().cpu().numpy(),
                         f1.xy[torch.from_numpy(m.idx1)].double().cpu().numpy())
        return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("hard", type=Path, help="a folder holding wxbs/ and evd/ in the datasets' formats")
    parser.add_argument("--max-side", type=int, default=1024, help="working size: px on the longer side")
    parser.add_argument("--keypoints", type=int, default=4096, help="at most this many keypoints per image")
    parser.add_argument("--out", type=Path, default=Path("results/hybrid_descriptors.json"))
    args = parser.parse_args()
    variants, config = Variants(args.keypoints), BenchConfig()
    pairs: dict[str, dict] = {}
    for protocol in ("wxbs", "evd"):
        for pair in load_dataset(f"{protocol}:{args.hard / protocol}"):
            originals = load_image(pair.image0), load_image(pair.image1)
            (image0, frame0), (image1, frame1) = (
                resize_image(image, factor=working_factor(image.shape[1], image.shape[0], None, args.max_side))
                for image in originals)
            start = time.perf_counter()
            found = variants.matches(image0, image1)
            seconds = time.perf_counter() - start
            raw = {name: (frame0.to_original(x0), frame1.to_original(x1)) for name, (x0, x1) in found.items()}
            scores = evaluate_protocol(protocol, pair_gt(pair, originals), raw, config)
            key = f"{protocol}/{pair.name}"
            pairs[key] = {name: {"matches": len(raw[name][0]), "maa": result["maa"], "maa_mean": result["maa_mean"]}
                          for name, result in scores.items()}
            print(key, f"{seconds:.1f} s", json.dumps({k: [v["matches"], round(v["maa"], 3), round(v["maa_mean"], 3)]
                                                      for k, v in pairs[key].items()}), flush=True)
    summary = {protocol: {name: {k: float(np.mean([p[name][k] for key, p in pairs.items()
                                                   if key.startswith(protocol + "/")])) for k in ("maa", "maa_mean")}
                          for name in VARIANTS} for protocol in ("wxbs", "evd")}
    for protocol, rows in summary.items():
        for name, row in rows.items():
            print(f"{protocol} {name}: mAA {row['maa']:.3f}, over {config.protocol_orders} orders "
                  f"{row['maa_mean']:.3f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"max_side": args.max_side, "keypoints": args.keypoints, "pairs": pairs,
                                    "summary": summary}, indent=1) + "\n")


if __name__ == "__main__":
    main()
