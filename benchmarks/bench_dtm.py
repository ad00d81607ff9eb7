"""DTM speed on recorded real calls, with the agreement of the outputs with the recorded ones.

    python benchmarks/bench_dtm.py --record [CALLS]      # record the calls of one Slime run (~1 min)
    python benchmarks/bench_dtm.py [CALLS] [--out results/bench_dtm.json] [--repeat 1] [--every 1]
                                   [--baseline GIT_REV]

CALLS (default results/dtm_calls_slime.pkl) is a pickled list of dicts, one per ``dtm_filter`` call: its
arguments xy0, xy1, scores, size0, size1, unmatched0, unmatched1 (default config) and the recorded outputs
keep, removed_at, restored. ``--record`` writes it: every call of one weight-free Slime run on graf
1 -> 3 at 640x480 (``bench_slime.py``'s pair), in this process (669 calls at the time of writing). ``--every N`` takes every N-th call. A round runs all calls once, in this
process, on one thread; the reported times are the smallest over ``--repeat`` rounds: wall-clock seconds
and this process's CPU seconds (less sensitive to other processes on a busy machine). ``--baseline REV``
also times the DTM of that git revision (its ``dtm.py`` and the DTM modules it imports, their loops compiled
afresh), its rounds alternating with the current code's, so both see the same machine load. The JSON also
has ms per call, whether every output equals the recorded one and the fraction of candidates whose keep
flag does, and the 1-minute load average before and after. The exit status is 1 when the current code's
outputs differ from a recording made by the same code (it is deterministic).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import pickle
import platform
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path
from types import ModuleType

import cv2
import numpy as np

from slime_match.matching import dtm

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "src/slime_match/matching"
# the DTM modules dtm.py imports, each after those it imports, in the revisions that have them
DTM_MODULES = ("delaunay", "dtm_kernels", "dtm_contraction_kernels", "dtm_mesh")


def _git_show(rev: str, path: str) -> str | None:
    out = subprocess.run(["git", "show", f"{rev}:{path}"], cwd=ROOT, capture_output=True, text=True, check=False)
    return out.stdout if out.returncode == 0 else None


def _load(name: str, source: str, folder: Path) -> ModuleType:
    path = folder / f"{name}.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(f"slime_match.matching.{name}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses and relative imports look modules up by name
    spec.loader.exec_module(module)
    return module


def load_baseline(rev: str, folder: Path) -> ModuleType:
    """The dtm module of a git revision with that revision's DTM modules, importable next to the current
    ones (same package, other names)."""
    source = _git_show(rev, f"{PACKAGE}/dtm.py")
    if source is None:
        raise SystemExit(f"{rev}: no {PACKAGE}/dtm.py")
    for name in DTM_MODULES:
        module = _git_show(rev, f"{PACKAGE}/{name}.py")
        if module is not None:
            for other in DTM_MODULES:
                module = module.replace(f"from .{other} import", f"from ._baseline_{other} import")
            _load(f"_baseline_{name}", module, folder)
            source = source.replace(f"from .{name} import", f"from ._baseline_{name} import")
    return _load("_baseline_dtm", source, folder)


def record_calls(path: Path) -> int:
    """Run weight-free Slime (one worker) on bench_slime.py's 640x480 pair and pickle its dtm_filter calls."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_slime import WEIGHT_FREE, load_pair

    from slime_match.config import make_config
    from slime_match.matcher import Matcher
    from slime_match.pipelines import hzplus

    calls = []

    def recording(xy0, xy1, scores, size0, size1, unmatched0=None, unmatched1=None, config=None):
        res = dtm.dtm_filter(xy0, xy1, scores, size0, size1, unmatched0, unmatched1, config)
        calls.append({"xy0": np.asarray(xy0), "xy1": np.asarray(xy1), "scores": np.asarray(scores),
                      "size0": size0, "size1": size1, "unmatched0": unmatched0, "unmatched1": unmatched1,
                      "keep": res.keep, "removed_at": res.removed_at, "restored": res.restored})
        return res

    a, b, _ = load_pair(ROOT.parent / "shared" / "data", 640, 480)
    hzplus.dtm_filter = recording
    try:
        Matcher(make_config("slime", workers=1, **WEIGHT_FREE))(a, b)
    finally:
        hzplus.dtm_filter = dtm.dtm_filter
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        pickle.dump(calls, f)
    return len(calls)


