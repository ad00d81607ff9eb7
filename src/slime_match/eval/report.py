"""Benchmark report: the paper's tables (Table "result_plot" and SM "Detailed results"), bar charts, times,
pose AUC, and per-pair coverage / error maps (paper Figs. "coverage" and "accuracy").

Aggregation over the pairs of a group ("planar" = homography GT, "non-planar" = everything else), per
method and RANSAC threshold: coverage and precision are means of the per-pair values in %, accuracy is the
mAA of Eq. acc_formula in % (thresholds 1..t_perp px), "no match" counts pairs without kept matches and
"wrong only" pairs with matches but none correct. The best threshold of a method maximises its non-planar
accuracy (planar when there are no non-planar pairs), as in the paper's main table. Pose pairs add the
AUC@5/10/20 of the max(rotation, translation) angular error, at the essential-matrix RANSAC threshold
with the highest AUC sum over the group. When the planar pairs include rotated variants, a second table
splits them into original and rotated pairs (where upright methods are expected to fail).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from slime_match.eval import metrics as M
from slime_match.eval.code_version import UNKNOWN
from slime_match.eval.methods import method_title
from slime_match.geometry.homography import project
from slime_match.io import save_figure, save_text

GROUPS = ("planar", "non-planar")
ROTATION_GROUPS = {"planar original": True, "planar rotated": False}  # subgroup -> pairs' "upright" flag
COLUMNS = ("coverage", "precision", "accuracy", "no_match", "wrong_only")
HEADERS = {
    "coverage": "Coverage (%)",
    "precision": "Precision (%)",
    "accuracy": "Accuracy (%)",
    "no_match": "No match pairs",
    "wrong_only": "Wrong only pairs",
}


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
        "essential_threshold": t, "pairs": n}}}
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
    }


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


# ----------------------------------------------------------------------------------------------------------
# tables


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


# ----------------------------------------------------------------------------------------------------------
# figures


def bar_charts(summary: dict[str, Any], agg: dict[str, Any], folder: Path) -> list[Path]:
    """One PNG per metric: methods at their best threshold, one bar per group (like the paper's bars)."""
    methods = list(summary["methods"])
    groups = [g for g in GROUPS if any(k[0] == g for k in agg["rows"])]
    written = []
    for column in COLUMNS:
        fig = Figure(figsize=(max(5.0, 0.7 * len(methods) + 2), 3.2))
        ax = fig.subplots()
        width = 0.8 / len(groups)
        for i, g in enumerate(groups):
            vals = [agg["rows"][(g, m, agg["best"][m])][column] for m in methods]
            ax.bar(np.arange(len(methods)) + (i - (len(groups) - 1) / 2) * width, vals, width, label=g)
        ax.set_xticks(
            np.arange(len(methods)),
            [method_title(summary["methods"][m]) for m in methods],
            rotation=40,
            ha="right",
            fontsize=8,
        )
        ax.set_ylabel(HEADERS[column])
        ax.legend(fontsize=8)
        ax.grid(axis="y", alpha=0.3)
        path = folder / f"bar_{column}.png"
        save_figure(path, fig)
        written.append(path)
    return written


def _overlay(image: np.ndarray, valid: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """Grey image with the valid-but-uncovered area in red and the covered area in green."""
    grey = image.mean(axis=2, keepdims=True).repeat(3, axis=2)
    out = 0.6 * grey
    tint = np.zeros_like(out)
    tint[valid & ~covered] = (1.0, 0.0, 0.0)
    tint[valid & covered] = (0.0, 1.0, 0.0)
    return np.clip(out + 0.4 * tint, 0, 1)


def coverage_figure(images, valid, x0: np.ndarray, x1: np.ndarray, t: float, title: str):
    """Paper Fig. "coverage": correct keypoints (blue) dilated by ``t`` px (green) over the valid area
    (red where uncovered), both images."""
    fig = Figure(figsize=(10, 4))
    axes = fig.subplots(1, 2)
    for ax, image, v, pts in zip(axes, images, valid, (x0, x1)):
        ax.imshow(_overlay(image, v, M.dilated_mask(pts, v.shape, t)))
        ax.plot(pts[:, 0], pts[:, 1], ".", color="blue", markersize=2)
        ax.set_axis_off()
    fig.suptitle(title, fontsize=9)
    return fig


def error_maps(gt, model: np.ndarray | None, valid, step: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel accuracy error in px of an estimated model over each image's valid area (NaN elsewhere),
    on a grid of ``step`` px: planar ``|H x - H_gt x|`` (image 0) and with the inverses (image 1);
    non-planar the epipolar line area over the other image's diagonal."""
    maps = []
    for which in (0, 1):
        v = valid[which]
        sub = v[::step, ::step]
        err = np.full(sub.shape, np.nan)
        pts = np.stack(np.nonzero(sub)[::-1], 1).astype(np.float64) * step
        if model is not None and len(pts):
            if gt.planar:
                Ha, Hb = (
                    (model, gt.pair.H) if which == 0 else (np.linalg.inv(model), np.linalg.inv(gt.pair.H))
                )
                with np.errstate(invalid="ignore", over="ignore"):
                    e = np.linalg.norm(project(Ha, pts)[0] - project(Hb, pts)[0], axis=1)
            else:
                Fa, Fb = (model, gt.pair.F) if which == 0 else (model.T, gt.pair.F.T)
                ph = np.concatenate([pts, np.ones((len(pts), 1))], 1)
                other = valid[1 - which].shape
                e = M.epipolar_line_area(ph @ Fa.T, ph @ Fb.T, other, 4) / math.hypot(*other)
            err[sub] = e
        maps.append(err)
    return maps[0], maps[1]


def error_figure(images, maps, t: float, title: str, step: int = 4):
    """Paper Fig. "accuracy": error maps (0..t px colour scale) over the images."""
    fig = Figure(figsize=(10, 4))
    axes = fig.subplots(1, 2)
    for ax, image, err in zip(axes, images, maps):
        ax.imshow(image.mean(axis=2), cmap="gray", alpha=0.6)
        h, w = image.shape[:2]
        im = ax.imshow(
            err,
            cmap="turbo",
            vmin=0,
            vmax=t,
            alpha=0.6,
            extent=(-0.5, err.shape[1] * step - 0.5, err.shape[0] * step - 0.5, -0.5),
        )
        ax.set_xlim(-0.5, w - 0.5)
        ax.set_ylim(h - 0.5, -0.5)
        ax.set_axis_off()
    fig.colorbar(im, ax=axes, fraction=0.03, label="error (px)")
    fig.suptitle(title, fontsize=9)
    return fig


def write_pair_maps(folder: Path, images, gt, extras: dict[str, Any], t: float) -> list[Path]:
    """Coverage map of the raw matches (first threshold) and error map of the model at each threshold
    other than "none" (only the first RANSAC one, to keep the folder small), per method."""
    written = []
    keys = list(extras["kept"])
    ths = list(dict.fromkeys(th for _, th in keys))
    cov_th = ths[0]
    err_th = next((th for th in ths if th != "none"), ths[0])
    for (label, th), (k0, k1, ok, model) in extras["kept"].items():
        if th == cov_th:
            fig = coverage_figure(
                images, extras["valid"], k0[ok], k1[ok], t, f"{gt.pair.name} {label} thr {_thr(th)}: coverage"
            )
            path = folder / f"coverage_{label}_thr-{th}.png"
            save_figure(path, fig)
            written.append(path)
        if th == err_th:
            fig = error_figure(
                images,
                error_maps(gt, model, extras["valid"]),
                t,
                f"{gt.pair.name} {label} thr {_thr(th)}: accuracy error",
            )
            path = folder / f"error_{label}_thr-{th}.png"
            save_figure(path, fig)
            written.append(path)
    return written


# ----------------------------------------------------------------------------------------------------------
# outputs


def write_report(results: str | Path, summary: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write ``table.md``, ``table.csv`` and ``bar_<metric>.png`` of a results folder (from its
    ``metrics.json`` when ``summary`` is None); returns the aggregate."""
    results = Path(results)
    summary = json.loads(json.dumps(summary)) if summary is not None else load_summary(results)
    agg = aggregate(summary)
    save_text(results / "table.md", markdown_tables(summary, agg))
    save_text(results / "table.csv", csv_table(summary, agg))
    bar_charts(summary, agg, results)
    return agg


def write_results_doc(results: str | Path, doc: str | Path, command: str) -> None:
    """``docs/results.md``: the tables of a results folder, the command that produced them and the
    datasets/methods used."""
    results = Path(results)
    summary = load_summary(results)
    agg = aggregate(summary)
    cfg = summary["config"]
    rotations = cfg["rotations"] or "none"
    lines = [
        "# Benchmark results",
        "",
        f"Generated by `{command}` (results folder `{results}`, written {summary['written']}).",
        "",
        f"- datasets: {', '.join(cfg['datasets'])}; rotated variants {rotations} of the "
        + f"{', '.join(cfg['rotate_kinds'])} pairs (non-upright pairs);",
        f"- methods: {', '.join(f'`{s}`' for s in summary['methods'].values())};",
        f"- post-processing RANSAC ({cfg['ransac_backend']}): homography for planar pairs, fundamental "
        + f"otherwise, thresholds {', '.join(cfg['thresholds'])} px; seed {cfg['seed']};",
        f"- correctness / coverage threshold t_perp = {cfg['t_perp']:g} px. Charts and coverage/error maps "
        + "are in the results folder (`bar_*.png`, `maps/`).",
        "",
        markdown_tables(summary, agg),
    ]
    text = "\n".join(lines)
    save_text(Path(doc), text)


def main(argv: list[str] | None = None) -> int:
    """``python -m slime_match.eval.report RESULTS [--doc docs/results.md --command CMD]``: rewrite the
    tables of a results folder from its metrics.json (no recomputation)."""
    parser = argparse.ArgumentParser(prog="python -m slime_match.eval.report")
    parser.add_argument("results")
    parser.add_argument("--doc", default=None, help="also write this Markdown document")
    parser.add_argument("--command", default="slime bench", help="command line quoted in the document")
    args = parser.parse_args(argv)
    write_report(args.results)
    if args.doc:
        write_results_doc(args.results, args.doc, args.command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
