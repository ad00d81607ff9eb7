"""A ``slime pairs`` run as a COLMAP database, and optionally its sparse reconstruction (``slime colmap``).

The run's keypoints are merged into one list per image with one-to-one matches (:mod:`.export`); COLMAP's
own geometric verification and incremental mapper (pycolmap, an optional dependency) do the rest.
"""

from __future__ import annotations

import logging
import os
import shutil
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from slime_match.choices import CAMERA_MODES

from ..errors import ConfigError, ImageError, SlimeMatchError
from ..io import save_json
from .export import (
    PairMatches,
    check_export_folder,
    check_images,
    merge_keypoints,
    read_run,
    staged_folder,
)
from .outputs import SUMMARY_FILE
from .pair_lists import write_pairs

logger = logging.getLogger("slime_match")

DATABASE_FILE = "database.db"
VERIFIED_PAIRS_FILE = "pairs.txt"
SPARSE_FOLDER = "sparse"
EXPORT_FILES = (DATABASE_FILE, VERIFIED_PAIRS_FILE, SUMMARY_FILE, SPARSE_FOLDER)  # the database first: the mark


# The eight ways a file's EXIF orientation turns its stored pixels (raw, h x w) into the upright image:
# (the upright array from the raw one, the raw (x, y) of upright pixel centres (x, y)).
_ORIENTATIONS = (
    (lambda a: a, lambda x, y, w, h: (x, y)),
    (lambda a: a[:, ::-1], lambda x, y, w, h: (w - 1 - x, y)),
    (lambda a: a[::-1, ::-1], lambda x, y, w, h: (w - 1 - x, h - 1 - y)),
    (lambda a: a[::-1], lambda x, y, w, h: (x, h - 1 - y)),
    (lambda a: a.T, lambda x, y, w, h: (y, x)),
    (lambda a: np.rot90(a, -1), lambda x, y, w, h: (y, h - 1 - x)),
    (lambda a: a[::-1, ::-1].T, lambda x, y, w, h: (w - 1 - y, h - 1 - x)),
    (lambda a: np.rot90(a, 1), lambda x, y, w, h: (w - 1 - y, x)),
)


def to_stored_frame(points: np.ndarray, path: str | os.PathLike) -> np.ndarray:
    """Keypoints of an upright image file (turned by its EXIF orientation, as ``io.load_image`` does) in the
    frame of its stored pixels, which COLMAP reads.

    Args:
        points: (N, 2) positions (px) in the upright image, top-left pixel centre = (0, 0).
        path: the image file.

    Returns:
        (N, 2) positions in the stored pixels (the same positions when the file has no EXIF turn).

    Raises:
        ImageError: the file cannot be decoded, or no turn of its stored pixels gives its upright image.
    """
    data = np.fromfile(str(path), dtype=np.uint8)
    upright = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) if data.size else None
    stored = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_IGNORE_ORIENTATION) if data.size else None
    if upright is None or stored is None:
        raise ImageError(f"{path}: not a readable image (corrupt file or unsupported format)")
    h, w = stored.shape
    for turn, stored_xy in _ORIENTATIONS:
        if np.array_equal(turn(stored), upright):  # False on other shapes
            return np.stack(stored_xy(*points.T, w, h), 1)
    raise ImageError(f"{path}: its upright image is no turn of its stored pixels (EXIF orientation)")


def _pycolmap():
    try:
        import pycolmap  # an optional dependency: the package's "colmap" extra
    except ImportError as error:
        raise ConfigError("slime colmap needs pycolmap: pip install 'slime-match[colmap]' (or pycolmap)"
                          ) from error
    return pycolmap


def write_database(path: str | os.PathLike, image_dir: str | os.PathLike, keypoints: dict[str, np.ndarray],
                   pairs: list[PairMatches], matches: list[np.ndarray], camera_mode: str = "auto") -> None:
    """Create the COLMAP database ``path``: images (cameras from their EXIF data, as COLMAP does), keypoints
    (in the frame of the stored pixels, which COLMAP does not turn by the EXIF orientation, and with COLMAP's
    pixel convention: top-left pixel centre = (0.5, 0.5)) and raw matches.

    Args:
        image_dir: the folder the image names are relative to.
        keypoints, matches: from :func:`merge_keypoints` (``matches`` in ``pairs`` order).
        camera_mode: "auto", "single", "per-folder" or "per-image" (COLMAP's camera sharing).
    """
    pycolmap = _pycolmap()
    if camera_mode not in CAMERA_MODES:
        raise ConfigError(f"camera_mode must be one of {', '.join(CAMERA_MODES)}, got {camera_mode!r}")
    mode = pycolmap.CameraMode.__members__[camera_mode.upper().replace("-", "_")]
    pycolmap.Database.open(path).close()  # import_images needs the file
    pycolmap.import_images(path, image_dir, mode, sorted(keypoints))
    with pycolmap.Database.open(path) as db:
        ids = {image.name: image.image_id for image in db.read_all_images()}
        missing = sorted(set(keypoints) - set(ids))
        if missing:
            raise SlimeMatchError(f"COLMAP could not import {len(missing)} image(s) from {image_dir}: "
                                  f"{', '.join(missing[:5])}")
        for name, points in keypoints.items():
            stored = to_stored_frame(points, Path(image_dir) / name)
            db.write_keypoints(ids[name], (stored + 0.5).astype(np.float32))
        for pair, pair_matches in zip(pairs, matches):
            db.write_matches(ids[pair.name0], ids[pair.name1], pair_matches.astype(np.uint32))


