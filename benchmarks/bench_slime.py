"""Slime's speed next to its quality: per-stage seconds, peak memory, correct matches, the base Hz+ on the same
pair, and the block detection ablation (merged vs scale vs block, tiles); OpenCV SIFT as a same-process reference.

    python benchmarks/bench_slime.py [--out results/bench_slime.json] [--descriptor tfeat] [--skip-ablation]
                                     [--skip-fast] [--skip-fine] [--skip-large] [--learned]
    python benchmarks/bench_slime.py --device cuda --descriptor hardnet      # the GPU run

Pairs: graf img1 -> img3 resized (cv2.INTER_AREA) to 640x480 and 1200x900; the GT homography is scaled with
the resize in the pixel-centre convention ``x_s = (x + 0.5) f - 0.5`` (per axis: graf is 800x640).

Runs (each Slime run is timed once, after the base Hz+ on the same pair and config has warmed the models; one
untimed ``slime-fast`` call first compiles Slime's kernels, which a fresh machine has not cached):
* Slime, AffNet + OriNet + ``--descriptor`` (TFeat by default), at 640x480 and 1200x900;
* weight-free Slime (Baumberg + gradient orientation + RootSIFT) at 640x480;
* the ``slime-fast`` preset (block scales 1, 2 instead of the paper's 1, 2, 3), learned and weight-free, 640x480;
* the ``slime-fine`` preset (block scales 1-4), learned and weight-free, 640x480 (no target: it trades time
  for coverage);
* the ablation at 640x480, learned and weight-free: the default "merged" detection (each 256 px block crop
  detected on its own, keypoints shared by overlapping blocks described once) vs "scale" (one detection per
  block scale) vs "block" (each block crop detected and described on its own, the paper's prototype), and
  vs tiles detected per crop (``tile_detection="block"``) -- same pair, same everything else;
* with ``--learned`` (ALIKED and LightGlue weights in ``TORCH_HOME``: ``scripts/fetch_learned_weights.py``):
  ALIKED + LightGlue alone (``aliked-lg``), then Slime on it (``slime-aliked``), at 640x480, and the time of
  ``slime-aliked`` over the default Slime run of the same pair;
* OpenCV SIFT (8000 features) detect+describe of the same images.

Quality: matches correct when the two-sided GT reprojection error is below t (paper t = 15 px, and 3 px),
precision = correct / matches; coverage (paper, t = 15 px) over the GT valid area; "distinct_1px" = matches
left when near-duplicates (both ends within 1 px, L-inf) count once (overlapping blocks can find one
corner twice at sub-pixel offsets, which the final exact-duplicate merge keeps).
Memory: "peak_rss_mb" = the process's resident-set high-water mark during the call (VmHWM, reset before
it through /proc/self/clear_refs), "workers_maxrss_mb" = the largest resident set of any forked block-pair
worker so far in this process (RUSAGE_CHILDREN cannot be reset; pages shared with the parent included),
"cuda_peak_mb" = torch's allocator peak during the call. Forks: "fork_ms_after_warm_up" = the time this process
takes to fork a child (Slime's workers are forked; on a GPU machine with a CUDA context a fork took 25 ms),
with the kernel's transparent huge page mode. No pytest test times anything: this script
is the timing record, run once on a quiet machine where possible (load average recorded).
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import platform
import resource
import sys
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from slime_match._runtime.openmp import set_default_spin_count

set_default_spin_count()  # as the slime command does, before torch loads

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
if "TORCH_HOME" not in os.environ and (SHARED / "weights").is_dir():
    os.environ["TORCH_HOME"] = str((SHARED / "weights").resolve())

import cv2
import numpy as np
import torch
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from slime_match.config import make_config
from slime_match.eval.code_version import code_version
from slime_match.eval.metrics import DEFAULTS, correct_matches_homography, coverage, valid_area_homography
from slime_match.io import load_image
from slime_match.matcher import Matcher

TARGETS_S = {
    "slime_learned_640x480": 20.0,
    "slime_learned_1200x900": 60.0,
    "slime_weight-free_640x480": 8.0,
    "slime_cuda_640x480": 3.0,
}
WEIGHT_FREE = {"shape": "baumberg", "orientation": "gradient", "descriptor": "rootsift"}
SIZES = {"640x480": (640, 480), "1200x900": (1200, 900)}
THRESHOLDS = (DEFAULTS.t_perp, 3.0)


# ---------------------------------------------------------------------------------------------- data
def load_pair(data: Path, width: int, height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """graf img1, img3 as float RGB resized to (width, height) and the GT homography between the resized images."""
    folder = data / "oxford_graf"
    if not (folder / "img1.png").is_file():
        raise SystemExit(f"graf images not found in {folder}: pass --data <folder holding oxford_graf/>")
    images, scales = [], []
    for name in ("img1.png", "img3.png"):
        image = load_image(folder / name)
        sx, sy = width / image.shape[1], height / image.shape[0]
        scales.append(np.array([[sx, 0, 0.5 * sx - 0.5], [0, sy, 0.5 * sy - 0.5], [0, 0, 1.0]]))
        images.append(np.ascontiguousarray(cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)))
    h = scales[1] @ np.loadtxt(folder / "H1to3p") @ np.linalg.inv(scales[0])
    return images[0], images[1], h


# ---------------------------------------------------------------------------------------------- measuring
def _status_mb(key: str) -> float | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def _reset_peak() -> None:
    """Return freed heap to the OS (glibc) and reset VmHWM to the current resident set (Linux)."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        pass


