"""The output folder of one matched pair: matches.npz, summary.json, matches.png (and stages.npz)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..io import save_json, save_npz
from ..output_folder import remove_owned_files, replacing_owned_files
from ..result import MatchResult

MATCHES_FILE = "matches.npz"
SUMMARY_FILE = "summary.json"
PLOT_FILE = "matches.png"
STAGES_FILE = "stages.npz"
PAIR_FILES = (MATCHES_FILE, SUMMARY_FILE, PLOT_FILE, STAGES_FILE)  # every file a pair's folder may hold


def write_pair_outputs(result: MatchResult, image0: np.ndarray, image1: np.ndarray, out: Path,
                       plot: bool = True, extra: dict[str, Callable[[Path], None]] | None = None) -> None:
    """Write the pair's files into ``out``, all or nothing, in place of an earlier result's files.

    The files are staged in a hidden folder inside ``out`` and moved in when all are written; an earlier
    result's files that this one does not write again (its ``stages.npz``, ``matches.png``) are removed, and
    the folder's other files are left alone. An error or an interruption before the move leaves ``out`` as
    it was. summary.json is moved in last: a folder holding it holds one complete result.

    Args:
        result: the pair's matches.
        image0, image1: the loaded (H, W, 3) float images (for the picture).
        out: the pair's folder (created if needed).
        plot: also draw matches.png.
        extra: more files of the command, by name, each with the function that writes it to a given path.
    """
    from ..viz import plot_matches

    extra = extra or {}
    with replacing_owned_files(out, (*PAIR_FILES, *extra), last=SUMMARY_FILE) as staging:
        for name, write in extra.items():
            write(staging / name)
        save_npz(staging / MATCHES_FILE, **result.arrays())
        if plot:
            plot_matches(image0, image1, result, staging / PLOT_FILE)
        if result.stages is not None:
            save_npz(staging / STAGES_FILE, **result.stages)
        save_json(staging / SUMMARY_FILE, result.summary)


def remove_pair_outputs(out: Path) -> None:
    """Remove the files of an earlier result from a pair's folder, if it exists (summary.json first)."""
    remove_owned_files(out, PAIR_FILES, last=SUMMARY_FILE)


def is_complete(out: Path) -> bool:
    """Whether ``out`` holds the files of a finished pair (summary.json is moved in last)."""
    return (Path(out) / MATCHES_FILE).is_file() and (Path(out) / SUMMARY_FILE).is_file()