def export_run(run: str | os.PathLike, image_dir: str | os.PathLike, output: str | os.PathLike,
               merge_radius: float = 1.0, inliers_only: bool = False, camera_mode: str = "auto",
               reconstruct: bool = True, seed: int = 0, threads: int = 1, overwrite: bool = False
               ) -> dict[str, Any]:
    """A ``slime pairs`` run as a COLMAP database, geometrically verified by COLMAP, and (``reconstruct``)
    COLMAP's incremental reconstruction of it.

    Writes ``output/{database.db, pairs.txt, summary.json}`` and, with ``reconstruct``, ``output/sparse/N/``
    (COLMAP's binary model files, largest model first), all or nothing.

    Args:
        run: the ``slime pairs`` run folder; image_dir: the folder its image names are relative to.
        merge_radius, inliers_only: see :func:`merge_keypoints`, :func:`read_run`.
        camera_mode: see :func:`write_database`.
        seed: COLMAP's random seed (verification and mapping).
        threads: COLMAP's mapping threads; with 1 the models are the same on every run, with more (faster on
            large runs) they may differ slightly.
        overwrite: replace ``output`` when it holds an earlier export (a non-empty folder is refused
            otherwise).

    Returns:
        The summary (also ``summary.json``): keypoints and matches kept, verified pairs (with a two-view
        geometry of at least one inlier; COLMAP drops the raw matches of the others) and, per model,
        registered images, 3D points, mean track length and mean reprojection error (px).
    """
    pycolmap = _pycolmap()
    if seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed}")
    if threads < 1:
        raise ConfigError(f"threads must be >= 1, got {threads}")
    out = Path(output)
    check_export_folder(out, EXPORT_FILES, "COLMAP", overwrite)
    start = time.perf_counter()
    pairs = read_run(run, inliers_only)
    check_images(pairs, image_dir)
    keypoints, matches, _ = merge_keypoints(pairs, merge_radius)
    logger.info("COLMAP export: %d images, %d keypoints, %d one-to-one matches in %d pairs", len(keypoints),
                sum(len(k) for k in keypoints.values()), sum(len(m) for m in matches), len(pairs))
    with _colmap_logs(pycolmap, shown=logger.getEffectiveLevel() <= logging.INFO), staged_folder(out) as staging:
        database = staging / DATABASE_FILE
        write_database(database, image_dir, keypoints, pairs, matches, camera_mode)
        pairs_file = staging / VERIFIED_PAIRS_FILE
        write_pairs(pairs_file, [(p.name0, p.name1) for p in pairs])
        verification = pycolmap.TwoViewGeometryOptions()
        verification.ransac.random_seed = seed
        pycolmap.verify_matches(database, pairs_file, verification)
        with pycolmap.Database.open(database) as db:
            # num_verified_image_pairs() also counts the pairs that verification rejected (no inlier)
            verified = sum(count > 0 for count in db.read_two_view_geometry_num_inliers()[1])
        logger.info("COLMAP export: %d of %d pairs verified", verified, len(pairs))
        summary: dict[str, Any] = {
            "run": str(run), "images": len(keypoints), "pairs": len(pairs), "verified_pairs": verified,
            "merge_radius": merge_radius, "inliers_only": inliers_only, "camera_mode": camera_mode,
            "keypoints": int(sum(len(k) for k in keypoints.values())),
            "matches": int(sum(len(m) for m in matches)),
        }
        if reconstruct:
            summary["models"] = _reconstruct(pycolmap, database, Path(image_dir), staging / SPARSE_FOLDER, seed,
                                            threads)
        summary["seconds"] = round(time.perf_counter() - start, 2)
        save_json(staging / SUMMARY_FILE, summary)
    return summary


@contextmanager
def _colmap_logs(pycolmap, shown: bool) -> Iterator[None]:
    """COLMAP's info log on (``shown``) or off (its errors only: its info lines run to thousands) in the block."""
    level = pycolmap.logging.minloglevel
    if not shown:
        pycolmap.logging.minloglevel = 2
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = level


def _reconstruct(pycolmap, database: Path, image_dir: Path, sparse: Path, seed: int, threads: int
                 ) -> list[dict[str, Any]]:
    """COLMAP's incremental mapping into ``sparse/N``, largest model first; the statistics of each model."""
    options = pycolmap.IncrementalPipelineOptions()
    options.random_seed = seed
    options.num_threads = threads
    work = sparse.with_name(sparse.name + "-unsorted")
    work.mkdir()
    with tqdm(desc="COLMAP mapping", unit=" images registered", file=sys.stderr, disable=None) as progress:
        models = pycolmap.incremental_mapping(database, image_dir, work, options,
                                              initial_image_pair_callback=lambda: progress.update(2),
                                              next_image_callback=lambda: progress.update(1))
    ranked = sorted(models.values(), key=lambda model: model.num_reg_images(), reverse=True)
    sparse.mkdir()
    stats = []
    for index, model in enumerate(ranked):
        (sparse / str(index)).mkdir()
        model.write(sparse / str(index))
        stats.append({"registered_images": model.num_reg_images(), "points3D": model.num_points3D(),
                      "mean_track_length": round(model.compute_mean_track_length(), 3),
                      "mean_reprojection_error": round(model.compute_mean_reprojection_error(), 3),
                      "images": sorted(image.name for image in model.images.values() if image.has_pose)})
    shutil.rmtree(work)
    return stats
