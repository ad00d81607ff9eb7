"""The benchmark's tables from the aggregate: the paper's Table "result_plot" (best threshold per method),
planar original vs rotated pairs, SM "Detailed results" (every threshold), pose AUC, the standard protocols of
the hard sets (per dataset and per pair) and times, in Markdown; one CSV row per group, method and
threshold."""

from __future__ import annotations

import csv
import io
from typing import Any

from slime_match.eval.aggregation import GROUPS, ROTATION_GROUPS
from slime_match.eval.methods import method_title

COLUMNS = ("coverage", "precision", "accuracy", "no_match", "wrong_only")
HEADERS = {
    "coverage": "Coverage (%)",
    "precision": "Precision (%)",
    "accuracy": "Accuracy (%)",
    "no_match": "No match pairs",
    "wrong_only": "Wrong only pairs",
}


def _fmt(column: str, value: float) -> str:
    return f"{value:.2f}" if column in ("coverage", "precision", "accuracy") else f"{int(value)}"


def _thr(th: str) -> str:
    return "--" if th == "none" else th


def markdown_tables(summary: dict[str, Any], agg: dict[str, Any]) -> str:
    """The report in Markdown: main table (best threshold), planar original vs rotated pairs, detailed table
    (every threshold), pose AUC, times."""
    methods, thresholds = list(summary["methods"]), summary["config"]["thresholds"]
    groups = [g for g in GROUPS if any(k[0] == g for k in agg["rows"])]
    counts = {g: next(v["pairs"] for k, v in agg["rows"].items() if k[0] == g) for g in groups}

    def header(names) -> list[str]:
        head = ["Method", "RANSAC thr. (px)"] + [f"{g}: {HEADERS[c]}" for g in names for c in COLUMNS]
        return ["| " + " | ".join(head) + " |", "| " + " | ".join(["---"] * len(head)) + " |"]

    def row(m: str, th: str, names=groups, table=agg["rows"]) -> str:
        cells = [method_title(summary["methods"][m]), _thr(th)]
        cells += [_fmt(c, table[(g, m, th)][c]) for g in names for c in COLUMNS]
        return "| " + " | ".join(cells) + " |"

    lines = [
        f"Pairs: {', '.join(f'{g} {counts[g]}' for g in groups)}; accuracy = mAA (Eq. acc_formula, "
        + f"1..{int(summary['config']['t_perp'])} px); best RANSAC threshold by {agg['best_group']} accuracy.",
        "",
        "### Main table (best RANSAC threshold per method)",
        "",
        *header(groups),
    ]
    lines += [row(m, agg["best"][m]) for m in methods]
    if agg["rotation_rows"]:
        rotation = agg["rotation_rows"]
        sub = {g: next(v["pairs"] for k, v in rotation.items() if k[0] == g) for g in ROTATION_GROUPS}
        lines += [
            "",
            "### Planar pairs: original vs rotated by the added rotations (best RANSAC threshold; "
            + ", ".join(f"{g} {n}" for g, n in sub.items())
            + " pairs)",
            "",
            *header(ROTATION_GROUPS),
        ]
        lines += [row(m, agg["best"][m], ROTATION_GROUPS, rotation) for m in methods]
    lines += [
        "",
        "### Detailed results (every RANSAC threshold; -- = no RANSAC)",
        "",
        *header(groups),
    ]
    lines += [row(m, th) for m in methods for th in thresholds]
    if agg["pose"]:
        lines += [
            "",
            "### Pose AUC (pose pairs; LoFTR protocol, best essential-matrix threshold)",
            "",
            "| Method | RANSAC thr. (px) | AUC@5 (%) | AUC@10 (%) | AUC@20 (%) | essential thr. (px) |",
            "| --- | --- | --- | --- | --- | --- |",
        ]
        for m in methods:
            for th in thresholds:
                v = agg["pose"][(m, th)]
                lines.append(
                    f"| {method_title(summary['methods'][m])} | {_thr(th)} | {v['auc@5']:.2f} | {v['auc@10']:.2f} | "
                    f"{v['auc@20']:.2f} | {v['essential_threshold']} |"
                )
    if agg["protocols"]:
        lines += ["", *_protocol_tables(summary, agg)]
    lines += [
        "",
        "### Time per pair (matching only, models loaded; RANSAC excluded)",
        "",
        "| Method | mean seconds per pair | pairs | code version (pairs) |",
        "| --- | --- | --- | --- |",
    ]
    for m in methods:
        t = agg["seconds"][m]
        code = ", ".join(f"{v} ({n})" for v, n in sorted(t["code"].items(), key=lambda kv: (-kv[1], kv[0])))
        lines.append(f"| {method_title(summary['methods'][m])} | {t['mean']:.2f} | {t['pairs']} | {code} |")
    return "\n".join(lines) + "\n"