def _children_maxrss_mb() -> float:
    kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return kb / 2**20 if sys.platform == "darwin" else kb / 1024


def fork_cost_ms(rounds: int = 5) -> float | None:
    """Median ms for this process to fork a child that exits at once (None without ``os.fork``).

    Slime's workers are forked processes, and a fork copies the parent's page tables: its cost grows with the
    parent's resident set and mappings (on an H100 machine a fork took 25 ms in a process holding a CUDA
    context, 62 forks a call), and huge pages (``transparent_hugepage``) cut it.
    """
    if not hasattr(os, "fork"):
        return None
    times = []
    for _ in range(rounds):
        start = time.perf_counter()
        pid = os.fork()
        if pid == 0:
            os._exit(0)
        times.append(time.perf_counter() - start)
        os.waitpid(pid, 0)
    return round(float(np.median(times)) * 1e3, 2)


def transparent_hugepage() -> str | None:
    """The kernel's transparent huge page mode (the bracketed word of its sysfs setting), None off Linux."""
    try:
        text = Path("/sys/kernel/mm/transparent_hugepage/enabled").read_text()
    except OSError:
        return None
    return text[text.find("[") + 1:text.find("]")] if "[" in text else text.strip()


def distinct_matches(xy0: np.ndarray, xy1: np.ndarray, radius: float = 1.0) -> int:
    """Matches left when near-duplicates (both ends within ``radius`` px, chained) count once."""
    if len(xy0) == 0:
        return 0
    pairs = cKDTree(np.hstack([xy0, xy1])).query_pairs(radius, p=np.inf, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(xy0), len(xy0)))
    return int(connected_components(graph, directed=False)[0])


def quality(xy0: np.ndarray, xy1: np.ndarray, h: np.ndarray, shape: tuple[int, int]) -> dict[str, Any]:
    """Correct matches and precision at each threshold, the paper's coverage (t = 15 px), and the number of
    distinct matches (near-duplicates within 1 px at both ends merged)."""
    out: dict[str, Any] = {"matches": len(xy0), "distinct_1px": distinct_matches(xy0, xy1)}
    for t in THRESHOLDS:
        ok = correct_matches_homography(xy0, xy1, h, t=t)
        out[f"correct_{t:g}px"] = int(ok.sum())
        out[f"precision_{t:g}px"] = round(float(ok.mean()), 4) if len(ok) else 0.0
    ok = correct_matches_homography(xy0, xy1, h, t=DEFAULTS.t_perp)
    valid0, valid1 = valid_area_homography(h, shape, shape)
    out["coverage"] = round(coverage(xy0[ok], xy1[ok], shape, shape, valid0, valid1, t=DEFAULTS.t_perp), 4)
    return out


