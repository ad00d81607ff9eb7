"""Methods and presets on one pair of each kind of scene: the measurements behind docs/choosing.md.

    python benchmarks/choosing_matrix.py [--methods "slime;hz+"] [--pairs graf/1-4,evd/dum] [--out FILE]

Each method spec (``slime bench`` names) runs on each pair (``tests/quality/gates.py`` names: ``graf/1-4``
planar, ``graf/1-3@45`` rotated by 45 degrees, ``evd/dum`` extreme viewpoint, ``wxbs/zanky`` wide baseline
with lighting change, ``scannet/0`` indoor non-planar); the script writes every row (correct matches,
precision, coverage, protocol mAA, pose error, seconds of matching) to a JSON file and prints a Markdown
table. Seconds depend on the machine and its load: compare them within one run.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "quality"))
from gates import measure

METHODS = ("slime;slime-fast;slime-fine;slime-upright;slime:views=off;slime-rootsift;slime-keynet;hz+;keynet;"
           "rootsift;asift")
PAIRS = "graf/1-4,graf/1-3@45,evd/dum,wxbs/zanky,scannet/0"


def cell(row: dict, pair: str) -> str:
    """One table cell: the pair's headline quality and the seconds."""
    if pair.startswith(("evd/", "wxbs/")):
        quality = f"mAA {row['maa']:.2f}"
    elif pair.startswith("scannet/"):
        quality = f"pose {row['pose_error']:.0f} deg"
    else:
        quality = f"cov {row['coverage']:.2f}"
    return f"{quality}, {row['correct']} ok, {row['seconds']:.1f} s"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", default=METHODS)
    parser.add_argument("--pairs", default=PAIRS)
    parser.add_argument("--out", default=str(ROOT / "results" / "choosing.json"))
    args = parser.parse_args(argv)
    methods = [m for m in args.methods.split(";") if m]
    pairs = [p for p in args.pairs.split(",") if p]
    rows = {}
    for method in methods:
        for pair in pairs:
            rows[f"{method} {pair}"] = row = asdict(measure(method, pair))
            print(json.dumps({"method": method, "pair": pair, **row}), file=sys.stderr, flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")
    print("| method | " + " | ".join(pairs) + " |")
    print("|---" * (len(pairs) + 1) + "|")
    for method in methods:
        print(f"| `{method}` | " + " | ".join(cell(rows[f"{method} {p}"], p) for p in pairs) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
