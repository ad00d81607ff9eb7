"""Speed and memory of the base pipeline Hz+, stage by stage, next to OpenCV SIFT and the speed targets.

    python benchmarks/bench_base.py [--device cuda] [--out results/bench_base.json] [--threads 2,1] [--repeat 2]

Measured, once per torch/OpenCV thread count of ``--threads`` (default: torch's default count, then 1, the
load-robust figure on a shared machine):

* HarrisZ+ on graf img1 resized to 640x480 and 1200x900;
* Blob matching of 8000 x 8000 random unit 128-D descriptors (random positions in 1200x900);
* DTM on 12,000 synthetic candidates (half on a homography with 1 px noise, half random);
* a whole Hz+ pair, graf img1 -> img3 resized to 640x480, for AffNet+OriNet+TFeat, weight-free
  (Baumberg + gradient + RootSIFT) and AffNet+OriNet+HardNet when HardNet's weights are on disk; stages
  as in ``HzPlusPipeline.detect`` / ``match``: prepare (tensor + patch pyramid), HarrisZ+, shape,
  orientation, descriptor (both images), Blob, DTM; with match counts and correct matches (< 3 px on GT);
* OpenCV SIFT (8000 features) detect+describe on the same images;
* patches/s at batch 4000 of each patch stage: ours and the unmodified kornia module (before/after).

Times: a warm-up call, then the minimum (and median) over ``--repeat`` calls, CUDA synchronised.
Memory ("peak_mb"): the process's resident-set high-water mark during the first timed call minus the
resident set just before it. On Linux the mark is reset before each measurement (``/proc/self/clear_refs``),
after returning glibc's freed heap to the OS (``malloc_trim``), so it is the block's own peak; elsewhere it
falls back to the ``ru_maxrss`` increase, which reads 0 when
the block stays below an earlier peak ("peak_method" says which). It counts all CPU memory (torch, NumPy,
OpenCV); on CUDA, "cuda_peak_mb" is torch's allocator peak over the allocation before the call.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import platform
import resource
import statistics
import sys
import time
from collections.abc import Callable
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
from kornia.feature import PatchDominantGradientOrientation, SIFTDescriptor

from slime_match.eval.code_version import code_version
from slime_match.features.gradients import DominantGradientOrientation, SIFTPatchDescriptor
from slime_match.features.harrisz import detect_harrisz
from slime_match.features.inference import fuse_for_inference
from slime_match.features.weights import is_cached, load_model
from slime_match.matching.blob import blob_match
from slime_match.matching.dtm import dtm_filter
from slime_match.pipelines import BaseConfig, HzPlusPipeline

TARGETS = {
    "harrisz_640x480_s": 0.5,
    "pair_affnet+orinet+tfeat_s": 8.0,
    "pair_weight-free_s": 2.0,
    "patches_per_s_2_threads": {
        "affnet": 2400,
        "orinet": 2300,
        "tfeat": 3700,
        "hardnet": 1400,
        "rootsift": 11600,
    },
}
PAIR_CONFIGS = {
    "affnet+orinet+tfeat": {"descriptor": "tfeat"},
    "weight-free": {"shape": "baumberg", "orientation": "gradient", "descriptor": "rootsift"},
    "affnet+orinet+hardnet": {"descriptor": "hardnet"},
}


# ---------------------------------------------------------------------------------------------- measuring
def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _status_kb(key: str) -> int | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def _reset_peak() -> bool:
    """Return freed heap pages to the OS (glibc) and reset the VmHWM mark to the current resident set."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


def _maxrss_kb() -> int:
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb // 1024 if sys.platform == "darwin" else kb  # bytes on macOS


