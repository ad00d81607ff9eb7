"""Readers of planar (homography) datasets: the paper's planar folder, HPatches, Oxford, EVD."""

from __future__ import annotations

import re
from pathlib import Path

from slime_match.eval.datasets.files import find_image, read_mask, read_matrix, require_dir
from slime_match.eval.datasets.pair import Pair


def read_planar(folder: Path | str) -> list[Pair]:
    """The paper's planar folder: ``<scene>{1..6}.png``, ``<scene>_H1<k>.txt`` (1 -> k), masks
    ``mask_<scene><k>.png`` (non-zero = exclude) and rotated variants ``<scene>rot<k>.png`` +
    ``<scene>rot_H1<k>.txt`` (reference image ``<scene>rot1.png`` if present, else ``<scene>1.png``)."""
    folder = require_dir(folder, "planar dataset")
    pairs = []
    for hfile in sorted(folder.glob("*_H1*.txt")):
        m = re.fullmatch(r"(?P<scene>.+)_H1(?P<k>\d+)\.txt", hfile.name)
        if m is None:
            continue
        scene, k = m["scene"], m["k"]
        base = scene.removesuffix("rot")
        im0 = find_image(folder, f"{scene}1") or find_image(folder, f"{base}1")
        im1 = find_image(folder, f"{scene}{k}")
        if im0 is None or im1 is None:
            raise FileNotFoundError(f"{hfile}: images {scene}1 / {scene}{k} not found in {folder}")
        mask0 = read_mask(folder / f"mask_{scene}1.png")
        if mask0 is None:
            mask0 = read_mask(folder / f"mask_{base}1.png")
        mask1 = read_mask(folder / f"mask_{scene}{k}.png")
        pairs.append(
            Pair(f"{scene}/1-{k}", im0, im1, "homography", H=read_matrix(hfile), mask0=mask0, mask1=mask1)
        )
    if not pairs:
        raise FileNotFoundError(f"no '<scene>_H1<k>.txt' homography files in {folder}")
    return pairs


def _read_hpatches_sequence(folder: Path) -> list[Pair]:
    pairs = []
    im0 = find_image(folder, "1")
    for hfile in sorted(folder.glob("H_1_*")):
        k = hfile.name[4:]
        im1 = find_image(folder, k)
        if im0 is None or im1 is None:
            raise FileNotFoundError(f"{hfile}: images 1 / {k} not found in {folder}")
        pairs.append(Pair(f"{folder.name}/1-{k}", im0, im1, "homography", H=read_matrix(hfile)))
    return pairs


def read_hpatches(folder: Path | str) -> list[Pair]:
    """HPatches: one sequence folder (``1..6.ppm`` + ``H_1_k``) or a root of ``v_*`` / ``i_*`` folders."""
    folder = require_dir(folder, "HPatches")
    seqs = (
        [folder]
        if any(folder.glob("H_1_*"))
        else sorted(p for p in folder.iterdir() if p.is_dir() and p.name[:2] in ("v_", "i_"))
    )
    pairs = [p for s in seqs for p in _read_hpatches_sequence(s)]
    if not pairs:
        raise FileNotFoundError(f"no HPatches sequences (folders v_*/i_* with H_1_k files) in {folder}")
    return pairs


def read_oxford(folder: Path | str) -> list[Pair]:
    """Oxford affine sequence: ``img1..imgK.*`` and ``H1toKp`` (1 -> K)."""
    folder = require_dir(folder, "Oxford sequence")
    im0 = find_image(folder, "img1")
    pairs = []
    for hfile in sorted(folder.glob("H1to*p")):
        k = hfile.name[4:-1]
        im1 = find_image(folder, f"img{k}")
        if im0 is None or im1 is None:
            raise FileNotFoundError(f"{hfile}: images img1 / img{k} not found in {folder}")
        pairs.append(Pair(f"{folder.name}/1-{k}", im0, im1, "homography", H=read_matrix(hfile)))
    if not pairs:
        raise FileNotFoundError(f"no H1to<k>p files in {folder}")
    return pairs


def read_evd(folder: Path | str) -> list[Pair]:
    """EVD-style: ``1/<name>.png``, ``2/<name>.png``, ``h/<name>.txt`` (3x3, 1 -> 2)."""
    folder = require_dir(folder, "EVD dataset")
    hdir = require_dir(folder / "h", "EVD dataset")
    pairs = []
    for hfile in sorted(hdir.glob("*.txt")):
        im0, im1 = find_image(folder / "1", hfile.stem), find_image(folder / "2", hfile.stem)
        if im0 is None or im1 is None:
            raise FileNotFoundError(f"{hfile}: images 1/{hfile.stem}.* or 2/{hfile.stem}.* not found")
        pairs.append(Pair(hfile.stem, im0, im1, "homography", H=read_matrix(hfile)))
    if not pairs:
        raise FileNotFoundError(f"no homography files in {hdir}")
    return pairs
