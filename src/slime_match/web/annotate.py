"""The ground-truth correspondence tool's files: point pairs clicked in two images, grouped in sets (one plane
each; their models are in :mod:`.annotation_models`), saved in the formats that ``slime bench`` reads: a WxBS pair folder (``01.*``, ``02.*``, ``corrs.txt``, rows ``x0 y0 x1 y1``) or a
planar pair (``<name>1.*``, ``<name>2.*`` and the 3x3 homography ``<name>_H12.txt``, image 1 -> 2).

A pair may be marked occluded (the point is seen in one image only): it is kept in the tool's own
``annotation.json`` beside the files and left out of ``corrs.txt`` and of every fit.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..eval.datasets.files import find_image, read_matrix
from ..io import save_json, save_text
from .annotation_models import corrs_array, fundamental_check, homography_check

NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")
MODELS = ("H", "F")


class AnnotationError(ConfigError):
    """Bad annotation input: the message says what to fix."""


def read_pairs(items: Any) -> list[dict[str, Any]]:
    """Point pairs from the client: ``{"x0", "y0", "x1", "y1", "set", "occluded"}`` each (an occluded pair
    has the point of one image only: the other's x and y are None)."""
    if not isinstance(items, list):
        raise AnnotationError("pairs must be a list of {x0, y0, x1, y1, set, occluded}")
    pairs = []
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            raise AnnotationError(f"pair {i} is not an object")
        occluded = bool(item.get("occluded", False))
        try:
            values = [None if occluded and item.get(key) is None else float(item[key])
                      for key in ("x0", "y0", "x1", "y1")]
            group = int(item.get("set", 0))
        except (KeyError, TypeError, ValueError):
            raise AnnotationError(f"pair {i}: x0, y0, x1, y1 must be numbers (an occluded pair may leave one "
                                  "image's point null), set an integer") from None
        x0, y0, x1, y1 = values
        if (x0 is None) != (y0 is None) or (x1 is None) != (y1 is None) or (x0 is None and x1 is None):
            raise AnnotationError(f"pair {i}: an occluded pair has the point of one image (x and y)")
        if not all(np.isfinite([v for v in values if v is not None])) or group < 0:
            raise AnnotationError(f"pair {i}: coordinates must be finite and the set >= 0")
        pairs.append({"x0": x0, "y0": y0, "x1": x1, "y1": y1, "set": group, "occluded": occluded})
    return pairs


def corrs_text(pairs: list[dict[str, Any]]) -> str:
    """The WxBS ``corrs.txt`` of the visible pairs: one ``x0 y0 x1 y1`` row each."""
    corrs = corrs_array(pairs)
    return "".join(" ".join(f"{v:.3f}" for v in row) + "\n" for row in corrs)


def matrix_text(matrix: np.ndarray) -> str:
    """A 3x3 matrix as text, three rows of three numbers (what ``read_matrix`` reads)."""
    return "".join(" ".join(f"{v:.12g}" for v in row) + "\n" for row in np.asarray(matrix, np.float64))


def export_text(pairs: list[dict[str, Any]], model: str) -> tuple[str, str]:
    """(file name, text) of the annotation as the bench reads it: ``corrs.txt`` (F) or ``H12.txt`` (H)."""
    check_model(model)
    corrs = corrs_array(pairs)
    if model == "F":
        _, why = fundamental_check(corrs)
        if why is not None:
            raise AnnotationError(f"a WxBS corrs.txt is read as the 8-point F of its pairs: {why}")
        return "corrs.txt", corrs_text(pairs)
    H, why = homography_check(corrs)
    if why is not None:
        raise AnnotationError(f"a planar pair's file is the H of its pairs: {why}")
    return "H12.txt", matrix_text(H)


def check_model(model: Any) -> str:
    if model not in MODELS:
        raise AnnotationError(f"model must be 'H' (a planar pair) or 'F' (a WxBS pair), got {model!r}")
    return model


def check_name(name: Any) -> str:
    if not isinstance(name, str) or not NAME.fullmatch(name):
        raise AnnotationError("the pair name must be 1-64 letters, digits, '_' or '-', starting with a letter or "
                              f"digit; got {name!r}")
    return name


def save(folder: Path, name: str, model: str, image0: Path, image1: Path, pairs: list[dict[str, Any]],
         overwrite: bool = False) -> dict[str, Any]:
    """Write the annotation under ``folder`` as the bench reads it, with copies of the two images.

    F: ``folder/wxbs/<name>/{01.*, 02.*, corrs.txt, annotation.json}`` (``slime bench wxbs:folder/wxbs``).
    H: ``folder/planar/{<name>1.*, <name>2.*, <name>_H12.txt, <name>_annotation.json}``
    (``slime bench planar:folder/planar``).

    Returns:
        ``{"kind", "files"}``: the dataset kind and the written files relative to ``folder``.
    """
    check_name(name)
    check_model(model)
    _, text = export_text(pairs, model)
    pictures = [image0.read_bytes(), image1.read_bytes()]  # first: they may be the copies that a resave replaces
    record = {"model": model, "image0": image0.name, "image1": image1.name, "pairs": pairs}
    if model == "F":
        target = folder / "wxbs" / name
        if target.exists() and not overwrite:
            raise AnnotationError(f"a WxBS pair {name!r} exists already: choose another name or overwrite it")
        if target.exists():
            shutil.rmtree(target)
        target.mkdir(parents=True)
        images = [target / f"01{image0.suffix.lower()}", target / f"02{image1.suffix.lower()}"]
        files = [*images, target / "corrs.txt", target / "annotation.json"]
        save_text(target / "corrs.txt", text)
        save_json(target / "annotation.json", record)
        kind = "wxbs"
    else:
        target = folder / "planar"
        target.mkdir(parents=True, exist_ok=True)
        hfile = target / f"{name}_H12.txt"
        if hfile.exists() and not overwrite:
            raise AnnotationError(f"a planar pair {name!r} exists already: choose another name or overwrite it")
        for stem in (f"{name}1", f"{name}2"):  # an earlier save's images may have had another extension
            if (old := find_image(target, stem)) is not None:
                old.unlink()
        images = [target / f"{name}1{image0.suffix.lower()}", target / f"{name}2{image1.suffix.lower()}"]
        files = [*images, hfile, target / f"{name}_annotation.json"]
        save_text(hfile, text)
        save_json(target / f"{name}_annotation.json", record)
        kind = "planar"
    for data, copy in zip(pictures, images):
        copy.write_bytes(data)
    return {"kind": kind, "files": [f.relative_to(folder).as_posix() for f in files]}


def open_file(path: Path) -> dict[str, Any]:
    """An annotation from the files the bench reads: a WxBS ``corrs.txt`` (with ``01.*`` and ``02.*``
    beside it), a planar ``<scene>_H1<k>.txt`` (with ``<scene>1.*`` and ``<scene><k>.*``), an Oxford
    ``H1to<k>p`` (with ``img1.*`` and ``img<k>.*``) or an EVD ``h/<name>.txt`` (with ``1/<name>.*`` and
    ``2/<name>.*``); the tool's
    ``annotation.json`` beside them, when there is one, brings back the sets and the occluded points.

    Returns:
        ``{"kind", "image0", "image1", "pairs", "H"}``: kind "wxbs" or "planar", the image paths, the pairs,
        and for a planar file its homography.
    """
    if path.name == "corrs.txt":
        image0, image1 = find_image(path.parent, "01"), find_image(path.parent, "02")
        if image0 is None or image1 is None:
            raise AnnotationError(f"{path.name}: the images 01.* and 02.* are not beside it")
        try:
            corrs = np.loadtxt(path, dtype=np.float64, ndmin=2)
        except ValueError as error:
            raise AnnotationError(f"{path.name} is not a table of numbers: {error}") from None
        if corrs.size and corrs.shape[1] != 4:
            raise AnnotationError(f"{path.name}: expected rows 'x0 y0 x1 y1', got {corrs.shape[1]} columns")
        pairs = [{"x0": r[0], "y0": r[1], "x1": r[2], "y1": r[3], "set": 0, "occluded": False}
                 for r in corrs.reshape(-1, 4).tolist()]
        sidecar = path.parent / "annotation.json"
        return {"kind": "wxbs", "image0": image0, "image1": image1, "H": None,
                "pairs": _recorded_pairs(sidecar, corrs) or pairs}
    planar = _planar_images(path)
    if planar is None:
        raise AnnotationError(f"{path.name} is none of the ground truths the bench reads: a WxBS corrs.txt, a "
                              "planar '<scene>_H1<k>.txt', an Oxford 'H1to<k>p' or an EVD 'h/<name>.txt'")
    image0, image1, sidecar = planar
    try:
        H = read_matrix(path)
    except (ValueError, ConfigError) as error:
        raise AnnotationError(f"{path.name} is not a 3x3 matrix: {error}") from None
    return {"kind": "planar", "image0": image0, "image1": image1, "H": H.tolist(),
            "pairs": (_recorded_pairs(sidecar, None) if sidecar else None) or []}


def _planar_images(path: Path) -> tuple[Path, Path, Path | None] | None:
    """(image 0, image 1, the tool's record beside them or None) of a homography file in one of the bench's
    planar layouts, None for a file in none of them.

    Raises:
        AnnotationError: a homography file whose images are missing.
    """
    folder = path.parent
    if (match := re.fullmatch(r"(?P<scene>.+)_H1(?P<k>\d+)\.txt", path.name)) is not None:  # planar
        scene, k = match["scene"], match["k"]
        names = (f"{scene}1", f"{scene}{k}")
        image0 = find_image(folder, names[0]) or find_image(folder, f"{scene.removesuffix('rot')}1")
        image1, sidecar = find_image(folder, names[1]), folder / f"{scene}_annotation.json"
    elif (match := re.fullmatch(r"H1to(?P<k>\d+)p", path.name)) is not None:  # Oxford
        names = ("img1", f"img{match['k']}")
        image0, image1, sidecar = find_image(folder, names[0]), find_image(folder, names[1]), None
    elif folder.name == "h" and path.suffix == ".txt":  # EVD: 1/<name>.*, 2/<name>.*, h/<name>.txt
        names = (f"1/{path.stem}", f"2/{path.stem}")
        image0, image1 = find_image(folder.parent / "1", path.stem), find_image(folder.parent / "2", path.stem)
        sidecar = None
    else:
        return None
    if image0 is None or image1 is None:
        raise AnnotationError(f"{path.name}: the images {names[0]}.* and {names[1]}.* are missing")
    return image0, image1, sidecar


def _recorded_pairs(sidecar: Path, corrs: np.ndarray | None) -> list[dict[str, Any]] | None:
    """The pairs of the tool's ``annotation.json``, when there is one that agrees with ``corrs`` (the file
    the bench reads wins: an edited corrs.txt makes the record stale)."""
    if not sidecar.is_file():
        return None
    try:
        pairs = read_pairs(json.loads(sidecar.read_text()).get("pairs"))
    except (OSError, ValueError, AttributeError, ConfigError):
        return None
    if corrs is not None:
        mine = corrs_array(pairs)
        if mine.shape != corrs.reshape(-1, 4).shape or not np.allclose(mine, corrs.reshape(-1, 4), atol=1e-3):
            return None
    return pairs


def saved(folder: Path) -> list[dict[str, str]]:
    """The annotations saved under ``folder``: ``{"kind", "name", "path"}`` with the path of the file to open
    (relative to ``folder``)."""
    found = []
    for corrs in sorted((folder / "wxbs").glob("*/corrs.txt")):
        found.append({"kind": "wxbs", "name": corrs.parent.name, "path": corrs.relative_to(folder).as_posix()})
    for hfile in sorted((folder / "planar").glob("*_H12.txt")):
        found.append({"kind": "planar", "name": hfile.name[:-len("_H12.txt")],
                      "path": hfile.relative_to(folder).as_posix()})
    return found