def measure(
    fn: Callable[[], Any], device: torch.device, repeat: int, warmup: bool = True
) -> tuple[dict, Any]:
    """Time ``fn`` (warm-up, then ``repeat`` calls) and its memory peak on the first timed call.

    Returns:
        ({"seconds", "median_s", "peak_mb", "peak_method"[, "cuda_peak_mb"]}, the last result of fn).
    """
    if warmup:
        fn()
    _sync(device)
    exact = _reset_peak() and _status_kb("VmHWM") is not None
    rss0 = _status_kb("VmRSS") if exact else _maxrss_kb()
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
        cuda0 = torch.cuda.memory_allocated(device)
    times, out = [], None
    for i in range(repeat):
        start = time.perf_counter()
        out = fn()
        _sync(device)
        times.append(time.perf_counter() - start)
        if i == 0:
            peak = (_status_kb("VmHWM") if exact else _maxrss_kb()) - rss0
            if device.type == "cuda":
                cuda_peak = torch.cuda.max_memory_allocated(device) - cuda0
    record = {
        "seconds": round(min(times), 4),
        "median_s": round(statistics.median(times), 4),
        "peak_mb": round(max(peak, 0) / 1024, 1),
        "peak_method": "VmHWM-reset" if exact else "ru_maxrss-delta",
    }
    if device.type == "cuda":
        record["cuda_peak_mb"] = round(cuda_peak / 2**20, 1)
    return record, out


