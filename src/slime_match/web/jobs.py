"""Matches of ``slime web`` run in a worker process, one at a time, with their progress stage by stage.

The server process never matches: a long match would hold its threads and a crash (out of memory, a killed
worker) would take the server with it. One worker process, started on the first job and kept for the next
ones (models stay loaded while the configuration stays the same), takes the jobs in order; it reports each
Slime stage as it starts and ends, and writes the pair's files (``matches.npz``, ``summary.json`` and, when
asked, ``stages.npz``) into the job's folder. A worker that dies fails its job and a new one takes the next.
"""

from __future__ import annotations

import itertools
import json
import logging
import multiprocessing
import os
import queue
import shutil
import signal
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

logger = logging.getLogger("slime_match")

KEPT_JOBS = 50  # finished jobs whose files are kept; older ones are deleted


@dataclass
class Job:
    """One match: what it matches, its state and the stages it went through.

    Attributes:
        id: the job's name in the API.
        images: the two images as the client named them (``{"root": ..., "path": ...}``).
        preset: the preset (or method) name.
        folder: where the worker writes the pair's files.
        status: "queued", "running", "done", "failed" or "cancelled".
        stages: ``{"name", "seconds"}`` in the order they started; seconds is None while a stage runs.
        notices: the warnings the worker logged while it ran (numba compiling on first use, weights passed
            over...).
    """

    id: str
    images: list[dict[str, Any]]
    preset: str
    folder: Path
    status: str = "queued"
    stages: list[dict[str, Any]] = field(default_factory=list)
    notices: list[str] = field(default_factory=list)
    error: str | None = None
    counts: dict[str, Any] = field(default_factory=dict)
    created: float = field(default_factory=time.time)
    started: float | None = None
    finished: float | None = None
    number: int = 0

    def end(self, status: str, error: str) -> None:
        """End the job unfinished: ``status`` "failed" or "cancelled", ``error`` says why."""
        self.status, self.finished, self.error = status, time.time(), error

    def state(self) -> dict[str, Any]:
        """The job as the API reports it."""
        now = time.time()
        elapsed = None if self.started is None else round((self.finished or now) - self.started, 2)
        return {"id": self.id, "status": self.status, "images": self.images, "preset": self.preset,
                "stages": self.stages, "notices": self.notices, "error": self.error, "counts": self.counts,
                "elapsed": elapsed, "number": self.number, "created": self.created,
                "has_stages": (self.folder / "stages.npz").is_file() if self.status == "done" else False}


