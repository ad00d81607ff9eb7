"""The output folder of one matched pair: matches.npz, summary.json, matches.png (and stages.npz)."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..io import save_json, save_npz
from ..result import MatchResult

MATCHES_FILE = "matches.npz"
SUMMARY_FILE = "summary.json"


def write_pair_outputs(result: MatchResult, image0: np.ndarray, image1: np.ndarray, out: Path,
                       plot: bool = True) -> None:
    """Write the pair's files into ``out``, all or nothing (staged in a hidden folder, then moved).

    Args:
        result: the pair's matches.
        image0, image1: the loaded (H, W, 3) float images (for the picture).
        out: the pair's folder (created if needed).
        plot: also draw matches.png.
    """
    from ..viz import plot_matches

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=out, prefix=".staging-"))
    try:
        save_npz(staging / MATCHES_FILE, **result.arrays())
        if plot:
            plot_matches(image0, image1, result, staging / "matches.png")
        if result.stages is not None:
            save_npz(staging / "stages.npz", **result.stages)
        save_json(staging / SUMMARY_FILE, result.summary)  # moved last: its presence marks a complete folder
        (out / SUMMARY_FILE).unlink(missing_ok=True)
        for item in sorted(staging.iterdir(), key=lambda p: p.name == SUMMARY_FILE):
            os.replace(item, out / item.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def is_complete(out: Path) -> bool:
    """Whether ``out`` holds the files of a finished pair (summary.json is moved in last)."""
    return (Path(out) / MATCHES_FILE).is_file() and (Path(out) / SUMMARY_FILE).is_file()
