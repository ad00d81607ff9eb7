"""The pairs of a batch on a Ray cluster: Ray actors, each holding one Matcher (its models loaded once, its
feature cache), match the pairs that this process hands out one at a time.

Ray is an optional dependency (the ``ray`` extra), imported only here and only when asked for. The actors read
the images and write the pair folders themselves: the image folder and the run folder must have the same path
on every node (a shared file system). This process writes the records and the index, as for a local run.
"""

from __future__ import annotations

import copy
import logging
import socket
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import Any

from ..config import MatchConfig
from ..errors import ConfigError, SlimeMatchError
from ..matcher import Matcher
from .pair_tasks import PairJob, PairWorker, job_images, pair_record, set_threads
from .schedule import PairScheduler

logger = logging.getLogger("slime_match")


def import_ray() -> ModuleType:
    """The ``ray`` module.

    Raises:
        ConfigError: Ray is not installed.
    """
    try:
        import ray
    except ImportError:
        raise ConfigError("running pairs on Ray needs Ray, an optional dependency: "
                          "pip install 'slime-match[ray]'") from None
    return ray


@contextmanager
def connected(address: str) -> Iterator[ModuleType]:
    """Within the block, this process is connected to the Ray cluster at ``address`` ("auto": the cluster
    started on this machine by ``ray start``, or named by ``RAY_ADDRESS``; else ``host:port`` of its head). A
    process already connected (``ray.init``) keeps its connection, and ``address`` is not used.

    Raises:
        ConfigError: Ray is not installed, or no cluster answers at ``address``.
    """
    ray = import_ray()
    if ray.is_initialized():
        yield ray
        return
    _check_answers(address)
    try:
        ray.init(address=address, logging_level=logging.WARNING)
    except (ConnectionError, ValueError, RuntimeError) as error:
        raise ConfigError(f"cannot connect to a Ray cluster at {address!r}: {error} (start one with "
                          "`ray start --head`, or give the address of its head)") from None
    try:
        yield ray
    finally:
        ray.shutdown()


def _check_answers(address: str, timeout: float = 10.0) -> None:
    """Raise ConfigError when nothing accepts a connection at the ``host:port`` of ``address`` within
    ``timeout`` seconds (Ray itself would retry for minutes); "auto" and other forms are left to Ray."""
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as error:
        raise ConfigError(f"no Ray cluster answers at {address} ({error}): check the address of its head "
                          "(`ray status` on the head shows it)") from None


class PairActor:
    """A Ray actor that matches pairs: one Matcher (models loaded once) and its feature cache.

    Args:
        config: the matcher configuration, its Slime worker count resolved.
        threads: torch and numba threads (the actor's CPUs).
        feature_cache_mb: the Matcher's feature cache (MiB).
        out: the run folder (the same path on every node).
        plot: also draw each pair's matches.png.
    """

    def __init__(self, config: MatchConfig, threads: int, feature_cache_mb: float, out: Path, plot: bool) -> None:
        set_threads(threads)
        self._worker = PairWorker(Matcher(config, feature_cache_mb=feature_cache_mb), out, plot)

    def ready(self) -> bool:
        """True once the actor is built (its answer tells the driver that the actor may take pairs)."""
        return True

    def match(self, job: PairJob) -> tuple[dict[str, Any], list[str]]:
        """Match a pair into its folder: its record, and the images the feature cache holds (most recent
        first)."""
        return self._worker.match(job), self._worker.held()


def check_node_cpus(ray: ModuleType, threads: int) -> None:
    """Raise ConfigError unless a node of the connected cluster has ``threads`` CPUs (an actor's)."""
    largest = max((node["Resources"].get("CPU", 0) for node in ray.nodes() if node["Alive"]), default=0)
    if threads > largest:
        raise ConfigError(f"each Ray actor asks for {threads} CPUs (--cpus-per-worker), more than any node of "
                          f"the cluster has (at most {largest:g})")


def match_on_ray(ray: ModuleType, config: MatchConfig, jobs: list[PairJob], todo: list[int], out: Path,
                 plot: bool, actors: int | None, threads: int, feature_cache_mb: float
                 ) -> Iterator[tuple[int, dict[str, Any]]]:
    """(index, record) of the ``todo`` pairs as Ray actors finish them.

    Each actor asks for ``threads`` CPUs of the cluster, and its Slime workers are as many (unless the
    configuration sets them). An actor that finishes a pair is given the pair that best reuses the images its
    cache holds (:class:`PairScheduler`). The pair of an actor that dies (killed, out of memory, its node
    lost) goes to the next actor that asks for one, and a new actor replaces the dead one; a pair whose
    actor dies twice is recorded as failed. Closing the iterator kills the actors.

    Args:
        ray: the ``ray`` module, connected (:func:`connected`).
        config: the matcher configuration.
        jobs, todo: the pairs, and the positions in ``jobs`` of those to match.
        out: the run folder.
        plot: also draw each pair's matches.png.
        actors: how many actors; None: as many as the cluster's CPUs hold.
        threads: CPUs per actor.
        feature_cache_mb: each actor's feature cache (MiB).

    Raises:
        SlimeMatchError: no actor could start (their error named).
    """
    config = copy.deepcopy(config)
    if config.slime.workers is None:
        config.slime.workers = threads
    if actors is None:
        actors = max(1, int(ray.cluster_resources().get("CPU", 0) // threads))
    remote = ray.remote(PairActor).options(num_cpus=threads, max_restarts=0)
    scheduler = PairScheduler([job_images(jobs[index]) for index in todo])
    retry: list[int] = []  # todo positions whose actor died once
    died: set[int] = set()
    starting: dict[Any, Any] = {}  # ready() reference -> actor
    busy: dict[Any, tuple[Any, int]] = {}  # match() reference -> actor, todo position

    def start() -> None:
        actor = remote.remote(config, threads, feature_cache_mb, out, plot)
        starting[actor.ready.remote()] = actor

    def give(actor: Any, cached: list[str]) -> None:
        position = retry.pop(0) if retry else scheduler.next(cached)
        if position is None:
            ray.kill(actor)
        else:
            busy[actor.match.remote(jobs[todo[position]])] = (actor, position)

    try:
        for _ in range(min(actors, len(todo))):
            start()
        while busy or (starting and (retry or len(scheduler))):
            (reference,), _ = ray.wait([*busy, *starting], num_returns=1)
            if reference in starting:
                actor = starting.pop(reference)
                try:
                    ray.get(reference)
                except ray.exceptions.RayError as error:
                    logger.warning("a Ray actor could not start: %s", _first_line(error))
                    if not busy and not starting:
                        raise SlimeMatchError(f"no Ray actor could start: {_first_line(error)}") from None
                else:
                    give(actor, [])
                continue
            actor, position = busy.pop(reference)
            try:
                record, cached = ray.get(reference)
            except ray.exceptions.RayError as error:  # the actor died in this pair
                ray.kill(actor)
                job = jobs[todo[position]]
                if position in died:
                    yield todo[position], pair_record(job, "failed", error="its Ray actor died twice "
                                                      f"(out of memory?): {_first_line(error)}")
                else:
                    died.add(position)
                    retry.append(position)
                    logger.warning("%s %s: its Ray actor died (%s); the pair goes to another actor",
                                   job.name0, job.name1, _first_line(error))
                if retry or len(scheduler):
                    start()
                continue
            give(actor, cached)
            yield todo[position], record
    finally:
        for actor in [*starting.values(), *(actor for actor, _ in busy.values())]:
            ray.kill(actor)


def _first_line(error: BaseException) -> str:
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__
