"""A ``slime pairs`` run as hloc's feature and match files (``slime hloc``).

hloc (Hierarchical-Localization) keeps keypoints and matches in two HDF5 files: ``features.h5`` has a group per
image name with ``keypoints`` (N, 2) and ``image_size`` (width, height); ``matches.h5`` has a group per pair,
named by hloc's ``names_to_pair`` (each name with ``/`` turned to ``-``, the two joined by ``/``), with
``matches0`` (N0,), the index of each keypoint of the first image's match in the second image or -1, and
``matching_scores0`` (N0,). hloc's triangulation, reconstruction and localization read them. The run's keypoints
are merged into one list per image with one-to-one matches first (:mod:`.export`). h5py is an optional
dependency.
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..io import image_size, save_json
from ..result import confidence_of
from .export import check_export_folder, check_images, merge_keypoints, read_run, staged_folder
from .outputs import SUMMARY_FILE
from .pair_lists import write_pairs

logger = logging.getLogger("slime_match")

FEATURES_FILE = "features.h5"
MATCHES_FILE = "matches.h5"
PAIRS_FILE = "pairs.txt"
EXPORT_FILES = (FEATURES_FILE, MATCHES_FILE, PAIRS_FILE, SUMMARY_FILE)  # features.h5 first: the mark


def pair_key(name0: str, name1: str) -> str:
    """hloc's name of a pair's group in ``matches.h5``."""
    return "/".join((name0.replace("/", "-"), name1.replace("/", "-")))


def similarity(scores: np.ndarray) -> np.ndarray:
    """hloc's matching scores (higher is better, in (0, 1]): the matches' confidences, 1 / (1 + d) of their
    dissimilarities d (:func:`slime_match.result.confidence_of`), as float32."""
    return confidence_of(scores).astype(np.float32)


def _h5py():
    try:
        import h5py  # an optional dependency: the package's "hloc" extra
    except ImportError as error:
        raise ConfigError("slime hloc needs h5py: pip install 'slime-match[hloc]' (or h5py)") from error
    return h5py


def export_hloc(run: str | os.PathLike, image_dir: str | os.PathLike, output: str | os.PathLike,
                merge_radius: float = 1.0, inliers_only: bool = False, overwrite: bool = False) -> dict[str, Any]:
    """Write a ``slime pairs`` run as ``output/{features.h5, matches.h5, pairs.txt, summary.json}``, all or
    nothing.

    Keypoints are in the upright frame of :func:`slime_match.io.load_image` (as hloc's own extractors, which
    read images with OpenCV, write them), top-left pixel centre = (0, 0) (hloc adds COLMAP's 0.5 itself).

    Args:
        run: the ``slime pairs`` run folder; image_dir: the folder its image names are relative to.
        merge_radius, inliers_only: see :func:`slime_match.runs.export.merge_keypoints` and ``read_run``.
        overwrite: replace ``output`` when it holds an earlier hloc export (a non-empty folder is refused
            otherwise).

    Returns:
        The summary (also ``summary.json``): images, pairs, keypoints and matches written, seconds.
    """
    h5py = _h5py()
    out = Path(output)
    check_export_folder(out, EXPORT_FILES, "hloc", overwrite)
    start = time.perf_counter()
    pairs = read_run(run, inliers_only)
    names = check_images(pairs, image_dir)
    sizes = {name: image_size(Path(image_dir) / name) for name in names}
    keypoints, matches, scores = merge_keypoints(pairs, merge_radius)
    with staged_folder(out) as staging:
        with h5py.File(staging / FEATURES_FILE, "w") as features:
            for name in names:
                group = features.create_group(name)
                group.create_dataset("keypoints", data=keypoints[name].astype(np.float32))
                group.create_dataset("image_size", data=np.array(sizes[name], np.int64))
        with h5py.File(staging / MATCHES_FILE, "w") as matches_h5:
            for pair, pair_matches, pair_scores in zip(pairs, matches, scores):
                matches0 = np.full(len(keypoints[pair.name0]), -1, np.int32)
                scores0 = np.zeros(len(keypoints[pair.name0]), np.float32)
                matches0[pair_matches[:, 0]] = pair_matches[:, 1]
                scores0[pair_matches[:, 0]] = similarity(pair_scores)
                group = matches_h5.require_group(pair_key(pair.name0, pair.name1))
                group.create_dataset("matches0", data=matches0)
                group.create_dataset("matching_scores0", data=scores0)
        write_pairs(staging / PAIRS_FILE, [(p.name0, p.name1) for p in pairs])
        summary = {
            "run": str(run), "images": len(names), "pairs": len(pairs), "merge_radius": merge_radius,
            "inliers_only": inliers_only, "keypoints": int(sum(len(k) for k in keypoints.values())),
            "matches": int(sum(len(m) for m in matches)), "seconds": round(time.perf_counter() - start, 2),
        }
        save_json(staging / SUMMARY_FILE, summary)
    logger.info("hloc export: %d images, %d keypoints, %d one-to-one matches in %d pairs", summary["images"],
                summary["keypoints"], summary["matches"], summary["pairs"])
    return summary
