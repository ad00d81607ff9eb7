"""One pair of a batch: its job, its matching into its folder, and its record, the same in every process that
matches pairs (this one, a spawned worker, a Ray actor)."""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ImageError
from ..io import load_image
from ..matcher import Matcher
from .outputs import SUMMARY_FILE, remove_pair_outputs, write_pair_outputs
from .schedule import RecentImages

logger = logging.getLogger("slime_match")


@dataclass(frozen=True)
class PairJob:
    """One line of a pairs file.

    Attributes:
        name0, name1: the image names as written in the pairs file.
        path0, path1: the resolved image paths.
        folder: the pair's output folder name (relative to the run folder).
    """

    name0: str
    name1: str
    path0: Path
    path1: Path
    folder: str


def pair_record(job: PairJob, status: str, matches: int | None = None, seconds: float | None = None,
                error: str | None = None, **cache: int) -> dict[str, Any]:
    """A pair's entry of pairs.json; ``cache``: Slime's ``feature_sets`` and ``cached_feature_sets``."""
    record = {"image0": job.name0, "image1": job.name1, "folder": job.folder, "status": status,
              "matches": matches, "seconds": seconds, **cache}
    if error is not None:
        record["error"] = error
    return record


def cache_counts(counts: dict[str, Any]) -> dict[str, int]:
    """The feature-set counts of a Slime summary's ``counts`` (none for the other methods)."""
    return {key: counts[key] for key in ("feature_sets", "cached_feature_sets") if key in counts}


def finished_counts(folder: Path) -> dict[str, Any]:
    """matches, seconds and feature-set counts of a finished pair folder, from its summary.json."""
    summary = json.loads((folder / SUMMARY_FILE).read_text())
    return {"matches": summary["counts"]["matches"], "seconds": summary["seconds"]["total"],
            **cache_counts(summary["counts"])}


def match_one(matcher: Matcher, job: PairJob, out: Path, plot: bool) -> dict[str, Any]:
    """Match one pair and write its folder under ``out``; a failure (bad image, bug) is recorded, not raised,
    and removes an earlier result's files from the pair's folder."""
    start = time.perf_counter()
    try:
        image0, image1 = load_image(job.path0), load_image(job.path1)
        result = matcher(image0, image1)
        write_pair_outputs(result, image0, image1, out / job.folder, plot=plot)
    except ImageError as error:
        remove_pair_outputs(out / job.folder)
        return pair_record(job, "failed", seconds=round(time.perf_counter() - start, 4), error=str(error))
    except Exception as error:  # one pair must not end a long run; the record says what happened
        logger.exception("pair %s %s failed", job.name0, job.name1)
        remove_pair_outputs(out / job.folder)
        return pair_record(job, "failed", seconds=round(time.perf_counter() - start, 4),
                           error=f"{type(error).__name__}: {error}")
    return pair_record(job, "done", len(result), result.summary["seconds"]["total"],
                       **cache_counts(result.summary["counts"]))


def job_images(job: PairJob) -> tuple[str, str]:
    """The pair's image identities for :class:`~slime_match.runs.schedule.PairScheduler`: their paths."""
    return str(job.path0), str(job.path1)


class PairWorker:
    """A Matcher matching pairs one after another into the run folder ``out`` (this process, a spawned worker
    or a Ray actor), and the images whose features its cache holds."""

    def __init__(self, matcher: Matcher, out: Path, plot: bool) -> None:
        self.matcher, self.out, self.plot = matcher, out, plot
        self._recent = RecentImages()

    def match(self, job: PairJob) -> dict[str, Any]:
        """Match one pair (:func:`match_one`) and remember its images; its record."""
        record = match_one(self.matcher, job, self.out, self.plot)
        self._recent.touch(job_images(job))
        return record

    def held(self) -> list[str]:
        """The images the feature cache holds, the most recently used first (for ``PairScheduler.next``)."""
        cache = self.matcher.level_cache
        return self._recent.held(0 if cache is None else cache.image_count)


def set_threads(threads: int) -> None:
    """Let this process's torch and numba use ``threads`` threads (numba at most its configured count)."""
    import numba
    import torch

    torch.set_num_threads(threads)
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
