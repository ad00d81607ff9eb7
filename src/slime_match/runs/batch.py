"""Many pairs in one run (``slime pairs``): a pairs file in, one output folder per pair, resumable.

A pairs file lists one pair per line, two image names separated by spaces (the format of hloc's pairs
files); blank lines and ``#`` comments are ignored, and relative names are resolved against an image folder.
Every pair gets the folder ``OUT/<name0>__<name1>/`` (``/`` in names becomes ``-``) with the files of
``slime match`` and its record ``OUT/records/<name0>__<name1>.json``; ``OUT/pairs.json`` indexes the records
and ``OUT/run.json`` records the configuration, so that a rerun skips the finished pairs and refuses to mix
configurations. The pairs are matched here, in spawned worker processes, or by the actors of a Ray cluster
(:mod:`~slime_match.runs.ray_backend`); a run may also be split into shards (:mod:`~slime_match.runs.shards`)
matched at once by several processes into one run folder.
"""

from __future__ import annotations

import copy
import logging
import multiprocessing
import os
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from multiprocessing.connection import Connection, wait
from multiprocessing.context import SpawnProcess
from pathlib import Path
from types import ModuleType
from typing import Any

from tqdm import tqdm

from .._runtime.cpus import available_cpus
from ..choices import BATCH_BACKENDS
from ..config import MatchConfig
from ..errors import ConfigError, ImageError, some_of
from ..matcher import FEATURE_CACHE_MB, Matcher
from .index import RUN_FILE, claim_run_folder, drop_other_pairs, write_index, write_record
from .outputs import is_complete
from .pair_tasks import PairJob, PairWorker, finished_counts, job_images, pair_record, set_threads
from .ray_backend import check_node_cpus, connected, match_on_ray
from .schedule import PairScheduler
from .shards import check_shard, shard_positions

logger = logging.getLogger("slime_match")


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


def match_pairs(config: MatchConfig, jobs: list[PairJob], output: str | os.PathLike, workers: int | None = None,
                overwrite: bool = False, plot: bool = False, feature_cache_mb: float = FEATURE_CACHE_MB,
                progress: bool = True, backend: str = "local", ray_address: str = "auto",
                cpus_per_worker: int | None = None, shard: tuple[int, int] | None = None) -> list[dict[str, Any]]:
    """Match every pair (of the shard) into ``output/<folder>/``, skipping the pairs already finished there.

    The pairs are matched in the order that best reuses each worker's feature cache
    (:class:`~slime_match.runs.schedule.PairScheduler`). Each finished pair's record is written to
    ``output/records/`` as it comes, and ``output/pairs.json`` is rebuilt from the records at the end (also
    on an interruption).

    Args:
        config: the matcher configuration (the same for every pair).
        jobs: pairs from :func:`read_pairs`.
        output: the run folder.
        workers: pairs matched at once: local processes (None: 1), or Ray actors (None: as many as the
            cluster's CPUs hold, ``cpus_per_worker`` each).
        overwrite: recompute finished pairs, and accept a run folder made with another configuration (whose
            pairs that ``jobs`` does not list are then removed: no result of another configuration stays).
        plot: also draw each pair's matches.png.
        feature_cache_mb: memory (MiB) for the Slime features of recent images, reused by later pairs with
            the same image (see :class:`Matcher`): shared by the local workers, each Ray actor's own; 0 turns
            it off.
        progress: a progress bar on stderr when it is a terminal.
        backend: "local" (this machine) or "ray" (the actors of a Ray cluster).
        ray_address: the Ray cluster, "auto" or its head's ``host:port`` (see
            :func:`~slime_match.runs.ray_backend.connected`).
        cpus_per_worker: CPUs of each local worker or Ray actor, the threads and Slime workers of its Matcher
            (None: local workers share the CPUs this process may use equally, a Ray actor takes 1).
        shard: (I, N): match only part I of N of ``jobs`` (:func:`~slime_match.runs.shards.shard_positions`);
            the index still covers every pair of ``jobs``.

    Returns:
        One record per pair matched or skipped here, in ``jobs`` order: names, folder, status ("done",
        "skipped" or "failed"), matches, seconds, for Slime the feature sets it used and how many of them came
        from the cache (``feature_sets``, ``cached_feature_sets``) and, for failures, the error. pairs.json
        lists the records of every pair of ``jobs`` that has one ("done" or "failed"), and ``finished`` when
        every pair has one.

    Raises:
        ConfigError: a bad worker count, backend or shard, Ray missing or unreachable, or ``output`` holding a
            run with another configuration.
    """
    if workers is not None and workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    if cpus_per_worker is not None and cpus_per_worker < 1:
        raise ConfigError(f"cpus per worker must be >= 1, got {cpus_per_worker}")
    if backend not in BATCH_BACKENDS:
        raise ConfigError(f"unknown backend {backend!r}: expected one of {', '.join(BATCH_BACKENDS)}")
    if shard is not None:
        check_shard(shard)
    out = Path(output)
    # a missing Ray, no cluster or no node of cpus_per_worker CPUs fail before the run folder is touched
    with _cluster(backend, ray_address, cpus_per_worker or 1) as ray:
        # resolves "auto" choices and fails early on missing weights or a missing GPU (and a bad cache budget)
        matcher = Matcher(config, feature_cache_mb=feature_cache_mb)
        if claim_run_folder(out, matcher.config, overwrite) and (dropped := drop_other_pairs(out, jobs)):
            logger.warning("removed %d pair(s) of the earlier configuration that the pairs file does not list (%s)",
                           len(dropped), some_of(dropped, 3))
        selected = range(len(jobs)) if shard is None else shard_positions([job_images(j) for j in jobs], *shard)
        records: dict[int, dict[str, Any]] = {}
        todo = []
        for index in selected:
            if not overwrite and is_complete(out / jobs[index].folder):
                records[index] = pair_record(jobs[index], "skipped", **finished_counts(out / jobs[index].folder))
            else:
                todo.append(index)
        bar = tqdm(total=len(selected), initial=len(records), desc="pairs", unit="pair", file=sys.stderr,
                   disable=None if progress else True)  # None: a bar only when stderr is a terminal
        if ray is not None and todo:
            finished = match_on_ray(ray, matcher.config, jobs, todo, out, plot, workers, cpus_per_worker or 1,
                                    feature_cache_mb)
        elif (workers or 1) == 1 or len(todo) <= 1:
            finished = _match_in_process(matcher, jobs, todo, out, plot)
        else:
            finished = _match_in_workers(matcher, jobs, todo, out, plot, workers, cpus_per_worker,
                                         feature_cache_mb / workers)
        try:
            for index, record in finished:
                write_record(out, record)
                records[index] = record
                if record["status"] == "failed":
                    logger.warning("%s %s: %s", record["image0"], record["image1"], record["error"])
                bar.set_postfix_str(f"{record['image0']} {record['image1']}: {record['matches'] or 0} matches")
                bar.update()
        finally:
            finished.close()  # stops the workers when the loop ends early
            bar.close()
            write_index(out, jobs)
        return [records[i] for i in sorted(records)]


