"""Aggregation of a benchmark's per-pair metrics (``metrics.json``) into the values of the paper's tables.

Over the pairs of a group ("planar" = homography GT, "non-planar" = everything else), per method and RANSAC
threshold: coverage and precision are means of the per-pair values in %, accuracy is the mAA of Eq.
acc_formula in % (thresholds 1..t_perp px), "no match" counts pairs without kept matches and "wrong only"
pairs with matches but none correct. The best threshold of a method maximises its non-planar accuracy
(planar when there are no non-planar pairs), as in the paper's main table. Pose pairs add the AUC@5/10/20 of
the max(rotation, translation) angular error, at the essential-matrix RANSAC threshold with the highest AUC
sum over the group. When the planar pairs include rotated variants, they are also split into original and
rotated pairs (where upright methods are expected to fail). Pairs scored by a standard protocol
(:mod:`slime_match.eval.metrics.protocols`) add, per dataset and method, the mean pair mAA, the solved pairs
(mAA > 0) and the pairs without raw matches.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from slime_match.eval import metrics as M
from slime_match.eval.code_version import UNKNOWN

GROUPS = ("planar", "non-planar")
ROTATION_GROUPS = {"planar original": True, "planar rotated": False}  # subgroup -> pairs' "upright" flag


def load_summary(results: str | Path) -> dict[str, Any]:
    """The ``metrics.json`` of a results folder."""
    return json.loads((Path(results) / "metrics.json").read_text())


def _error(value: float | None) -> float:
    return math.inf if value is None else float(value)


def aggregate(summary: dict[str, Any]) -> dict[str, Any]:
    """Per group, method and threshold: the table values; plus times, best thresholds and pose AUC.

    Returns:
        {"rows": {(group, method, threshold): {column: value, "pairs": n}}, "rotation_rows": the same for
        the planar pairs split into ``ROTATION_GROUPS`` (empty unless both kinds exist), "best": {method: threshold},
        "seconds": {method: {"mean": s, "pairs": n, "code": {code version: pairs}}}, "pose": {(method, threshold): {"auc@5": ...,
        "essential_threshold": t, "pairs": n}}, "protocols": :func:`_protocols`}
    """
    cfg = summary["config"]
    thresholds, methods = cfg["thresholds"], list(summary["methods"])
    t_perp = int(cfg["t_perp"])
    pairs = summary["pairs"]
    rows: dict[tuple[str, str, str], dict[str, float]] = {}
    for group in GROUPS:
        rows.update(_rows(group, [p for p in pairs if p["group"] == group], methods, thresholds, t_perp))
    planar = [p for p in pairs if p["group"] == "planar"]
    rotation_rows: dict[tuple[str, str, str], dict[str, float]] = {}
    if any(p["upright"] for p in planar) and not all(p["upright"] for p in planar):
        for subgroup, upright in ROTATION_GROUPS.items():
            members = [p for p in planar if p["upright"] == upright]
            rotation_rows.update(_rows(subgroup, members, methods, thresholds, t_perp))
    pick = "non-planar" if any(k[0] == "non-planar" for k in rows) else "planar"
    best = {
        m: max(thresholds, key=lambda th: (rows[(pick, m, th)]["accuracy"], -thresholds.index(th)))
        for m in methods
    }
    seconds = {
        m: {
            "mean": float(np.mean([p["methods"][m]["seconds"] for p in pairs])),
            "pairs": len(pairs),
            "code": dict(Counter(p["methods"][m].get("code", UNKNOWN) for p in pairs)),
        }
        for m in methods
    }
    return {
        "rows": rows,
        "rotation_rows": rotation_rows,
        "best": best,
        "best_group": pick,
        "seconds": seconds,
        "pose": _pose_auc(pairs, methods, thresholds),
        "protocols": _protocols(pairs, methods),
    }


def _protocols(pairs: list[dict], methods: list[str]) -> dict[tuple[str, str], dict[str, Any]]:
    """{(dataset spec, method): {"protocol": "evd" | "wxbs", "maa": mean pair mAA, "maa_mean": mean of the
    pairs' mAA over the matches' orders (None for results scored without it), "solved": pairs with mAA > 0,
    "pairs": n, "no_match_pairs": names of the pairs without raw matches}} over the pairs scored by a
    protocol, in dataset order."""
    out = {}
    datasets = dict.fromkeys(p["dataset"] for p in pairs if p.get("protocol"))
    for dataset in datasets:
        members = [p for p in pairs if p["dataset"] == dataset and p.get("protocol")]
        for m in methods:
            maa = np.array([p["methods"][m]["protocol"]["maa"] for p in members])
            over_orders = [p["methods"][m]["protocol"].get("maa_mean") for p in members]
            out[(dataset, m)] = {
                "protocol": "/".join(dict.fromkeys(p["protocol"] for p in members)),
                "maa": float(maa.mean()),
                "maa_mean": None if None in over_orders else float(np.mean(over_orders)),
                "solved": int((maa > 0).sum()),
                "pairs": len(members),
                "no_match_pairs": [p["name"] for p in members if p["methods"][m]["raw_matches"] == 0],
            }
    return out


def _rows(
    group: str, members: list[dict], methods: list[str], thresholds: list[str], t_perp: int
) -> dict[tuple[str, str, str], dict[str, float]]:
    """{(group, method, threshold): table values over the pairs ``members``} (empty without pairs)."""
    rows = {}
    if not members:
        return rows
    for m in methods:
        for th in thresholds:
            recs = [p["methods"][m]["thresholds"][th] for p in members]
            n = np.array([r["n_matches"] for r in recs])
            c = np.array([r["n_correct"] for r in recs])
            fails = M.failure_counts(n, c)
            rows[(group, m, th)] = {
                "coverage": 100 * float(np.mean([r["coverage"] for r in recs])),
                "precision": 100 * float(np.mean([r["precision"] for r in recs])),
                "accuracy": 100
                * M.mean_average_accuracy(np.array([_error(r["error"]) for r in recs]), t_perp),
                "no_match": fails["no_matches"],
                "wrong_only": fails["only_wrong"],
                "pairs": len(recs),
            }
    return rows


def _pose_auc(pairs: list[dict], methods: list[str], thresholds: list[str]) -> dict:
    members = [p for p in pairs if p["kind"] == "pose"]
    out = {}
    if not members:
        return out
    for m in methods:
        for th in thresholds:
            sweeps = [p["methods"][m]["thresholds"][th]["pose_errors"] for p in members]
            best = None
            for et in sweeps[0]:
                auc = M.pose_auc(np.array([_error(s[et]) for s in sweeps]))
                if best is None or sum(auc.values()) > sum(best[1].values()):
                    best = (et, auc)
            out[(m, th)] = {
                **{f"auc@{k:g}": 100 * v for k, v in best[1].items()},
                "essential_threshold": best[0],
                "pairs": len(members),
            }
    return out