def run_matcher(matcher: Matcher, pair: tuple[np.ndarray, np.ndarray, np.ndarray]) -> dict[str, Any]:
    """One timed call of a configured matcher on a pair, with its summary's stages, counts, memory and quality."""
    a, b, h = pair
    if matcher.device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(matcher.device)
    _reset_peak()
    rss0 = _status_mb("VmRSS")
    start = time.perf_counter()
    result = matcher(a, b)
    wall = time.perf_counter() - start
    peak = _status_mb("VmHWM")
    record: dict[str, Any] = {
        "wall_s": round(wall, 3),
        "seconds": result.summary["seconds"],
        "counts": result.summary["counts"],
        "peak_rss_mb": None if peak is None else round(peak, 1),
        "rss_before_mb": None if rss0 is None else round(rss0, 1),
        **quality(result.keypoints0, result.keypoints1, h, a.shape[:2]),
    }
    if matcher.config.method == "slime":
        record["workers_maxrss_mb"] = round(_children_maxrss_mb(), 1)
    if matcher.device.type == "cuda":
        record["cuda_peak_mb"] = round(torch.cuda.max_memory_allocated(matcher.device) / 2**20, 1)
    return record


def warm_up(pair, device: str, options: dict[str, Any]) -> float:
    """One untimed ``slime-fast`` call: loads the models and compiles Slime's numba kernels, which a fresh
    machine (no kernel cache on disk) would otherwise compile inside the first timed run. Returns seconds."""
    start = time.perf_counter()
    Matcher(make_config("slime-fast", device=device, **options))(*pair[:2])
    return round(time.perf_counter() - start, 2)


def bench_slime_vs_base(name: str, options: dict[str, Any], pair, device: str, target: float | None,
                        preset: str = "slime") -> dict:
    """Base Hz+ (also the warm-up) then Slime (``preset``) with the same base options on one pair."""
    base = run_matcher(Matcher(make_config("hz+", device=device, **options)), pair)
    slime = run_matcher(Matcher(make_config(preset, device=device, **options)), pair)
    out = {"preset": preset, "options": options, "slime": slime, "base": base,
           "slime_over_base_time": round(slime["wall_s"] / max(base["wall_s"], 1e-9), 2)}
    if target is not None:
        out["target_s"] = target
        out["meets_target"] = slime["wall_s"] <= target
    _print_comparison(name, out)
    return out


ABLATIONS = {"scale": {"detection": "scale"}, "block": {"detection": "block"},
             "block_tiles": {"tile_detection": "block"}}


def bench_ablation(label: str, options: dict, pair, device: str, default_record: dict) -> dict:
    """Slime with ``options`` and each detection choice of ``ABLATIONS``, next to the default run of the same
    pair ("merged" blocks, "scale" tiles)."""
    out = {"default": default_record}
    for name, option in ABLATIONS.items():
        out[name] = run_matcher(Matcher(make_config("slime", device=device, **option, **options)), pair)
        out[f"{name}_over_default_time"] = round(out[name]["wall_s"] / max(default_record["wall_s"], 1e-9), 2)
    _print_ablation(label, out)
    return out


def bench_learned_base(pair, device: str, default_record: dict) -> dict:
    """ALIKED + LightGlue alone (which loads the networks) then Slime on it, next to the default Slime run of the
    same pair; then Slime on it with DISK's planes pooled (``slime-aliked-disk``, timed after one untimed call)."""
    base = run_matcher(Matcher(make_config("aliked-lg", device=device)), pair)
    slime = run_matcher(Matcher(make_config("slime-aliked", device=device)), pair)
    out = {"preset": "slime-aliked", "slime": slime, "base": base,
           "slime_over_base_time": round(slime["wall_s"] / max(base["wall_s"], 1e-9), 2),
           "over_default_slime_time": round(slime["wall_s"] / max(default_record["wall_s"], 1e-9), 2)}
    _print_comparison("Slime on ALIKED + LightGlue (slime-aliked) 640x480, base aliked-lg", out)
    print(f"slime-aliked / default Slime time: {out['over_default_slime_time']:.2f}x")
    pooled_matcher = Matcher(make_config("slime-aliked-disk", device=device), feature_cache_mb=0)
    pooled_matcher(*pair[:2])  # untimed: DISK's first call
    pooled = run_matcher(pooled_matcher, pair)
    out["pooled_disk"] = pooled
    out["pooled_over_slime_time"] = round(pooled["wall_s"] / max(slime["wall_s"], 1e-9), 2)
    print(f"slime-aliked-disk (DISK's planes pooled): {pooled['wall_s']:.1f} s, {out['pooled_over_slime_time']:.2f}x "
          f"slime-aliked; {pooled['counts'].get('pooled_planes')} pooled planes")
    return out


