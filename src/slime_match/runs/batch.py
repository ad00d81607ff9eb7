"""Many pairs in one run (``slime pairs``): a pairs file in, one output folder per pair, resumable.

A pairs file lists one pair per line, two image names separated by spaces (the format of hloc's pairs
files); blank lines and ``#`` comments are ignored, and relative names are resolved against an image folder.
Every pair gets the folder ``OUT/<name0>__<name1>/`` (``/`` in names becomes ``-``) with the files of
``slime match``; ``OUT/pairs.json`` indexes them and ``OUT/run.json`` records the configuration, so that a
rerun skips the finished pairs and refuses to mix configurations.
"""

from __future__ import annotations

import copy
import json
import logging
import multiprocessing
import os
import signal
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from multiprocessing.context import SpawnProcess
from pathlib import Path
from typing import Any

from tqdm import tqdm

from .. import __version__
from .._runtime.cpus import available_cpus
from ..config import MatchConfig
from ..errors import ConfigError, ImageError, some_of
from ..io import jsonable, load_image, save_json
from ..matcher import FEATURE_CACHE_MB, Matcher
from .outputs import SUMMARY_FILE, is_complete, write_pair_outputs
from .schedule import PairScheduler, RecentImages

logger = logging.getLogger("slime_match")

INDEX_FILE = "pairs.json"
RUN_FILE = "run.json"


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


