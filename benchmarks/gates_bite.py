"""Proof that the quality gates bite: run ``tests/quality`` once per on-purpose degradation of the matches.

    python benchmarks/gates_bite.py [--degradations thin,half,views-off] [--out results/gates_bite.json]

Each degradation (``benchmarks/gate_degradations.py``: keep one match of three; drop the matches in the left
half of image 0; turn the simulated views off) keeps the precision of what it keeps, so only gates that
compare with ground truth can notice it. The script writes, per degradation, the gates that failed and the
seconds the run took, prints a summary, and exits 1 when a degradation leaves every gate passing.
Run the gates on the real code first (``python -m pytest tests/quality``): they must pass there.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from gate_degradations import DEGRADATIONS


def run_gates(degradation: str) -> dict:
    """Run the quality gates under one degradation: {"failed": [test ids], "passed": n, "seconds": s}."""
    env = {**os.environ, "SLIME_DEGRADATION": degradation,
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT / "benchmarks"), os.environ.get("PYTHONPATH")]))}
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "gates.xml"
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "gate_degradations", "-p", "no:cacheprovider",
                        f"--junitxml={report}", "tests/quality"], cwd=ROOT, env=env, check=False)
        seconds = time.perf_counter() - start
        cases = ET.parse(report).getroot().iter("testcase")
        outcome = {f"{c.get('classname')}::{c.get('name')}": not any(ch.tag in ("failure", "error") for ch in c)
                   for c in cases}
    return {"failed": sorted(k for k, ok in outcome.items() if not ok), "passed": sum(outcome.values()),
            "seconds": round(seconds, 1)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--degradations", default=",".join(DEGRADATIONS))
    parser.add_argument("--out", default=str(ROOT / "results" / "gates_bite.json"))
    args = parser.parse_args(argv)
    chosen = [d for d in args.degradations.split(",") if d]
    unknown = sorted(set(chosen) - set(DEGRADATIONS))
    if unknown:
        parser.error(f"unknown degradations {unknown}; choose from {DEGRADATIONS}")
    results = {d: run_gates(d) for d in chosen}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=1) + "\n")
    for name, res in results.items():
        print(f"{name}: {len(res['failed'])} gates failed, {res['passed']} passed ({res['seconds']} s)")
        for test in res["failed"]:
            print(f"    {test}")
    missed = [name for name, res in results.items() if not res["failed"]]
    if missed:
        print(f"NOT caught by any gate: {', '.join(missed)}")
    print(f"written {args.out}")
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