def bench_opencv_sift(pairs: dict[str, tuple]) -> dict:
    sift = cv2.SIFT_create(nfeatures=8000)
    out = {}
    for size, (a, b, _) in pairs.items():
        greys = [cv2.cvtColor((im * 255 + 0.5).astype(np.uint8), cv2.COLOR_RGB2GRAY) for im in (a, b)]
        sift.detectAndCompute(greys[0], None)  # warm-up
        start = time.perf_counter()
        features = [len(sift.detectAndCompute(g, None)[0]) for g in greys]
        out[size] = {"seconds_pair": round(time.perf_counter() - start, 3), "features": features}
        print(f"OpenCV SIFT {size}: detect+describe of both images {out[size]['seconds_pair']:.2f} s, "
              f"features {features}")
    return out


# ---------------------------------------------------------------------------------------------- printing
def _quality_line(r: dict) -> str:
    t = f"{DEFAULTS.t_perp:g}"
    return (f"matches {r['matches']} (distinct@1px {r['distinct_1px']}), correct@{t}px {r[f'correct_{t}px']} (precision {r[f'precision_{t}px']:.3f}), "
            f"correct@3px {r['correct_3px']} (precision {r['precision_3px']:.3f}), coverage {r['coverage']:.3f}")


def _print_comparison(name: str, out: dict) -> None:
    slime, base = out["slime"], out["base"]
    target = f"   target <= {out['target_s']:g} s: {'met' if out['meets_target'] else 'MISSED'}" if "target_s" in out else ""
    print(f"\n== {name}")
    print(f"Slime  {slime['wall_s']:8.2f} s{target}")
    print("   stages: " + ", ".join(f"{k} {v:.2f}" for k, v in slime["seconds"].items()))
    print(f"   peak RSS {slime['peak_rss_mb']} MB (workers {slime.get('workers_maxrss_mb')} MB); "
          f"{_quality_line(slime)}")
    print("   counts: " + ", ".join(f"{k} {v}" for k, v in slime["counts"].items()))
    print(f"base   {base['wall_s']:8.2f} s   stages: " + ", ".join(f"{k} {v:.2f}" for k, v in base["seconds"].items()))
    print(f"   peak RSS {base['peak_rss_mb']} MB; {_quality_line(base)}")
    print(f"Slime / base time: {out['slime_over_base_time']:.1f}x")


def _print_ablation(label: str, out: dict) -> None:
    print(f"\n== ablation, Slime {label} 640x480: block detection merged (default) vs scale vs block, tiles")
    for key in ("default", *ABLATIONS):
        r = out[key]
        print(f"{key:9s} {r['wall_s']:8.2f} s  features {r['seconds'].get('features', 0):.2f} s, "
              f"block_pairs {r['seconds'].get('block_pairs', 0):.2f} s; {_quality_line(r)}")
    for key in ABLATIONS:
        print(f"{key} / default time: {out[f'{key}_over_default_time']:.2f}x")