def run_round(module: ModuleType, calls: list[dict]) -> tuple[float, float, bool, float]:
    """Wall-clock and CPU seconds for all calls, whether every output equals the recorded one, and the
    fraction of candidates whose keep flag equals the recorded one."""
    equal = True
    wall = cpu = 0.0
    agree = total = 0
    for c in calls:
        start_wall, start_cpu = time.perf_counter(), time.process_time()
        res = module.dtm_filter(c["xy0"], c["xy1"], c["scores"], c["size0"], c["size1"], c["unmatched0"],
                                c["unmatched1"])
        wall += time.perf_counter() - start_wall
        cpu += time.process_time() - start_cpu
        equal &= (np.array_equal(res.keep, c["keep"]) and np.array_equal(res.removed_at, c["removed_at"])
                  and np.array_equal(res.restored, c["restored"]))
        agree += int(np.count_nonzero(res.keep == c["keep"]))
        total += len(c["keep"])
    return wall, cpu, bool(equal), agree / max(total, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("calls", nargs="?", type=Path, default=Path("results/dtm_calls_slime.pkl"))
    parser.add_argument("--record", action="store_true", help="write CALLS from one Slime run and exit")
    parser.add_argument("--out", type=Path)
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--every", type=int, default=1)
    parser.add_argument("--baseline", help="git revision whose dtm.py is timed too")
    args = parser.parse_args()
    if args.record:
        print(f"recorded {record_calls(args.calls)} calls -> {args.calls}")
        return
    if not args.calls.is_file():
        raise SystemExit(f"{args.calls} not found: record it first with --record")
    with open(args.calls, "rb") as f:
        calls = pickle.load(f)[:: args.every]
    with tempfile.TemporaryDirectory() as folder:
        variants = {"current": dtm}
        if args.baseline:
            variants["baseline"] = load_baseline(args.baseline, Path(folder))
        load_before = os.getloadavg()[0]
        rounds: dict[str, list[tuple[float, float]]] = {name: [] for name in variants}
        equal = dict.fromkeys(variants, True)
        agreement = dict.fromkeys(variants, 1.0)
        for _ in range(args.repeat):
            for name, module in variants.items():
                wall, cpu, same, agree = run_round(module, calls)
                rounds[name].append((wall, cpu))
                equal[name] &= same
                agreement[name] = min(agreement[name], agree)
        load_after = os.getloadavg()[0]

    report: dict = {
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "calls_file": str(args.calls),
        "calls": len(calls),
        "repeat": args.repeat,
        "load_average_1min": {"before": load_before, "after": load_after},
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "opencv": cv2.__version__,
    }
    for name in variants:
        wall = min(w for w, _ in rounds[name])
        cpu = min(c for _, c in rounds[name])
        report[name] = {"total_s": round(wall, 4), "ms_per_call": round(1000 * wall / len(calls), 3),
                        "cpu_s": round(cpu, 4), "rounds_s": [round(w, 4) for w, _ in rounds[name]],
                        "outputs_equal_recorded": equal[name], "keep_agreement": round(agreement[name], 5)}
        print(f"{name:9s} {wall:8.3f} s  {1000 * wall / len(calls):7.2f} ms/call  cpu {cpu:8.3f} s  "
              f"outputs equal: {equal[name]}, keep flags equal: {100 * agreement[name]:.2f}%")
    if args.baseline:
        report["baseline"]["revision"] = args.baseline
        report["speedup"] = round(report["baseline"]["total_s"] / report["current"]["total_s"], 2)
        report["speedup_cpu"] = round(report["baseline"]["cpu_s"] / report["current"]["cpu_s"], 2)
        print(f"speed-up  {report['speedup']:.2f}x wall, {report['speedup_cpu']:.2f}x cpu")
    print(f"load average (1 min) {load_before:.2f} -> {load_after:.2f}")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=2) + "\n")
    if not equal["current"]:
        print("the current code's outputs differ from the recorded ones (recorded with another version?)")
        sys.exit(1)


if __name__ == "__main__":
    main()
