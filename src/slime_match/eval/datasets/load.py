"""Datasets by name: :func:`load_dataset` maps a spec to its reader and the bundled data folder."""

from __future__ import annotations

import os
from pathlib import Path

from slime_match.errors import ConfigError
from slime_match.eval.datasets.motorcycle import read_motorcycle
from slime_match.eval.datasets.pair import Pair
from slime_match.eval.datasets.planar import read_evd, read_hpatches, read_oxford, read_planar
from slime_match.eval.datasets.pose import read_megadepth1500, read_scannet1500, read_scannet_pairs
from slime_match.eval.datasets.wxbs import read_wxbs


def default_data_root() -> Path:
    """Folder of the named datasets: ``$SLIME_MATCH_DATA``, else a ``shared/data`` folder beside the source
    checkout or beside the current folder."""
    env = os.environ.get("SLIME_MATCH_DATA")
    if env:
        return Path(env)
    repo = Path(__file__).resolve().parents[4]
    for cand in (repo.parent / "shared" / "data", Path.cwd().parent / "shared" / "data"):
        if cand.is_dir():
            return cand
    raise FileNotFoundError("data folder not found: pass root= or set SLIME_MATCH_DATA")


def load_dataset(spec: str, root: Path | str | None = None) -> list[Pair]:
    """Pairs of a dataset named by ``spec``.

    Specs: "graf", "hpatches", "scannet-sample", "motorcycle" (bundled data under ``root``, default
    :func:`default_data_root`); "planar:<dir>", "hpatches:<dir>", "oxford:<dir>", "evd:<dir>", "wxbs:<dir>";
    "megadepth1500:<images_root>", "scannet1500:<images_root>" (GT from ``root/gt_1500``).
    """
    name, _, arg = spec.partition(":")
    name = name.strip().lower()
    readers = {
        "planar": read_planar,
        "hpatches": read_hpatches,
        "oxford": read_oxford,
        "evd": read_evd,
        "wxbs": read_wxbs,
    }
    if name in readers and arg:
        return readers[name](arg)
    if name == "motorcycle":
        return read_motorcycle()
    if name in ("megadepth1500", "scannet1500"):
        if not arg:
            raise ConfigError(f"{name} needs an images root: '{name}:<images_root>'")
        base = Path(root) if root is not None else default_data_root()
        if name == "megadepth1500":
            return read_megadepth1500(arg, base / "gt_1500" / "megadepth")
        return read_scannet1500(arg, base / "gt_1500" / "scannet")
    bundled = {
        "graf": lambda r: read_oxford(r / "oxford_graf"),
        "hpatches": lambda r: read_hpatches(r / "hpatches"),
        "scannet-sample": lambda r: read_scannet_pairs(r / "scannet_sample" / "pairs_with_gt.txt"),
    }
    if name in bundled and not arg:
        return bundled[name](Path(root) if root is not None else default_data_root())
    known = sorted(set(readers) | set(bundled) | {"motorcycle", "megadepth1500", "scannet1500"})
    raise ConfigError(
        f"unknown dataset spec {spec!r}; known: {', '.join(known)} (folder formats need ':<dir>')"
    )