# ---------------------------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cpu", choices=("cpu", "cuda"), help="torch device")
    parser.add_argument("--descriptor", default="tfeat", choices=("tfeat", "hardtfeat", "hardnet"),
                        help="descriptor of the learned (AffNet + OriNet) runs")
    parser.add_argument("--out", default="results/bench_slime.json", help="JSON output path")
    parser.add_argument("--data", default=str(SHARED / "data"), help="folder holding oxford_graf/")
    parser.add_argument("--skip-large", action="store_true", help="skip the 1200x900 run")
    parser.add_argument("--skip-fast", action="store_true", help="skip the slime-fast (block scales 1, 2) runs")
    parser.add_argument("--skip-fine", action="store_true", help="skip the slime-fine (block scales 1-4) runs")
    parser.add_argument("--skip-ablation", action="store_true",
                        help="skip the block and tile detection ablation (minutes on a CPU)")
    parser.add_argument("--learned", action="store_true",
                        help="also ALIKED + LightGlue alone, Slime on it (slime-aliked) and with DISK's planes pooled "
                             "(slime-aliked-disk) at 640x480 (their weights in TORCH_HOME)")
    args = parser.parse_args(argv)
    if args.device == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda: no CUDA device available")
    sizes = {k: v for k, v in SIZES.items() if not (args.skip_large and k == "1200x900")}
    pairs = {size: load_pair(Path(args.data), *wh) for size, wh in sizes.items()}
    learned = f"affnet+orinet+{args.descriptor}"
    report: dict[str, Any] = {
        "meta": {
            "date": datetime.now(UTC).isoformat(timespec="seconds"),
            "code_version": code_version(),
            "command": " ".join([Path(sys.argv[0]).name, *(argv if argv is not None else sys.argv[1:])]),
            "device": "cpu" if args.device == "cpu" else torch.cuda.get_device_name(0),
            "cpu_count": os.cpu_count(),
            "torch_threads": torch.get_num_threads(),
            "platform": platform.platform(),
            "torch": torch.__version__,
            "opencv": cv2.__version__,
            "load_average_start": [round(x, 2) for x in os.getloadavg()],
            "pair": "oxford graf img1 -> img3, cv2.INTER_AREA resize, GT homography scaled per axis",
            "timing": "wall_s = one call after the base Hz+ call on the same pair and config (model warm-up), "
            "all after one untimed slime-fast call (kernel compilation: warm_up_s); "
            "seconds = the matcher summary's per-stage seconds",
        },
        "targets_s": TARGETS_S,
        "runs": {},
    }
    print(f"device {report['meta']['device']}, load average {report['meta']['load_average_start']}")
    report["meta"]["warm_up_s"] = warm_up(pairs["640x480"], args.device, {"descriptor": args.descriptor})
    report["meta"]["transparent_hugepage"] = transparent_hugepage()
    report["meta"]["fork_ms_after_warm_up"] = fork_cost_ms()
    print(f"fork of this process: {report['meta']['fork_ms_after_warm_up']} ms "
          f"(transparent huge pages: {report['meta']['transparent_hugepage']}, resident set "
          f"{_status_mb('VmRSS') or 0:.0f} MB)")
    runs = report["runs"]
    for size in sizes:
        key = "slime_cuda_640x480" if args.device == "cuda" and size == "640x480" else f"slime_learned_{size}"
        runs[f"{learned} {size}"] = bench_slime_vs_base(f"Slime {learned} {size}", {"descriptor": args.descriptor},
                                                        pairs[size], args.device, TARGETS_S[key])
    weight_free = bench_slime_vs_base("Slime weight-free (Baumberg + gradient + RootSIFT) 640x480", WEIGHT_FREE,
                                      pairs["640x480"], args.device, TARGETS_S["slime_weight-free_640x480"])
    runs["weight-free 640x480"] = weight_free
    if not args.skip_fast:
        for label, options, key in ((learned, {"descriptor": args.descriptor}, "slime_learned_640x480"),
                                    ("weight-free", WEIGHT_FREE, "slime_weight-free_640x480")):
            runs[f"fast (block scales 1, 2) {label} 640x480"] = bench_slime_vs_base(
                f"Slime fast (block scales 1, 2) {label} 640x480", options, pairs["640x480"], args.device,
                TARGETS_S[key], preset="slime-fast")
    if not args.skip_fine:  # the speed targets are for the paper's three scales: none applies here
        for label, options in ((learned, {"descriptor": args.descriptor}), ("weight-free", WEIGHT_FREE)):
            runs[f"fine (block scales 1-4) {label} 640x480"] = bench_slime_vs_base(
                f"Slime fine (block scales 1-4) {label} 640x480", options, pairs["640x480"], args.device, None,
                preset="slime-fine")
    if not args.skip_ablation:
        for label, options, default in ((learned, {"descriptor": args.descriptor}, runs[f"{learned} 640x480"]),
                                        ("weight-free", WEIGHT_FREE, weight_free)):
            runs[f"ablation block detection merged vs scale vs block, tiles, {label} 640x480"] = bench_ablation(
                label, options, pairs["640x480"], args.device, default["slime"])
    if args.learned:
        runs["slime-aliked 640x480"] = bench_learned_base(pairs["640x480"], args.device,
                                                          runs[f"{learned} 640x480"]["slime"])
    print()
    runs["opencv_sift"] = bench_opencv_sift(pairs)
    report["meta"]["load_average_end"] = [round(x, 2) for x in os.getloadavg()]

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(json.dumps(report, indent=2))
    tmp.replace(out)
    print(f"\nwrote {out}  (load average {report['meta']['load_average_start']} -> "
          f"{report['meta']['load_average_end']})")
    return report


if __name__ == "__main__":
    main()
