"""Descriptor cost per patch: HardNet, TFeat and RootSIFT on the same 32 x 32 patches, on one device.

    python benchmarks/bench_descriptors.py [--device cuda] [--patches 65536] [--out results/bench_descriptors.json]

What it is for: Slime describes tens of thousands of patches a pair (67,283 for graf 1->3 at 640x480 with
TFeat), so the descriptor's cost per patch, times that count, is what swapping descriptors changes in its
run time. Each descriptor runs as :class:`slime_match.features.descriptors.Descriptor` does (inference-folded
network, batches of ``DescriptorConfig.batch_size``). A network whose weights are not on disk runs with
kornia's random initialisation instead, and its record says ``"weights": "random (timing only)"``: its
arithmetic, hence its time, does not depend on the weights; its descriptors mean nothing. The library itself
never does this (it raises ``WeightsNotFoundError``).

Timing: the median of ``--repeat`` passes over all patches, after one warm-up pass; CUDA is synchronised
before each clock read. Patches are random noise blurred like image patches (content does not change the
time of a network).
"""

from __future__ import annotations

import argparse
import importlib
import json
import statistics
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

from slime_match._runtime.openmp import set_default_spin_count

set_default_spin_count()  # as the slime command does, before torch loads

ROOT = Path(__file__).resolve().parents[1]

import torch
import torch.nn.functional as F

from slime_match.eval.code_version import code_version
from slime_match.features.descriptors import Descriptor, DescriptorConfig
from slime_match.features.inference import fuse_for_inference
from slime_match.features.weights import SPECS, is_cached

NAMES = ("hardnet", "tfeat", "rootsift")


def make_descriptor(name: str, device: torch.device) -> tuple[Descriptor, str]:
    """The descriptor as the library builds it, or for an uncached network the same architecture with random
    weights; and which weights it has."""
    if name == "rootsift":
        return Descriptor("rootsift", device), "none (handcrafted)"
    if is_cached(name):
        return Descriptor(name, device), "trained"
    spec = SPECS[name]
    descriptor = Descriptor.__new__(Descriptor)
    descriptor.method, descriptor.config = name, DescriptorConfig()
    net = getattr(importlib.import_module(spec.module), spec.cls)(pretrained=False)
    descriptor.net = fuse_for_inference(net.eval().to(device))
    return descriptor, "random (timing only)"


def time_descriptor(descriptor: Descriptor, patches: torch.Tensor, repeat: int) -> list[float]:
    """Seconds of each pass describing ``patches`` (N, 1, 32, 32) in the library's batches."""
    batch = descriptor.config.batch_size

    def one_pass() -> float:
        if patches.is_cuda:
            torch.cuda.synchronize(patches.device)
        start = time.perf_counter()
        for part in patches.split(batch):
            descriptor.describe_patches(part)
        if patches.is_cuda:
            torch.cuda.synchronize(patches.device)
        return time.perf_counter() - start

    one_pass()  # warm-up: kernels, allocator, cuDNN algorithm choice
    return [one_pass() for _ in range(repeat)]


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    parser.add_argument("--patches", type=int, default=65536, help="patches per pass")
    parser.add_argument("--repeat", type=int, default=5, help="timed passes (median reported)")
    parser.add_argument("--out", default=str(ROOT / "results" / "bench_descriptors.json"))
    args = parser.parse_args(argv)
    if args.device == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda: no CUDA device available")
    device = torch.device(args.device)
    g = torch.Generator().manual_seed(0)
    patches = F.avg_pool2d(torch.rand(args.patches, 1, 36, 36, generator=g), 5, 1).to(device)
    report = {
        "meta": {"date": datetime.now(UTC).isoformat(timespec="seconds"), "code_version": code_version(),
                 "command": " ".join([Path(sys.argv[0]).name, *(argv if argv is not None else sys.argv[1:])]),
                 "device": torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu",
                 "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
                 "patches": args.patches, "batch_size": DescriptorConfig().batch_size},
        "descriptors": {},
    }
    print(f"device {report['meta']['device']}, {args.patches} patches a pass, batches of "
          f"{report['meta']['batch_size']}")
    for name in NAMES:
        descriptor, weights = make_descriptor(name, device)
        seconds = time_descriptor(descriptor, patches, args.repeat)
        median = statistics.median(seconds)
        report["descriptors"][name] = {"weights": weights, "seconds": [round(s, 4) for s in seconds],
                                       "ms_per_1000_patches": round(1000 * median / args.patches * 1000, 3)}
        print(f"{name:9s} {report['descriptors'][name]['ms_per_1000_patches']:8.3f} ms / 1000 patches  "
              f"(weights: {weights})")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(json.dumps(report, indent=2))
    tmp.replace(out)
    print(f"wrote {out}")
    return report


if __name__ == "__main__":
    main()