class JobRunner:
    """Runs match jobs in one worker process (spawned, so that the server's threads are not forked)."""

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.jobs: dict[str, Job] = {}
        self._lock = threading.Lock()
        self._context = multiprocessing.get_context("spawn")
        self._process = None
        self._tasks = None
        self._events = None
        self._current: str | None = None
        self._pending: list[tuple[str, dict, str, str]] = []
        self._numbers = itertools.count(1)
        self._by_key: dict[str, str] = {}  # a client's request key -> its job
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="slime-web-jobs", daemon=True)
        self._thread.start()

    # -- the API's side

    def submit(self, config: dict[str, Any], path0: Path, path1: Path, images: list[dict[str, Any]],
               preset: str, key: str | None = None) -> Job:
        """Queue a match of ``path0`` and ``path1`` with ``config`` (``MatchConfig.to_dict()``); a request
        ``key`` seen before gives that request's job again (one job per click, however often it is sent)."""
        with self._lock:
            if key is not None and self._by_key.get(key) in self.jobs:
                return self.jobs[self._by_key[key]]
            job_id = uuid.uuid4().hex[:12]
            job = Job(job_id, images, preset, self.folder / job_id, number=next(self._numbers))
            if key is not None:
                self._by_key[key] = job_id
            self.jobs[job_id] = job
            self._pending.append((job_id, config, str(path0), str(path1)))
            self._forget_old()
            self._dispatch()
        return job

    def get(self, job_id: str) -> Job | None:
        with self._lock:
            return self.jobs.get(job_id)

    def listed(self) -> list[Job]:
        """The jobs kept, the newest first."""
        with self._lock:
            return sorted(self.jobs.values(), key=lambda job: -job.number)

    def cancel(self, job_id: str) -> Job | None:
        """Stop a queued or running job (a running one stops its worker; the next job starts a new one)."""
        with self._lock:
            job = self.jobs.get(job_id)
            if job is None or job.status not in ("queued", "running"):
                return job
            if job.status == "queued":
                self._pending = [task for task in self._pending if task[0] != job_id]
            else:
                self._kill_worker()
                self._current = None
            job.end("cancelled", "cancelled by the user")
            self._dispatch()
            return job

    def close(self) -> None:
        """Stop the worker and the watcher; delete every job's files."""
        self._stop.set()
        with self._lock:
            self._kill_worker()
        self._thread.join(timeout=5)
        shutil.rmtree(self.folder, ignore_errors=True)

    # -- inside, with the lock held

    def _forget_old(self) -> None:
        finished = sorted((j for j in self.jobs.values() if j.status not in ("queued", "running")),
                          key=lambda j: j.number)
        for job in finished[:max(0, len(finished) - KEPT_JOBS)]:
            shutil.rmtree(job.folder, ignore_errors=True)
            del self.jobs[job.id]
        self._by_key = {key: job_id for key, job_id in self._by_key.items() if job_id in self.jobs}

    def _start_worker(self) -> None:
        """Start a worker; raises OSError when the system cannot start a process (nothing is kept then)."""
        tasks, events = self._context.Queue(), self._context.Queue()
        process = self._context.Process(target=_worker_main, args=(tasks, events), name="slime-web-worker",
                                        daemon=True)
        process.start()
        self._process, self._tasks, self._events = process, tasks, events

    def _kill_worker(self) -> None:
        """Stop the worker and the processes it forked (Slime's parallel steps): they share its process group."""
        if self._process is not None:
            if self._process.pid is not None and hasattr(os, "killpg"):
                try:
                    os.killpg(self._process.pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass  # it ended already, or never became a group leader
            self._process.kill()
            self._process.join(timeout=5)
        for channel in (self._tasks, self._events):
            if channel is not None:
                channel.cancel_join_thread()  # nobody reads them any more: never wait on them at exit
        self._process = self._tasks = self._events = None

    def _dispatch(self) -> None:
        if self._current is not None or not self._pending:
            return
        if self._process is None or not self._process.is_alive():
            self._kill_worker()
            try:
                self._start_worker()
            except OSError as error:  # out of processes or memory: no worker runs the queued jobs
                reason = error.strerror or type(error).__name__
                for job_id, *_ in self._pending:
                    self.jobs[job_id].end("failed", f"the matching worker could not start ({reason}); the next "
                                                    "match tries again")
                self._pending = []
                return
        job_id, config, path0, path1 = self._pending.pop(0)
        job = self.jobs[job_id]
        job.status, job.started = "running", time.time()
        self._current = job_id
        self._tasks.put((job_id, config, path0, path1, str(job.folder)))

    # -- the watcher thread

    def _watch(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                events, process = self._events, self._process
            if events is None:
                time.sleep(0.05)
                continue
            try:
                event = events.get(timeout=0.2)
            except (queue.Empty, OSError, ValueError, EOFError):
                with self._lock:
                    if self._process is process and process is not None and not process.is_alive():
                        self._worker_died(process.exitcode)
                continue
            with self._lock:
                if self._events is events:  # not from a worker killed meanwhile
                    self._handle(event)

    def _worker_died(self, code: int | None) -> None:
        job = self.jobs.get(self._current) if self._current else None
        if job is not None and job.status == "running":
            job.end("failed", f"the matching worker stopped (exit code {code}: killed, or out of memory); "
                              "the next match starts a new one")
        self._current = None
        self._kill_worker()
        self._dispatch()

    def _handle(self, event: tuple) -> None:
        kind, job_id = event[0], event[1]
        job = self.jobs.get(job_id)
        if job is None or job.status != "running":
            return
        if kind == "notice":
            job.notices.append(event[2])
            return
        if kind == "stage":
            _, _, stage, seconds = event
            if seconds is None:
                job.stages.append({"name": stage, "seconds": None})
            else:
                running = [s for s in job.stages if s["name"] == stage and s["seconds"] is None]
                if running:
                    running[-1]["seconds"] = round(seconds, 3)
                else:
                    job.stages.append({"name": stage, "seconds": round(seconds, 3)})
            return
        job.finished = time.time()
        if kind == "done":
            job.status, job.counts = "done", event[2]
        else:
            job.status, job.error = "failed", event[2]
        self._current = None
        self._dispatch()


def _worker_main(tasks, events) -> None:
    """The worker process: match each task and report its stages, then its end."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C stops the server, which stops the worker
    if hasattr(os, "setpgid"):
        os.setpgid(0, 0)  # a group of its own, with the processes it forks: a cancel stops them all
    from .._runtime.timing import stage_listener
    from ..config import MatchConfig
    from ..errors import SlimeMatchError
    from ..io import load_image
    from ..matcher import Matcher
    from ..runs.outputs import write_pair_outputs

    current = {"job": None}
    logging.getLogger("slime_match").addHandler(NoticeHandler(events, current))
    matcher, matcher_key = None, None
    while True:
        task = tasks.get()
        if task is None:
            return
        job_id, config_dict, path0, path1, out = task
        current["job"] = job_id

        def tell(stage: str, seconds: float | None, job_id=job_id) -> None:
            events.put(("stage", job_id, stage, seconds))

        try:
            key = json.dumps(config_dict, sort_keys=True, default=str)
            if key != matcher_key:
                tell("setup", None)
                start = time.perf_counter()
                matcher, matcher_key = None, None  # the old models go before the new ones load
                matcher = Matcher(MatchConfig.from_dict(config_dict))
                matcher_key = key
                tell("setup", time.perf_counter() - start)
            with stage_listener(tell):
                image0, image1 = load_image(path0), load_image(path1)
                result = matcher(image0, image1)
                write_pair_outputs(result, image0, image1, Path(out), plot=False)
            counts = dict(result.summary["counts"])
            counts["seconds"] = result.summary["seconds"]["total"]
            counts["warnings"] = list(result.summary.get("warnings", []))
            events.put(("done", job_id, counts))
        except SlimeMatchError as error:
            events.put(("failed", job_id, str(error)))
        except Exception as error:  # one bad job must not end the worker
            logger.exception("match job %s failed", job_id)
            events.put(("failed", job_id, f"{type(error).__name__}: {error}"))


class NoticeHandler(logging.Handler):
    """Sends the worker's warnings to the job that runs (``current["job"]``) as notices."""

    def __init__(self, events, current: dict[str, str | None]) -> None:
        super().__init__(logging.WARNING)
        self.events, self.current = events, current

    def emit(self, record: logging.LogRecord) -> None:
        if self.current["job"] is not None:
            self.events.put(("notice", self.current["job"], record.getMessage()))