@contextmanager
def _cluster(backend: str, address: str, threads: int) -> Iterator[ModuleType | None]:
    """Within the block, the ``ray`` module connected to the cluster at ``address`` that has a node of
    ``threads`` CPUs, for the "ray" backend (None for "local")."""
    if backend != "ray":
        yield None
        return
    with connected(address) as ray:
        check_node_cpus(ray, threads)
        yield ray


def reindex(jobs: list[PairJob], output: str | os.PathLike) -> dict[str, Any]:
    """Rebuild ``output/pairs.json`` from the records of ``jobs`` (see :func:`~slime_match.runs.index.
    write_index`), and return it.

    Raises:
        ConfigError: ``output`` is not a run folder (no run.json).
    """
    out = Path(output)
    if not (out / RUN_FILE).is_file():
        raise ConfigError(f"{out} is not a `slime pairs` run folder (no {RUN_FILE} in it)")
    return write_index(out, jobs)


def _match_in_process(matcher: Matcher, jobs: list[PairJob], todo: list[int], out: Path, plot: bool
                      ) -> Iterator[tuple[int, dict[str, Any]]]:
    """(index, record) of the ``todo`` pairs matched here, in the order that best reuses the feature cache."""
    scheduler = PairScheduler([job_images(jobs[index]) for index in todo])
    worker = PairWorker(matcher, out, plot)
    while (position := scheduler.next(worker.held())) is not None:
        yield todo[position], worker.match(jobs[todo[position]])


def _match_in_workers(matcher: Matcher, jobs: list[PairJob], todo: list[int], out: Path, plot: bool,
                      workers: int, cpus_per_worker: int | None, feature_cache_mb: float
                      ) -> Iterator[tuple[int, dict[str, Any]]]:
    """(index, record) of the ``todo`` pairs as they finish in ``workers`` spawned processes.

    Each worker has a Matcher of ``matcher``'s configuration, a feature cache of ``feature_cache_mb`` and
    ``cpus_per_worker`` CPUs, by default an equal share of the available CPUs (``available_cpus``): its torch
    threads and Slime's own forked workers. A
    worker that finishes a pair is given the pair that best reuses the images its cache holds
    (:class:`PairScheduler`). A worker that dies (killed, out of memory) fails its pair and is replaced. On an
    interruption the workers are stopped at once (a pair's files are written all or nothing).
    """
    share = cpus_per_worker or max(1, available_cpus() // workers)
    config = copy.deepcopy(matcher.config)
    if config.slime.workers is None:
        config.slime.workers = share
    scheduler = PairScheduler([job_images(jobs[index]) for index in todo])
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
                    record = pair_record(jobs[todo[position]], "failed", error="the worker process died (exit "
                                         f"code {process.exitcode}; out of memory?)")
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
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle: it stops the workers
    set_threads(threads)
    worker = PairWorker(Matcher(config, feature_cache_mb=feature_cache_mb), out, plot)
    while (job := pipe.recv()) is not None:
        record = worker.match(job)
        pipe.send((record, worker.held()))