def read_pairs(pairs_file: str | os.PathLike, image_dir: str | os.PathLike = ".") -> list[PairJob]:
    """Parse a pairs file and check that every image it names exists.

    Args:
        pairs_file: text file, one ``name0 name1`` pair per line.
        image_dir: folder that relative names are resolved against.

    Returns:
        The pairs in file order, repeated pairs once.

    Raises:
        ConfigError: unreadable file, a line without exactly two names, no pair, two pairs sharing a folder.
        ImageError: listed images that do not exist (their count, and the first five named).
    """
    path = Path(pairs_file)
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()  # a BOM (Windows editors) is not a name
    except (OSError, UnicodeDecodeError) as error:
        raise ConfigError(f"cannot read the pairs file {path}: {error}") from None
    jobs: dict[tuple[str, str], PairJob] = {}
    folders: dict[str, tuple[str, str]] = {}
    for number, line in enumerate(lines, 1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        if len(fields) != 2:
            raise ConfigError(f"{path}:{number}: expected two image names, got {len(fields)}: {line.strip()!r}")
        key = (fields[0], fields[1])
        if key in jobs:
            continue
        folder = f"{_slug(fields[0])}__{_slug(fields[1])}"
        if folders.setdefault(folder, key) != key:
            raise ConfigError(f"{path}:{number}: pairs {folders[folder]} and {key} would share the output "
                              f"folder {folder!r}; rename one of the images")
        jobs[key] = PairJob(fields[0], fields[1], Path(image_dir) / fields[0], Path(image_dir) / fields[1], folder)
    if not jobs:
        raise ConfigError(f"{path} lists no pair (one 'image0 image1' per line)")
    missing = sorted({str(p) for job in jobs.values() for p in (job.path0, job.path1) if not p.is_file()})
    if missing:
        raise ImageError(f"{len(missing)} image(s) listed in {path} not found (image folder {image_dir}): "
                         f"{some_of(missing, 5)}")
    return list(jobs.values())


def _slug(name: str) -> str:
    return name.replace("\\", "/").strip("/").replace("/", "-")


def match_pairs(config: MatchConfig, jobs: list[PairJob], output: str | os.PathLike, workers: int = 1,
                overwrite: bool = False, plot: bool = False, feature_cache_mb: float = FEATURE_CACHE_MB,
                progress: bool = True) -> list[dict[str, Any]]:
    """Match every pair into ``output/<folder>/``, skipping the pairs already finished there.

    The pairs are matched in the order that best reuses each worker's feature cache
    (:class:`~slime_match.runs.schedule.PairScheduler`); the records keep ``jobs`` order.

    Args:
        config: the matcher configuration (the same for every pair).
        jobs: pairs from :func:`read_pairs`.
        output: the run folder.
        workers: processes matching pairs at once; the CPU threads are split among them.
        overwrite: recompute finished pairs (and accept a run folder made with another configuration).
        plot: also draw each pair's matches.png.
        feature_cache_mb: memory (MiB, shared by the workers) for the Slime features of recent images, reused
            by later pairs with the same image (see :class:`Matcher`); 0 turns it off.

    Returns:
        One record per pair, in ``jobs`` order: names, folder, status ("done", "skipped" or "failed"),
        matches, seconds, for Slime the feature sets it used and how many of them came from the cache
        (``feature_sets``, ``cached_feature_sets``) and, for failures, the error. The same list is written to
        ``output/pairs.json``.

    Raises:
        ConfigError: ``workers`` < 1, or ``output`` holds a run with another configuration.
    """
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    out = Path(output)
    # resolves "auto" choices and fails early on missing weights or a missing GPU (and a bad cache budget)
    matcher = Matcher(config, feature_cache_mb=feature_cache_mb)
    _claim_run_folder(out, matcher.config, overwrite)
    records: dict[int, dict[str, Any]] = {}
    todo = []
    for index, job in enumerate(jobs):
        if not overwrite and is_complete(out / job.folder):
            records[index] = _record(job, "skipped", **_finished_counts(out / job.folder))
        else:
            todo.append(index)
    progress = tqdm(total=len(jobs), initial=len(records), desc="pairs", unit="pair", file=sys.stderr,
                    disable=None if progress else True)  # None: a bar only when stderr is a terminal
    if workers == 1 or len(todo) <= 1:
        finished = _match_in_process(matcher, jobs, todo, out, plot)
    else:
        finished = _match_in_workers(matcher, jobs, todo, out, plot, workers, feature_cache_mb / workers)
    try:
        for index, record in finished:
            records[index] = record
            if record["status"] == "failed":
                logger.warning("%s %s: %s", record["image0"], record["image1"], record["error"])
            progress.set_postfix_str(f"{record['image0']} {record['image1']}: {record['matches'] or 0} matches")
            progress.update()
    finally:
        finished.close()  # stops the workers when the loop ends early
        progress.close()
        ordered = [records[i] for i in sorted(records)]
        save_json(out / INDEX_FILE, {"pairs": ordered, "finished": len(records) == len(jobs)})
    return ordered


def _claim_run_folder(out: Path, config: MatchConfig, overwrite: bool) -> None:
    """Record the configuration in ``out/run.json``; refuse to resume a run made with another one."""
    current = jsonable(config.to_dict())
    run_file = out / RUN_FILE
    if run_file.is_file() and not overwrite:
        previous = json.loads(run_file.read_text()).get("config")
        if previous != current:
            changed = sorted(_differences(previous or {}, current))
            raise ConfigError(f"{out} holds a run made with another configuration (differs in: "
                              f"{', '.join(changed) or 'everything'}): use another output folder or --overwrite")
        return
    save_json(run_file, {"slime_match_version": __version__, "config": current})


def _differences(a: dict, b: dict, prefix: str = "") -> list[str]:
    """Dotted keys whose values differ between two nested dicts."""
    keys = []
    for key in sorted(set(a) | set(b)):
        va, vb = a.get(key), b.get(key)
        if isinstance(va, dict) and isinstance(vb, dict):
            keys += _differences(va, vb, f"{prefix}{key}.")
        elif va != vb:
            keys.append(prefix + key)
    return keys


def _record(job: PairJob, status: str, matches: int | None = None, seconds: float | None = None,
            error: str | None = None, **cache: int) -> dict[str, Any]:
    """A pair's entry of pairs.json; ``cache``: Slime's ``feature_sets`` and ``cached_feature_sets``."""
    record = {"image0": job.name0, "image1": job.name1, "folder": job.folder, "status": status,
              "matches": matches, "seconds": seconds, **cache}
    if error is not None:
        record["error"] = error
    return record


def _cache_counts(counts: dict[str, Any]) -> dict[str, int]:
    """The feature-set counts of a Slime summary's ``counts`` (none for the other methods)."""
    return {key: counts[key] for key in ("feature_sets", "cached_feature_sets") if key in counts}


def _finished_counts(folder: Path) -> dict[str, Any]:
    summary = json.loads((folder / SUMMARY_FILE).read_text())
    return {"matches": summary["counts"]["matches"], "seconds": summary["seconds"]["total"],
            **_cache_counts(summary["counts"])}


def _match_one(matcher: Matcher, job: PairJob, out: Path, plot: bool) -> dict[str, Any]:
    """Match one pair and write its folder; a failure (bad image, bug) is recorded, not raised."""
    start = time.perf_counter()
    try:
        image0, image1 = load_image(job.path0), load_image(job.path1)
        result = matcher(image0, image1)
        write_pair_outputs(result, image0, image1, out / job.folder, plot=plot)
    except ImageError as error:
        return _record(job, "failed", seconds=round(time.perf_counter() - start, 4), error=str(error))
    except Exception as error:  # one pair must not end a long run; the record says what happened
        logger.exception("pair %s %s failed", job.name0, job.name1)
        return _record(job, "failed", seconds=round(time.perf_counter() - start, 4),
                       error=f"{type(error).__name__}: {error}")
    return _record(job, "done", len(result), result.summary["seconds"]["total"],
                   **_cache_counts(result.summary["counts"]))


def _match_in_process(matcher: Matcher, jobs: list[PairJob], todo: list[int], out: Path, plot: bool
                      ) -> Iterator[tuple[int, dict[str, Any]]]:
    """(index, record) of the ``todo`` pairs matched here, in the order that best reuses the feature cache."""
    scheduler = PairScheduler([_images(jobs[index]) for index in todo])
    recent = RecentImages()
    while (position := scheduler.next(recent.held(_cached_images(matcher)))) is not None:
        job = jobs[todo[position]]
        record = _match_one(matcher, job, out, plot)
        recent.touch(_images(job))
        yield todo[position], record


def _images(job: PairJob) -> tuple[str, str]:
    return str(job.path0), str(job.path1)


def _cached_images(matcher: Matcher) -> int:
    return 0 if matcher.level_cache is None else matcher.level_cache.image_count


def _match_in_workers(matcher: Matcher, jobs: list[PairJob], todo: list[int], out: Path, plot: bool,
                      workers: int, feature_cache_mb: float) -> Iterator[tuple[int, dict[str, Any]]]:
    """(index, record) of the ``todo`` pairs as they finish in ``workers`` spawned processes.

    Each worker has a Matcher of ``matcher``'s configuration, a feature cache of ``feature_cache_mb`` and an
    equal share of the available CPUs (``available_cpus``: torch threads and Slime's own forked workers). A
    worker that finishes a pair is given the pair that best reuses the images its cache holds
    (:class:`PairScheduler`). A worker that dies (killed, out of memory) fails its pair and is replaced. On an
    interruption the workers are stopped at once (a pair's files are written all or nothing).
    """
    share = max(1, available_cpus() // workers)
    config = copy.deepcopy(matcher.config)
    if config.slime.workers is None:
        config.slime.workers = share
    scheduler = PairScheduler([_images(jobs[index]) for index in todo])
    context = multiprocessing.get_context("spawn")  # not fork: a forked copy of torch's thread pools can deadlock
    running: dict[Connection, tuple[SpawnProcess, int]] = {}  # a worker's pipe -> it and its pair (todo position)
    stopping: list[tuple[Connection, SpawnProcess]] = []  # workers told that no pair is left

    def start_worker(position: int) -> None:
        ours, theirs = context.Pipe()
        process = context.Process(target=_worker_main, args=(theirs, config, share, feature_cache_mb, out, plot),
                                  name="slime-pairs-worker")  # not daemonic: Slime forks workers of its own
        process.start()
        theirs.close()
        ours.send(jobs[todo[position]])
        running[ours] = (process, position)

    finished = False
    try:
        for _ in range(min(workers, len(todo))):
            start_worker(scheduler.next())
        while running:
            for pipe in wait(list(running)):
                process, position = running.pop(pipe)
                try:
                    record, cached = pipe.recv()
                except (EOFError, OSError):  # the worker died in this pair
                    process.join()
                    pipe.close()
                    record = _record(jobs[todo[position]], "failed", error="the worker process died (exit code "
                                     f"{process.exitcode}; out of memory?)")
                    if len(scheduler):
                        start_worker(scheduler.next())
                else:
                    following = scheduler.next(cached)
                    try:
                        pipe.send(None if following is None else jobs[todo[following]])
                    except OSError:  # the worker died after its answer: a new one takes its next pair
                        process.join()
                        pipe.close()
                        if following is not None:
                            start_worker(following)
                    else:
                        if following is None:  # told to stop
                            stopping.append((pipe, process))
                        else:
                            running[pipe] = (process, following)
                yield todo[position], record
        finished = True
    finally:
        for pipe, process in [*stopping, *((pipe, process) for pipe, (process, _) in running.items())]:
            if not finished:
                process.terminate()
            process.join()
            pipe.close()


def _worker_main(pipe: Connection, config: MatchConfig, threads: int, feature_cache_mb: float, out: Path,
                 plot: bool) -> None:
    """A worker of :func:`_match_in_workers`: match the pairs it is sent (None: stop), answering each with its
    record and the images its feature cache holds, the most recently used first."""
    import numba
    import torch

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle: it stops the workers
    torch.set_num_threads(threads)
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    matcher = Matcher(config, feature_cache_mb=feature_cache_mb)
    recent = RecentImages()
    while (job := pipe.recv()) is not None:
        record = _match_one(matcher, job, out, plot)
        recent.touch(_images(job))
        pipe.send((record, recent.held(_cached_images(matcher))))
