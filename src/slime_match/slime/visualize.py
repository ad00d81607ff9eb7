"""Pictures of Slime's stages (``slime viz``), like the paper's figures: blocks/tiles, planes, sets, final."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.patches import Rectangle

from ..errors import SlimeMatchError
from ..io import load_image, load_npz, save_figure
from ..output_folder import replacing_owned_files
from ..viz import draw_matches, pair_figure, side_by_side

STAGE_KEYS = {  # each picture and the stages.npz arrays it reads
    "blocks": ("blocks0", "blocks1"),
    "tiles": ("tiles0", "tiles1"),
    "planes": ("planes_H", "block_matches_xy0", "block_matches_xy1", "block_matches_plane"),
    **{name: ("table_xy0", "table_xy1", f"{name}_indptr", f"{name}_indices") for name in ("superset", "fbar", "ftheta")},
    "tile_matches": ("tile_matches_xy0", "tile_matches_xy1"),
    "final": ("final_xy0", "final_xy1"),
}
STAGES = tuple(STAGE_KEYS)


def _set_colors(labels: np.ndarray, seed: int = 0) -> np.ndarray:
    """(K, 3) one random bright colour per distinct label."""
    count = int(labels.max(initial=0)) + 1
    palette = matplotlib.colormaps["hsv"](np.linspace(0.0, 1.0, count, endpoint=False))[:, :3]
    return palette[np.random.default_rng(seed).permutation(count)][labels]


def _sets_to_rows(stages: dict, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(entries,) table rows and set index of every entry of a saved TileSets."""
    indptr = stages[f"{name}_indptr"]
    return stages[f"{name}_indices"], np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))


def _draw_boxes(ax, boxes: np.ndarray, offset: float) -> None:
    colors = ("tab:blue", "tab:orange", "tab:red", "tab:green")
    for x0, y0, x1, y1, scale in boxes:
        ax.add_patch(Rectangle((x0 + offset, y0), x1 - x0, y1 - y0, fill=False, lw=0.8,
                               edgecolor=colors[int(scale) % len(colors)]))


def render_stages(stages_path: str | os.PathLike, image0, image1, out_dir: str | os.PathLike,
                  stages: list[str] | None = None) -> list[Path]:
    """Draw the stages saved by ``slime match --save-stages`` into one PNG each.

    Args:
        stages_path: the ``stages.npz``.
        image0, image1: the two images (paths or arrays), as matched.
        out_dir: folder for ``<stage>.png``.
        stages: stage names among :data:`STAGES` (all when None).

    Returns:
        The written PNG paths.
    """
    names = list(stages or STAGES)
    unknown = sorted(set(names) - set(STAGES))
    if unknown:
        raise SlimeMatchError(f"unknown stage(s) {', '.join(unknown)}: choose among {', '.join(STAGES)}")
    required = tuple(dict.fromkeys(key for name in names for key in STAGE_KEYS[name]))
    data = load_npz(stages_path, "stages file", required, hint="; write it with `slime match --save-stages`")
    img0, img1 = load_image(image0), load_image(image1)
    out = Path(out_dir)
    with replacing_owned_files(out, [f"{name}.png" for name in STAGES]) as staging:
        for name in names:
            save_figure(staging / f"{name}.png", _stage_figure(name, data, img0, img1))
    return [out / f"{name}.png" for name in names]


def _stage_figure(name: str, data: dict[str, np.ndarray], img0: np.ndarray, img1: np.ndarray):
    """The figure of one stage of :data:`STAGES` from the arrays of a ``stages.npz``."""
    figure = pair_figure(img0, img1)
    ax = figure.subplots()
    if name in ("blocks", "tiles"):
        canvas, offset = side_by_side(img0, img1)
        ax.imshow(canvas)
        ax.set_axis_off()
        _draw_boxes(ax, data[f"{name}0"], 0.0)
        _draw_boxes(ax, data[f"{name}1"], offset)
        ax.set_title(f"{name}: {len(data[f'{name}0'])} / {len(data[f'{name}1'])} (cores, colour = scale)",
                     fontsize=9)
    elif name == "planes":
        plane = data["block_matches_plane"]
        draw_matches(ax, img0, img1, data["block_matches_xy0"], data["block_matches_xy1"],
                     _set_colors(plane), title=f"planes of the block pairs (M_l): {len(data['planes_H'])} "
                                              f"planes, {len(plane)} matches (colour = plane)")
    elif name in ("superset", "fbar", "ftheta"):
        rows, set_id = _sets_to_rows(data, name)
        titles = {"superset": "tile match sets of every plane (superset H)",
                  "fbar": "the largest sets, one per tile (F-bar)",
                  "ftheta": "sets fused and at the global orientation (F^theta)"}
        draw_matches(ax, img0, img1, data["table_xy0"][rows], data["table_xy1"][rows], _set_colors(set_id),
                     title=f"{titles[name]}: {int(set_id.max(initial=-1)) + 1} sets, {len(rows)} entries")
    else:
        key = "tile_matches" if name == "tile_matches" else "final"
        draw_matches(ax, img0, img1, data[f"{key}_xy0"], data[f"{key}_xy1"],
                     title=f"{name}: {len(data[f'{key}_xy0'])} matches")
    return figure
