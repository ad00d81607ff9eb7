"""The benchmark's figures: bar charts of the table values and per-pair coverage / error maps (paper Figs.
"coverage" and "accuracy")."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from slime_match.eval import metrics as M
from slime_match.eval.aggregation import GROUPS
from slime_match.eval.methods import method_title
from slime_match.eval.tables import COLUMNS, HEADERS, _thr
from slime_match.geometry.homography import project
from slime_match.io import save_figure


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
