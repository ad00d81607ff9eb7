"""Drawings of matches, blocks/tiles and Slime planes (matplotlib figures, not pyplot: the caller's backend
and open figures are left alone)."""

from __future__ import annotations

import os

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from .io import save_figure


def side_by_side(image0: np.ndarray, image1: np.ndarray) -> tuple[np.ndarray, float]:
    """Place two (H, W, 3) images next to each other; returns the canvas and the x offset of image 1."""
    height = max(image0.shape[0], image1.shape[0])
    canvas = np.ones((height, image0.shape[1] + image1.shape[1], 3), np.float32)
    canvas[: image0.shape[0], : image0.shape[1]] = image0
    canvas[: image1.shape[0], image0.shape[1]:] = image1
    return canvas, float(image0.shape[1])


def pair_figure(image0: np.ndarray, image1: np.ndarray) -> Figure:
    """A figure 12 inches wide sized for the two images side by side."""
    height = max(image0.shape[0], image1.shape[0])
    return Figure(figsize=(12, 12 * height / (image0.shape[1] + image1.shape[1]) + 0.4))


def draw_matches(
    ax,
    image0: np.ndarray,
    image1: np.ndarray,
    keypoints0: np.ndarray,
    keypoints1: np.ndarray,
    colors=None,
    max_lines: int = 600,
    seed: int = 0,
    title: str | None = None,
) -> None:
    """Draw matches as lines on an axis.

    Args:
        ax: matplotlib axis.
        image0, image1: (H, W, 3) float images in [0, 1].
        keypoints0, keypoints1: (K, 2) pixel coordinates.
        colors: one colour for all, or (K, 3|4) per match.
        max_lines: draw a random subset of at most this many lines (the rest would be an opaque blob).
    """
    canvas, offset = side_by_side(image0, image1)
    ax.imshow(canvas)
    ax.set_axis_off()
    count = len(keypoints0)
    index = np.arange(count)
    if count > max_lines:
        index = np.sort(np.random.default_rng(seed).choice(count, max_lines, replace=False))
        title = f"{title or ''} (lines: {max_lines} random matches; dots: all)".strip()
    if title:
        ax.set_title(title, fontsize=9)
    if count == 0:
        return
    colors = np.asarray("lime" if colors is None else colors, dtype=object if colors is None else float)
    per_match = colors.ndim == 2
    segments = np.stack([keypoints0[index], keypoints1[index] + [offset, 0.0]], axis=1)
    lines = LineCollection(segments, colors=colors[index] if per_match else str(colors), linewidths=0.5,
                           alpha=0.5)
    ax.add_collection(lines)
    point_colors = colors if per_match else str(colors)
    ax.scatter(keypoints0[:, 0], keypoints0[:, 1], s=1.0, c=point_colors, linewidths=0)
    ax.scatter(keypoints1[:, 0] + offset, keypoints1[:, 1], s=1.0, c=point_colors, linewidths=0)


def plot_matches(image0: np.ndarray, image1: np.ndarray, result, path: str | os.PathLike,
                 title: str | None = None) -> None:
    """Save a picture of a MatchResult: inliers green / outliers red when RANSAC ran, else all green."""
    figure = pair_figure(image0, image1)
    ax = figure.subplots()
    colors = None
    if result.inliers is not None and len(result):
        colors = np.where(np.asarray(result.inliers)[:, None], [[0.1, 0.9, 0.1]], [[0.95, 0.1, 0.1]])
    if title is None:
        title = f"{len(result)} matches"
        if result.inliers is not None:
            title += f", {int(np.sum(result.inliers))} inliers ({result.geometry_kind})"
    draw_matches(ax, image0, image1, result.keypoints0, result.keypoints1, colors, title=title)
    save_figure(path, figure)
