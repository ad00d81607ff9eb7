"""Speed of a learned base pipeline alone against kornia's own pipeline on the same images, in one process.

    python benchmarks/bench_learned.py [DATA/hard/wxbs] [--method aliked-lg] [--repeat 3] \
        [--out results/bench_learned.json]

For every pair of a WxBS-style folder (``01.*``, ``02.*``): ``slime_match.Matcher`` with the method's preset
(1024 px working size, 4096 keypoints, no views, no RANSAC, from the image files) against kornia's pipeline
written as kornia's documentation does: the images read with OpenCV, those over 1024 px on the longer side
shrunk to it with kornia's ``resize`` (antialiased), kornia's ALIKED / DISK / XFeat and its LightGlue /
LighterGlue with the same weights (mutual NN with ratio 0.9, kornia's "smnn", for the -nn methods). Each side runs ``--repeat`` times per pair after a warm-up pair; the minimum per pair is kept,
and the JSON holds the per-pair seconds, their sums, the ratio ours / kornia's and the match counts. The
learned weights come from kornia's cache (``TORCH_HOME``; see ``scripts/fetch_learned_weights.py``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if "TORCH_HOME" not in os.environ and (ROOT / ".cache" / "torch" / "hub").is_dir():
    os.environ["TORCH_HOME"] = str(ROOT / ".cache" / "torch")

import cv2
import numpy as np
import torch

import slime_match as sm
from slime_match.eval.code_version import code_version
from slime_match.features import learned_weights
from slime_match.pipelines.learned import LEARNED_BASES


class KorniaPipeline:
    """kornia's extractor and matcher of a learned base, on images resized by kornia to 1024 px."""

    def __init__(self, method: str, max_keypoints: int = 4096, side: int = 1024) -> None:
        import kornia.feature as KF

        self.extractor, matcher = LEARNED_BASES[method]
        self.side, self.max_keypoints = side, max_keypoints
        if self.extractor == "aliked":
            self.network = KF.ALIKED.from_pretrained("aliked-n16", max_num_keypoints=max_keypoints).eval()
        elif self.extractor == "disk":
            self.network = KF.DISK.from_pretrained("depth").eval()
        else:
            self.network = KF.XFeat.from_pretrained(top_k=max_keypoints).eval()
        self.glue = KF.LightGlue(self.extractor).eval() if matcher == "lightglue" else None
        self.matcher = None if self.glue is not None else KF.DescriptorMatcher("smnn", 0.9)

    def features(self, path: Path) -> tuple[torch.Tensor, torch.Tensor, tuple[int, int]]:
        import kornia

        image = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
        tensor = kornia.image.image_to_tensor(np.ascontiguousarray(image), keepdim=False).float() / 255.0
        if max(tensor.shape[-2:]) > self.side:  # shrunk only, as the matcher's working size
            tensor = kornia.geometry.resize(tensor, self.side, side="long", antialias=True)
        if self.extractor == "aliked":
            found = self.network(tensor)[0]
            return found.keypoints, found.descriptors, tuple(tensor.shape[-2:])
        if self.extractor == "disk":
            found = self.network(tensor, n=self.max_keypoints, pad_if_not_divisible=True)[0]
            return found.keypoints, found.descriptors, tuple(tensor.shape[-2:])
        found = self.network.detectAndCompute(tensor)[0]
        return found["keypoints"], found["descriptors"], tuple(tensor.shape[-2:])

    @torch.inference_mode()
    def __call__(self, path0: Path, path1: Path) -> int:
        (k0, d0, s0), (k1, d1, s1) = self.features(path0), self.features(path1)
        if self.glue is None:
            return len(self.matcher(d0, d1)[1])

        def side(k, d, size):
            return {"keypoints": k[None], "descriptors": d[None],
                    "image_size": torch.tensor([[size[1], size[0]]], dtype=torch.float32)}

        return len(self.glue({"image0": side(k0, d0, s0), "image1": side(k1, d1, s1)})["matches"][0])


def pairs_of(folder: Path) -> list[tuple[str, Path, Path]]:
    found = []
    for corrs in sorted(folder.rglob("corrs.txt")):
        images = sorted(p for p in corrs.parent.iterdir() if p.stem in ("01", "02"))
        if len(images) == 2:
            found.append((corrs.parent.name, *images))
    return found


def best_of(run, repeat: int) -> tuple[float, int]:
    times, count = [], 0
    for _ in range(repeat):
        start = time.perf_counter()
        count = run()
        times.append(time.perf_counter() - start)
    return min(times), count


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", nargs="?", type=Path, default=ROOT.parent / "shared" / "data" / "hard" / "wxbs")
    parser.add_argument("--method", default="aliked-lg", choices=tuple(LEARNED_BASES))
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "bench_learned.json")
    args = parser.parse_args(argv)
    pairs = pairs_of(args.data)
    if not pairs:
        print(f"no WxBS-style pairs (01.*, 02.*, corrs.txt) under {args.data}", file=sys.stderr)
        return 2
    ours = sm.Matcher(sm.make_config(args.method, views="off", device="cpu"), feature_cache_mb=0)
    theirs = KorniaPipeline(args.method)
    ours(pairs[0][1], pairs[0][2]), theirs(pairs[0][1], pairs[0][2])  # warm-up
    rows = []
    for name, path0, path1 in pairs:
        ours_s, ours_n = best_of(lambda a=path0, b=path1: len(ours(a, b).scores), args.repeat)
        theirs_s, theirs_n = best_of(lambda a=path0, b=path1: theirs(a, b), args.repeat)
        rows.append({"pair": name, "ours_s": round(ours_s, 4), "kornia_s": round(theirs_s, 4),
                     "ours_matches": ours_n, "kornia_matches": theirs_n})
        print(f"{name:20s} ours {ours_s:6.2f} s ({ours_n} matches)   "
              f"kornia {theirs_s:6.2f} s ({theirs_n} matches)")
    total_ours, total_theirs = (sum(r[key] for r in rows) for key in ("ours_s", "kornia_s"))
    report = {"method": args.method, "data": str(args.data), "repeat": args.repeat, "pairs": rows,
              "ours_s": round(total_ours, 3), "kornia_s": round(total_theirs, 3),
              "ratio": round(total_ours / total_theirs, 3), "torch_threads": torch.get_num_threads(),
              "machine": platform.processor() or platform.machine(), "code_version": code_version(),
              "weights": str(learned_weights.checkpoint_folder()), "date": datetime.now(UTC).isoformat()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1))
    print(f"ours {total_ours:.2f} s, kornia {total_theirs:.2f} s: ratio {report['ratio']:.2f} -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
