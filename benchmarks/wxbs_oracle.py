"""How much of the WxBS protocol Slime's stages hold: the protocol's mAA (MAGSAC++ F at 3 px, recall of the GT
correspondences over 1..20 px) of Slime's output, of its stage selections, and of an oracle that keeps only
the block stage's correct matches.

    python benchmarks/wxbs_oracle.py DATA/hard/wxbs [--options views=off] [--out results/wxbs_oracle.json]

Per pair, from one Slime run with its stages kept (the match table: the block planes' matches, exact
duplicates merged):
- ``final``: Slime's output, as ``slime bench`` scores it.
- ``oracle_3px``, ``oracle_5px``, ``oracle_15px``: the match table's matches within 3 / 5 / 15 px of the ground
  truth (``correct_matches_fundamental``: the GT F and the local flow of the GT correspondences), alone. What
  any selection of the block planes can give the protocol, give or take the refinement's accuracy.
- ``table``: the whole match table; ``m_plus``, ``fbar``, ``ftheta``: the vote's M+, F-bar and F^theta.
- ``final_plus_m_plus``: the output with M+ added; ``final_plus_table_8px``: the output with the table matches
  within 8 px (larger symmetric epipolar distance) of the F that MAGSAC++ fits to the output.
The summary is the mean over the pairs of each, and the correct block matches (5 px) per pair.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from slime_match import Matcher, make_config
from slime_match.eval.datasets.wxbs import read_wxbs
from slime_match.eval.metrics.correctness import correct_matches_fundamental
from slime_match.eval.metrics.protocols import magsac_fundamental, symmetric_epipolar_distance, wxbs_protocol

THRESHOLD, ITERATIONS = 3.0, 10_000  # the WxBS protocol's MAGSAC++ (as ``slime bench``)


def _maa(x0: np.ndarray, x1: np.ndarray, corrs: np.ndarray) -> float:
    return wxbs_protocol(x0, x1, corrs, THRESHOLD, ITERATIONS)["maa"]


def _in_sets(stages: dict[str, np.ndarray], name: str) -> np.ndarray:
    """(M,) bool: the table rows in some set of the family ``name`` (``superset``, ``fbar``, ``ftheta``)."""
    inside = np.zeros(len(stages["table_xy0"]), bool)
    inside[stages[f"{name}_indices"]] = True
    return inside


def pair_scores(matcher: Matcher, pair) -> dict[str, float | int]:
    """The protocol's mAA of every selection of one WxBS pair, and its correct block matches at 5 px."""
    result = matcher(pair.image0, pair.image1)
    stages, corrs = result.stages, pair.corrs
    x0, x1 = stages["table_xy0"], stages["table_xy1"]
    k0, k1 = result.keypoints0, result.keypoints1
    out: dict[str, float | int] = {"final": _maa(k0, k1, corrs)}
    for t in (3.0, 5.0, 15.0):
        ok = correct_matches_fundamental(x0, x1, pair.F, t, corrs)
        out[f"oracle_{t:g}px"] = _maa(x0[ok], x1[ok], corrs)
        if t == 5.0:
            out["correct_block_matches_5px"] = int(ok.sum())
    out["table"] = _maa(x0, x1, corrs)
    keep = np.asarray(stages["epipolar_keep"], bool)
    out["m_plus"] = _maa(x0[keep], x1[keep], corrs)
    for name in ("fbar", "ftheta"):
        inside = _in_sets(stages, name)
        out[name] = _maa(x0[inside], x1[inside], corrs)
    out["final_plus_m_plus"] = _maa(np.r_[k0, x0[keep]], np.r_[k1, x1[keep]], corrs)
    fitted = magsac_fundamental(k0, k1, THRESHOLD, ITERATIONS)
    near = (symmetric_epipolar_distance(fitted, x0, x1) < 8.0) if fitted is not None else np.zeros(len(x0), bool)
    out["final_plus_table_8px"] = _maa(np.r_[k0, x0[near]], np.r_[k1, x1[near]], corrs)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("wxbs", type=Path, help="a WxBS folder (pair folders with 01.*, 02.*, corrs.txt)")
    parser.add_argument("--options", default="", help="Slime options, e.g. views=off,descriptor=tfeat")
    parser.add_argument("--out", type=Path, default=Path("results/wxbs_oracle.json"))
    args = parser.parse_args()
    options = dict(item.split("=", 1) for item in filter(None, args.options.split(",")))
    matcher = Matcher(make_config("slime", keep_stages=True, **options))
    pairs = {}
    for pair in read_wxbs(args.wxbs):
        pairs[pair.name] = pair_scores(matcher, pair)
        print(pair.name, json.dumps({k: round(v, 3) for k, v in pairs[pair.name].items()}), flush=True)
    keys = next(iter(pairs.values())).keys()
    summary = {k: float(np.mean([p[k] for p in pairs.values()])) for k in keys}
    print(json.dumps({k: round(v, 3) for k, v in summary.items()}))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"options": options, "pairs": pairs, "summary": summary}, indent=1) + "\n")


if __name__ == "__main__":
    main()