def _protocol_tables(summary: dict[str, Any], agg: dict[str, Any]) -> list[str]:
    """Markdown of the standard protocols: per dataset and method, then the mAA of every pair."""
    cfg = summary["config"]
    orders = cfg.get("protocol_orders", 1)
    methods = list(summary["methods"])
    title = {m: method_title(summary["methods"][m]) for m in methods}
    lines = [
        "### Standard protocols (raw matches, OpenCV MAGSAC++)",
        "",
        (f"EVD: homography (MAGSAC++ {cfg['protocol_h_threshold']:g} px), mean transfer error against the GT over "
        "the common area, both directions; mAA over 1..15 px. WxBS: fundamental matrix (MAGSAC++ "
        f"{cfg['protocol_f_threshold']:g} px), symmetric epipolar distance of the GT correspondences; mAA = "
        f"mean recall over 1..20 px. {cfg['protocol_max_iters']} iterations, confidence 0.999. Solved: pairs "
        f"with mAA > 0. MAGSAC++ draws its samples by index, so a pair's mAA depends on the order of its "
        f"matches: mAA is that of the order the method gave; over {orders} orders, the mean over it and "
        f"{orders - 1} random permutations of the matches (the protocol's expected result)."),
        "",
        f"| Dataset | Protocol | Method | mAA | mAA over {orders} orders | Solved pairs | Pairs | Pairs without matches |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for (dataset, m), v in agg["protocols"].items():
        empty = ", ".join(v["no_match_pairs"]) or "--"
        lines.append(
            f"| {dataset} | {v['protocol'].upper()} | {title[m]} | {v['maa']:.2f} | {_maybe(v['maa_mean'])} | "
            f"{v['solved']} | {v['pairs']} | {empty} |"
        )
    lines += [
        "",
        (f"### Standard protocols per pair (pair mAA, then its mean over {orders} orders of the matches; the tilts "
         "of the simulated views a run added [Slime: the matches of F^theta on their planes, at the view angles "
         "in degrees that found them])"),
        "",
        "| Pair | Protocol | " + " | ".join(title[m] for m in methods) + " |",
        "| --- | --- | " + " | ".join("---" for _ in methods) + " |",
    ]
    for p in summary["pairs"]:
        if p.get("protocol"):
            cells = [f"{_pair_maa(p['methods'][m]['protocol'])}{_views_note(p['methods'][m].get('views'))}"
                     for m in methods]
            lines.append(f"| {p['name']} | {p['protocol'].upper()} | " + " | ".join(cells) + " |")
    return lines


def _maybe(value: float | None) -> str:
    """An mAA with two decimals, "--" when the results were scored without it."""
    return "--" if value is None else f"{value:.2f}"


def _pair_maa(protocol: dict[str, Any]) -> str:
    """A pair's protocol cell: "0.73 (0.58)", its mAA and (its mean over the matches' orders)."""
    mean = protocol.get("maa_mean")
    return f"{protocol['maa']:.2f}" + ("" if mean is None else f" ({mean:.2f})")


def _views_note(views: dict[str, Any] | None) -> str:
    """" (views: tilt 2, 4)" when a run added simulated views, else ""; Slime's runs add the F^theta matches on
    each step's planes and the view angles (degrees) that found them, " (views: tilt 2 [0], 4 [63 at 18, 36])";
    views of image 1 are named, " (views: image 1 tilt 2 [40 at 0])". Reads records without ``tried`` (image 0's
    tilts and their ``found`` counts) too."""
    if not views or not views.get("views"):
        return ""
    found = {f["tilt"]: f for f in views.get("found", [])}
    steps = views.get("tried") or [{"image": 0, "tilt": t, **found.get(t, {})} for t in views["tilts"]]
    named = any(step["image"] == 1 for step in steps)

    def step_note(step: dict[str, Any]) -> str:
        text = (f"image {step['image']} tilt " if named else "") + f"{step['tilt']:g}"
        if "ftheta_matches" not in step:
            return text
        angles = ", ".join(step.get("ftheta_by_angle", {}))
        return text + f" [{step['ftheta_matches']}" + (f" at {angles}" if angles else "") + "]"

    return " (views: " + ("" if named else "tilt ") + ", ".join(step_note(step) for step in steps) + ")"


def csv_table(summary: dict[str, Any], agg: dict[str, Any]) -> str:
    """One row per group, method and threshold (``best`` = 1 on the method's best threshold)."""
    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow(["group", "method", "spec", "threshold", "best", *COLUMNS, "pairs", "seconds"])
    for (group, m, th), v in agg["rows"].items():
        writer.writerow(
            [
                group,
                m,
                summary["methods"][m],
                th,
                int(agg["best"][m] == th),
                *(_fmt(c, v[c]) for c in COLUMNS),
                v["pairs"],
                f"{agg['seconds'][m]['mean']:.3f}",
            ]
        )
    return buf.getvalue()