# ---------------------------------------------------------------------------------------------- data
def _load_graf(data: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """graf img1, img3 (uint8 BGR) and the GT homography 1 -> 3, from the data folder or Debian's opencv-doc."""
    folder = data / "oxford_graf"
    if (folder / "img1.png").is_file():
        return (
            cv2.imread(str(folder / "img1.png")),
            cv2.imread(str(folder / "img3.png")),
            np.loadtxt(folder / "H1to3p"),
        )
    doc = Path("/usr/share/doc/opencv-doc/examples/data")
    if (doc / "graf1.png").is_file():
        fs = cv2.FileStorage(str(doc / "H1to3p.xml"), cv2.FILE_STORAGE_READ)
        h = fs.getFirstTopLevelNode().mat()
        return cv2.imread(str(doc / "graf1.png")), cv2.imread(str(doc / "graf3.png")), h
    raise SystemExit(
        f"graf images not found in {folder} nor {doc}: pass --data <folder holding oxford_graf/>"
    )


def _resize(bgr: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Float RGB in [0, 1] resized to (width, height), and the pixel-centre scaling matrix to it."""
    sx, sy = width / bgr.shape[1], height / bgr.shape[0]
    scale = np.array([[sx, 0, 0.5 * sx - 0.5], [0, sy, 0.5 * sy - 0.5], [0, 0, 1]])
    rgb = cv2.resize(bgr, (width, height), interpolation=cv2.INTER_AREA)[:, :, ::-1]
    return np.ascontiguousarray(rgb, dtype=np.float32) / 255.0, scale


def _grey_u8(rgb: np.ndarray) -> np.ndarray:
    return cv2.cvtColor((rgb * 255 + 0.5).astype(np.uint8), cv2.COLOR_RGB2GRAY)


def _unmatched(xy: np.ndarray, used: np.ndarray) -> np.ndarray:
    mask = np.ones(len(xy), bool)
    mask[used] = False
    return xy[mask]


# ---------------------------------------------------------------------------------------------- benchmarks
def bench_harrisz(images: dict[str, np.ndarray], device: torch.device, repeat: int) -> dict:
    out = {}
    for size, rgb in images.items():
        tensor = torch.from_numpy(rgb.transpose(2, 0, 1).copy()).to(device)
        rec, kp = measure(lambda t=tensor: detect_harrisz(t), device, repeat)
        out[size] = {**rec, "keypoints": len(kp)}
    return out


def bench_blob(device: torch.device, repeat: int, n: int = 8000) -> dict:
    g = torch.Generator().manual_seed(0)
    desc = [
        torch.nn.functional.normalize(torch.randn(n, 128, generator=g), dim=1).to(device) for _ in range(2)
    ]
    xy = [(torch.rand(n, 2, generator=g) * torch.tensor([1200.0, 900.0])).to(device) for _ in range(2)]
    rec, matches = measure(lambda: blob_match(desc[0], desc[1], xy[0], xy[1]), device, repeat)
    return {**rec, "descriptors": n, "candidates": len(matches)}


def bench_dtm(device: torch.device, repeat: int, k: int = 12000) -> dict:
    rng = np.random.default_rng(0)
    size = (900, 1200)
    h = np.array([[0.9, 0.1, 40.0], [-0.08, 0.95, 30.0], [1e-5, 2e-5, 1.0]])
    xy0 = rng.uniform([0, 0], [1200, 900], (k, 2))
    p = np.c_[xy0, np.ones(k)] @ h.T
    xy1 = p[:, :2] / p[:, 2:] + rng.normal(0, 1.0, (k, 2))
    outlier = np.arange(k) >= k // 2
    xy1[outlier] = rng.uniform([0, 0], [1200, 900], (int(outlier.sum()), 2))
    scores = rng.uniform(0, 1, k) + 0.3 * outlier
    others = [rng.uniform([0, 0], [1200, 900], (4000, 2)) for _ in range(2)]
    rec, res = measure(lambda: dtm_filter(xy0, xy1, scores, size, size, others[0], others[1]), device, repeat)
    kept = res.keep
    precision = float((~outlier[kept]).mean()) if kept.any() else 0.0
    return {
        **rec,
        "candidates": k,
        "inlier_ratio": 0.5,
        "kept": int(kept.sum()),
        "precision": round(precision, 3),
    }


def _run_pair(pipe: HzPlusPipeline, images: list[np.ndarray], device: torch.device) -> tuple[dict, Any]:
    """One Hz+ pair, stage by stage (the steps of HzPlusPipeline.detect and .match)."""
    sec: dict[str, float] = dict.fromkeys(("prepare", "harrisz", "shape", "orientation", "descriptor"), 0.0)

    def timed(stage: str, fn: Callable[[], Any]) -> Any:
        _sync(device)
        start = time.perf_counter()
        out = fn()
        _sync(device)
        sec[stage] = sec.get(stage, 0.0) + time.perf_counter() - start
        return out

    feats = []
    for rgb in images:
        ctx = timed("prepare", lambda rgb=rgb: pipe.prepare(rgb))
        kp = timed("harrisz", lambda ctx=ctx: detect_harrisz(ctx.image, pipe.harrisz))
        shape = timed("shape", lambda ctx=ctx, kp=kp: pipe.extractor.shape_frames(ctx.pyramid, kp))
        laf = timed("orientation", lambda ctx=ctx, shape=shape: pipe.extractor.orienter(ctx.pyramid, shape))
        desc = timed("descriptor", lambda ctx=ctx, laf=laf: pipe.extractor.descriptor(ctx.pyramid, laf))
        feats.append((laf[:, :, 2], desc))
    (xy0, d0), (xy1, d1) = feats
    cand = timed("blob", lambda: blob_match(d0, d1, xy0, xy1, pipe.config.blob))
    p0, p1 = (x.detach().cpu().numpy().astype(np.float64) for x in (xy0, xy1))
    size = images[0].shape[:2], images[1].shape[:2]
    keep = timed(
        "dtm",
        lambda: (
            dtm_filter(
                p0[cand.idx0],
                p1[cand.idx1],
                cand.scores,
                size[0],
                size[1],
                _unmatched(p0, cand.idx0),
                _unmatched(p1, cand.idx1),
                pipe.config.dtm,
            ).keep
        ),
    )
    sec["total"] = sum(sec.values())
    return sec, (p0, p1, cand, keep)


def bench_pairs(images: list[np.ndarray], h: np.ndarray, device: torch.device, repeat: int) -> dict:
    out: dict[str, Any] = {}
    for name, options in PAIR_CONFIGS.items():
        if options.get("descriptor") == "hardnet" and not is_cached("hardnet"):
            print("  HardNet: weights not available, skipped")
            out[name] = {"skipped": "HardNet weights not available"}
            continue
        pipe = HzPlusPipeline(BaseConfig(**options), device)
        _run_pair(pipe, images, device)  # warm-up (oneDNN primitives, allocator)
        runs: list = []
        rec, _ = measure(
            lambda pipe=pipe, runs=runs: runs.append(_run_pair(pipe, images, device)),
            device,
            repeat,
            warmup=False,
        )
        best = min(runs, key=lambda r: r[0]["total"])
        stages = {k: round(min(r[0][k] for r in runs), 4) for k in best[0]}
        p0, p1, cand, keep = best[1]
        q = np.c_[p0[cand.idx0[keep]], np.ones(int(keep.sum()))] @ h.T
        err = np.linalg.norm(q[:, :2] / q[:, 2:] - p1[cand.idx1[keep]], axis=1)
        out[name] = {
            "stages_s": stages,
            "total_s": stages["total"],
            "peak_mb": rec["peak_mb"],
            "peak_method": rec["peak_method"],
            **({"cuda_peak_mb": rec["cuda_peak_mb"]} if "cuda_peak_mb" in rec else {}),
            "keypoints": [len(p0), len(p1)],
            "blob_candidates": len(cand),
            "matches": int(keep.sum()),
            "correct_3px": int((err < 3.0).sum()),
        }
    return out


def bench_opencv_sift(images: dict[str, list[np.ndarray]], repeat: int) -> dict:
    sift = cv2.SIFT_create(nfeatures=8000)
    out = {}
    for name, imgs in images.items():
        greys = [_grey_u8(rgb) for rgb in imgs]
        rec, res = measure(
            lambda greys=greys: [sift.detectAndCompute(g, None) for g in greys], torch.device("cpu"), repeat
        )
        out[name] = {**rec, "images": len(greys), "features": [len(kps) for kps, _ in res]}
    return out


def _patch_stages(device: torch.device) -> dict[str, tuple[Callable, Callable]]:
    """name -> (ours, kornia's unmodified module), each mapping (B, 1, 32, 32) patches to its output."""
    stages: dict[str, tuple[Callable, Callable]] = {}
    for name in ("affnet", "orinet", "tfeat", "hardnet"):
        if not is_cached(name):
            print(f"  {name}: weights not available, skipped")
            continue
        ref = load_model(name, None, device)
        ours = fuse_for_inference(ref)
        if name == "affnet":
            stages[name] = tuple((lambda x, m=m: m.features(m._normalize_input(x))) for m in (ours, ref))
        else:
            stages[name] = (ours, ref)
    stages["rootsift"] = (SIFTPatchDescriptor(32, device=device), SIFTDescriptor(32).to(device))
    stages["gradient-orientation"] = (
        DominantGradientOrientation(32, 36, device),
        PatchDominantGradientOrientation(32, 36).to(device),
    )
    return stages


@torch.inference_mode()
def bench_throughput(device: torch.device, repeat: int, batch: int = 4000) -> dict:
    g = torch.Generator().manual_seed(0)
    patches = torch.nn.functional.avg_pool2d(torch.rand(batch, 1, 36, 36, generator=g), 5, 1).to(device)
    out = {}
    for name, (ours, ref) in _patch_stages(device).items():
        row = {}
        for label, fn in (("ours", ours), ("kornia", ref)):
            rec, _ = measure(lambda fn=fn: fn(patches), device, repeat)
            row[label] = {"patches_per_s": round(batch / rec["seconds"]), "seconds": rec["seconds"]}
        out[name] = row
    return out


# ---------------------------------------------------------------------------------------------- report
def _print_run(threads: int, run: dict) -> None:
    t2 = TARGETS["patches_per_s_2_threads"]
    print(f"\n=== threads={threads} ===")
    for size, r in run["harrisz"].items():
        target = f"target <= {TARGETS['harrisz_640x480_s']} s" if size == "640x480" else ""
        print(
            f"HarrisZ+ {size:>9}: {r['seconds']:7.3f} s  {r['keypoints']:5d} kp  peak +{r['peak_mb']} MB  {target}"
        )
    b, d = run["blob"], run["dtm"]
    print(
        f"Blob 8000x8000     : {b['seconds']:7.3f} s  {b['candidates']} candidates  peak +{b['peak_mb']} MB"
    )
    print(
        f"DTM 12k candidates : {d['seconds']:7.3f} s  kept {d['kept']} (precision {d['precision']})  "
        f"peak +{d['peak_mb']} MB"
    )
    for name, r in run["pairs"].items():
        if "skipped" in r:
            print(f"Hz+ pair {name}: skipped ({r['skipped']})")
            continue
        target = TARGETS.get(f"pair_{name}_s")
        stages = "  ".join(f"{k} {v:.3f}" for k, v in r["stages_s"].items() if k != "total")
        print(
            f"Hz+ pair 640x480 {name}: total {r['total_s']:.3f} s"
            + (f" (target <= {target} s)" if target else "")
            + f"  peak +{r['peak_mb']} MB  kp {r['keypoints']}  matches {r['matches']} (correct {r['correct_3px']})"
        )
        print(f"    {stages}")
    for name, r in run["opencv_sift"].items():
        print(
            f"OpenCV SIFT {name}: {r['seconds']:.3f} s for {r['images']} image(s), features {r['features']}"
        )
    print("patches/s at batch 4000 (ours | kornia module | target at 2 threads):")
    for name, r in run["throughput"].items():
        target = t2.get(name, "-")
        print(
            f"    {name:<22} {r['ours']['patches_per_s']:>7} | {r['kornia']['patches_per_s']:>7} | {target}"
        )


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cpu", help="torch device (cpu, cuda)")
    parser.add_argument("--out", default="results/bench_base.json", help="JSON output path")
    parser.add_argument(
        "--threads", default=None, help="comma-separated torch/OpenCV thread counts (default: N,1)"
    )
    parser.add_argument("--repeat", type=int, default=2, help="timed calls per measurement (after a warm-up)")
    parser.add_argument("--data", default=str(SHARED / "data"), help="folder holding oxford_graf/")
    args = parser.parse_args(argv)
    device = torch.device(args.device)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda: no CUDA device available")
    default_threads = torch.get_num_threads()
    threads = (
        [int(t) for t in args.threads.split(",")]
        if args.threads
        else sorted({default_threads, 1}, reverse=True)
    )

    bgr1, bgr3, h13 = _load_graf(Path(args.data))
    img1, s1 = _resize(bgr1, 640, 480)
    img3, s3 = _resize(bgr3, 640, 480)
    big1, _ = _resize(bgr1, 1200, 900)
    h = s3 @ h13 @ np.linalg.inv(s1)

    report: dict[str, Any] = {
        "meta": {
            "date": datetime.now(UTC).isoformat(timespec="seconds"),
            "code_version": code_version(),
            "command": " ".join([Path(sys.argv[0]).name, *(argv if argv is not None else sys.argv[1:])]),
            "device": str(device) if device.type == "cpu" else torch.cuda.get_device_name(device),
            "cpu_count": os.cpu_count(),
            "platform": platform.platform(),
            "torch": torch.__version__,
            "opencv": cv2.__version__,
            "load_average_start": [round(x, 2) for x in os.getloadavg()],
            "repeat": args.repeat,
            "timing": "seconds = min over repeat timed calls after one warm-up; median_s = their median",
            "memory": "peak_mb = resident-set high-water mark during the first timed call minus the resident set "
            "before it (VmHWM reset through /proc/self/clear_refs; ru_maxrss-delta fallback only counts new "
            "process-wide peaks); cuda_peak_mb = torch allocator peak over the prior allocation",
        },
        "targets": TARGETS,
        "runs": {},
    }
    for t in threads:
        torch.set_num_threads(t)
        cv2.setNumThreads(t)
        print(f"\n--- measuring with {t} thread(s) on {report['meta']['device']} ---")
        run = {
            "harrisz": bench_harrisz({"640x480": img1, "1200x900": big1}, device, args.repeat),
            "blob": bench_blob(device, args.repeat),
            "dtm": bench_dtm(device, args.repeat),
            "pairs": bench_pairs([img1, img3], h, device, args.repeat),
            "opencv_sift": bench_opencv_sift({"pair 640x480": [img1, img3], "1200x900": [big1]}, args.repeat),
            "throughput": bench_throughput(device, args.repeat),
        }
        report["runs"][f"threads={t}"] = run
        _print_run(t, run)
    torch.set_num_threads(default_threads)
    report["meta"]["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    busy = max(report["meta"]["load_average_start"][0], report["meta"]["load_average_end"][0])
    if max(threads) > 1 and busy > (os.cpu_count() or 1):
        report["meta"]["warning"] = (
            f"load average {busy} > {os.cpu_count()} cores: multi-threaded timings are dominated by OpenMP "
            "threads waiting for each other (oversubscription); the 1-thread figures are the load-robust ones"
        )
        print(f"\nWARNING: {report['meta']['warning']}")

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(json.dumps(report, indent=2))
    tmp.replace(out)
    print(
        f"\nwrote {out}  (load average {report['meta']['load_average_start']} -> {report['meta']['load_average_end']})"
    )
    return report


if __name__ == "__main__":
    main()
