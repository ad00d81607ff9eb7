"""A ``slime pairs`` run's matches prepared for structure-from-motion tools (``slime colmap``, ``slime hloc``).

Slime matches each pair on its own: one image's keypoints differ from pair to pair, and within a pair a
keypoint may take part in several matches (Slime keeps duplicated keypoints of overlapping blocks). SfM tools
want one keypoint list per image and one-to-one matches per pair. So, per image, every keypoint of every pair
it is in is pooled, exact duplicates merged, and the rest clustered greedily around the best-scored ones
within ``merge_radius`` px (``slime.clusters.greedy_clusters``): each cluster becomes one keypoint at its
representative's position. Per pair, the matches then map to keypoint pairs, of which a one-to-one subset is
kept by score (``matching.nn_kernels.greedy_accept``). Exports are staged and moved into place all or nothing.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError, ImageError, SlimeMatchError, some_of
from ..io import current_umask, load_npz
from ..matching.nn_kernels import greedy_accept
from ..slime.clusters import greedy_clusters
from .index import INDEX_FILE
from .outputs import MATCHES_FILE


@dataclass
class PairMatches:
    """The matches of one pair of a run.

    Attributes:
        name0, name1: image names (relative to the image folder).
        keypoints0, keypoints1: (K, 2) float64 positions in pixels, top-left pixel centre = (0, 0).
        scores: (K,) dissimilarities, lower is better.
    """

    name0: str
    name1: str
    keypoints0: np.ndarray
    keypoints1: np.ndarray
    scores: np.ndarray


def read_run(run: str | os.PathLike, inliers_only: bool = False) -> list[PairMatches]:
    """The finished pairs of a ``slime pairs`` run folder, in its index's order.

    Args:
        run: the run folder (holds ``pairs.json``).
        inliers_only: keep only the matches the run's RANSAC accepted (the run must have used ``--ransac``).

    Raises:
        SlimeMatchError: no ``pairs.json``, no finished pair, or (``inliers_only``) a pair without inliers.
    """
    run = Path(run)
    try:
        records = json.loads((run / INDEX_FILE).read_text())["pairs"]
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise SlimeMatchError(f"{run} is not a `slime pairs` run folder (cannot read its {INDEX_FILE}: "
                              f"{error})") from None
    pairs = []
    for record in records:
        if record.get("status") not in ("done", "skipped"):
            continue
        required = ("keypoints0", "keypoints1", "scores") + (("inliers",) if inliers_only else ())
        hint = "match the pairs with --ransac to use --inliers-only" if inliers_only else ""
        arrays = load_npz(run / record["folder"] / MATCHES_FILE, "matches file", required, hint)
        keep = arrays["inliers"].astype(bool) if inliers_only else slice(None)
        pairs.append(PairMatches(record["image0"], record["image1"], arrays["keypoints0"][keep],
                                 arrays["keypoints1"][keep], arrays["scores"][keep]))
    if not pairs:
        raise SlimeMatchError(f"{run} has no finished pair ({INDEX_FILE} lists {len(records)} pairs)")
    return pairs


def merge_keypoints(pairs: list[PairMatches], merge_radius: float = 1.0
                    ) -> tuple[dict[str, np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """One keypoint list per image and one-to-one matches per pair.

    Args:
        pairs: the matches of each pair.
        merge_radius: keypoints of one image within this distance (px, in both coordinates) of a
            better-scored one become one with it; 0 merges only identical positions.

    Returns:
        keypoints: per image name, (N, 2) float64 positions (px), best-scored first.
        matches: per pair, (M, 2) int64 indices into its two images' keypoints, one-to-one, best first.
        scores: per pair, (M,) float64 dissimilarities of those matches (the run's, lower is better).
    """
    if not merge_radius >= 0:  # NaN too
        raise ConfigError(f"merge_radius must be >= 0 px, got {merge_radius}")
    pooled: dict[str, list[tuple[int, int]]] = {}  # image -> (pair, side) in pooling order
    for p, pair in enumerate(pairs):
        pooled.setdefault(pair.name0, []).append((p, 0))
        pooled.setdefault(pair.name1, []).append((p, 1))
    keypoints: dict[str, np.ndarray] = {}
    index_of: dict[tuple[int, int], np.ndarray] = {}
    for name, members in pooled.items():
        points = np.concatenate([_side(pairs[p], s) for p, s in members]).astype(np.float64)
        scores = np.concatenate([pairs[p].scores for p, _ in members]).astype(np.float64)
        unique, inverse = np.unique(points, axis=0, return_inverse=True)
        best = np.full(len(unique), np.inf)
        np.minimum.at(best, inverse.reshape(-1), scores)
        reps, cluster = greedy_clusters(unique, best, merge_radius)
        keypoints[name] = unique[reps]
        ids = cluster[inverse.reshape(-1)]
        bounds = np.cumsum([0] + [len(pairs[p].scores) for p, _ in members])
        for (p, s), start, stop in zip(members, bounds[:-1], bounds[1:]):
            index_of[p, s] = ids[start:stop]
    matches, match_scores = [], []
    for p, pair in enumerate(pairs):
        ids = np.stack([index_of[p, 0], index_of[p, 1]], 1)
        order = np.argsort(pair.scores, kind="stable")
        accepted = greedy_accept(ids[:, 0], ids[:, 1], order, 1) if len(ids) else np.zeros(0, bool)
        kept = order[accepted[order]]
        matches.append(ids[kept])
        match_scores.append(pair.scores[kept].astype(np.float64))
    return keypoints, matches, match_scores


def _side(pair: PairMatches, side: int) -> np.ndarray:
    return pair.keypoints0 if side == 0 else pair.keypoints1


def check_images(pairs: list[PairMatches], image_dir: str | os.PathLike) -> list[str]:
    """The sorted image names of ``pairs``; ImageError when any is not a file under ``image_dir``."""
    names = sorted({name for pair in pairs for name in (pair.name0, pair.name1)})
    missing = [name for name in names if not (Path(image_dir) / name).is_file()]
    if missing:
        raise ImageError(f"{len(missing)} image(s) of the run not found in {image_dir}: {some_of(missing, 5)}")
    return names


def check_export_folder(out: Path, own: tuple[str, ...], tool: str, overwrite: bool) -> None:
    """Refuse an output folder that is a file or is not empty, unless ``overwrite`` and it holds an earlier
    export of ``tool`` ("COLMAP", "hloc") and nothing else: ``own`` names the export's files and folders, the
    first one marking an export. A user's file in the folder is never deleted with it."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"output folder {out} is a file, not a folder: choose another output folder")
    if not out.is_dir() or not any(out.iterdir()):
        return
    if not (out / own[0]).is_file():
        raise ConfigError(f"{out} is not empty and holds no {tool} export: choose another output folder")
    if not overwrite:
        raise ConfigError(f"{out} holds an earlier {tool} export: use --overwrite to replace it")
    others = sorted(p.name for p in out.iterdir() if p.name not in own)
    if others:
        raise ConfigError(f"{out} holds files that are not part of a {tool} export ({some_of(others, 3)}), which "
                          "--overwrite would delete: move them or choose another output folder")


@contextmanager
def staged_folder(out: Path) -> Iterator[Path]:
    """A fresh folder beside ``out`` to write an export into; it replaces ``out`` when the block ends without
    an error, and is removed otherwise. The earlier ``out`` is renamed aside before the new one takes its name,
    and deleted after. The folder gets the permissions of a plain ``mkdir`` under the umask."""
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}-staging-"))
    os.chmod(staging, 0o777 & ~current_umask())  # a plain mkdir's permissions (mkdtemp's are owner-only)
    earlier = None
    try:
        yield staging
        if out.exists():
            earlier = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}-earlier-"))
            os.replace(out, earlier)  # replaces the empty folder just made
        os.replace(staging, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        if earlier is not None:
            shutil.rmtree(earlier, ignore_errors=True)
