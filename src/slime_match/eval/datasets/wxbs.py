"""Reader of WxBS-style non-planar pairs (F from hand-taken GT correspondences)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from slime_match.errors import ConfigError
from slime_match.eval.datasets.files import find_image, require_dir
from slime_match.eval.datasets.pair import Pair, fundamental_from_corrs


def read_wxbs(folder: Path | str) -> list[Pair]:
    """WxBS-style: every folder (searched recursively) holding ``01.*``, ``02.*`` and ``corrs.txt``
    (rows ``x0 y0 x1 y1``); F_gt is the normalised 8-point fit to all GT correspondences."""
    folder = require_dir(folder, "WxBS dataset")
    pairs = []
    for cfile in sorted(folder.rglob("corrs.txt")):
        d = cfile.parent
        im0, im1 = find_image(d, "01"), find_image(d, "02")
        if im0 is None or im1 is None:
            raise FileNotFoundError(f"{d}: images 01.* / 02.* not found")
        corrs = np.loadtxt(cfile, dtype=np.float64, ndmin=2)
        if corrs.shape[1] != 4:
            raise ConfigError(f"{cfile}: expected rows 'x0 y0 x1 y1', got {corrs.shape[1]} columns")
        name = d.relative_to(folder).as_posix() if d != folder else d.name
        pairs.append(Pair(name, im0, im1, "fundamental", F=fundamental_from_corrs(corrs), corrs=corrs))
    if not pairs:
        raise FileNotFoundError(f"no WxBS pair folders (01.*, 02.*, corrs.txt) under {folder}")
    return pairs
