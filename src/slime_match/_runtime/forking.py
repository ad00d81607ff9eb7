"""``fork_map``: a map over forked worker processes, for Slime's parallel steps.

The steps (block crops, fixed-orientation descriptors, block and tile pairs, RANSAC batches) read the caller's
memory: images, features, networks. Forked children inherit it without pickling. A fork costs the parent time
in proportion to its page tables (6-10 ms on the 2-core CPU machine; 25 ms in a process holding a CUDA context
on an H100 machine, where one call of Slime forked 62 times), so ``fork_map``:

- computes in the caller too: ``workers`` processes take ``workers - 1`` forks;
- forks the children as a binomial tree (every process forks further children right after its own start):
  the forks run in ceil(log2(workers)) rounds of concurrent forks instead of one after another;
- lets a background thread wait for the children's exits;
- hands out the calls one at a time from a counter in shared memory (the processes stay busy until the
  last call), and each child sends all its results once, when no call is left, pickled by value through
  its own pipe.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from multiprocessing.connection import Connection
from typing import Any

import torch

from . import progress


@contextmanager
def torch_threads(count: int) -> Iterator[None]:
    """Run a block with ``count`` intra-op torch threads (restored afterwards).

    Slime's block-pair and tile loops are thousands of tiny tensor ops: with several threads each op pays a
    thread hand-off that costs far more than the op (measured: Blob matching of 450 x 450 descriptors
    9 ms with 1 thread, 140 ms with 2 on a loaded 2-core machine).
    """
    previous = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


class RemoteTraceback(Exception):
    """The traceback of an exception raised in a forked worker (the ``__cause__`` of the re-raised one)."""


class WorkerDied(RuntimeError):
    """A forked worker ended without sending its results (killed, for example by the out-of-memory killer)."""


def fork_map(fn: Callable[[int], Any], count: int, workers: int) -> list:
    """``[fn(0), ..., fn(count - 1)]``, computed by this process and ``workers - 1`` forked children.

    Each process runs single-threaded torch and takes the next call as soon as it is free. An exception
    raised by ``fn`` in a child is raised here again (its remote traceback as the cause).
    """
    size = min(workers, count)
    bar = progress.bar(count)
    if size <= 1 or "fork" not in multiprocessing.get_all_start_methods():
        results = []
        try:
            with torch_threads(1):  # as every process below: the same float rounding for any number of workers
                for k in range(count):
                    results.append(fn(k))
                    if bar is not None:
                        bar.update(1)
        finally:
            if bar is not None:
                bar.close()
        return results
    context = multiprocessing.get_context("fork")
    taken = context.Value("l", 0)  # calls handed out so far, in memory shared by the forks

    def run() -> list[tuple[int, Any]]:
        done = []
        while True:
            with taken.get_lock():
                k = taken.value
                taken.value += 1
            if k >= count:
                return done
            done.append((k, fn(k)))

    def stop() -> None:
        with taken.get_lock():
            taken.value = count

    pipes = [context.Pipe(duplex=False) for _ in range(size - 1)]  # rank r >= 1 writes to pipes[r - 1]
    watcher = None
    children: list[int] = []
    try:
        _fork_subtree(0, size, pipes, run, stop, children)
        for _, writer in pipes:
            writer.close()
        watcher = _watch(bar, taken, count)  # started after the forks: the children never hold its thread
        with torch_threads(1):
            parts = run()
        for reader, _ in pipes:
            parts += _received(reader)
    finally:
        stop()
        if watcher is not None:
            watcher()
        for reader, writer in pipes:
            reader.close()
            writer.close()
        _reap_later(children)
    return [result for _, result in sorted(parts, key=lambda done: done[0])]


def _watch(bar: Any, taken: Any, count: int) -> Callable[[], None] | None:
    """Move ``bar`` (None: no bar) with the calls handed out to the processes (``taken``), five times a second,
    in a thread of this process; returns the function that stops the thread and closes the bar."""
    if bar is None:
        return None
    done = threading.Event()

    def follow() -> None:
        while not done.wait(0.2):
            bar.update(max(min(taken.value, count) - bar.n, 0))

    thread = threading.Thread(target=follow, name="slime-progress", daemon=True)
    thread.start()

    def finish() -> None:
        done.set()
        thread.join()
        bar.update(count - bar.n)
        bar.close()

    return finish


def _reap_later(pids: list[int]) -> None:
    """Reap the children in a background thread. A child's exit unmaps its copy of the caller's address space
    (about 12 ms each on the 2-core CPU machine), which the caller need not wait for."""
    def reap() -> None:
        for pid in pids:
            try:
                os.waitpid(pid, 0)
            except ChildProcessError:  # reaped elsewhere (a waitpid(-1) of the application's own)
                pass

    if pids:
        threading.Thread(target=reap, name="slime-fork-reaper", daemon=True).start()


def _tree_children(rank: int, size: int) -> list[int]:
    """The ranks that ``rank`` forks in a binomial tree of ``size`` processes rooted at 0: rank + 2^k for every
    2^k > rank (rank 0 forks 1, 2, 4, 8...; rank 1 forks 3, 5, 9...; rank 2 forks 6, 10...)."""
    step = 1
    while step <= rank:
        step *= 2
    out = []
    while rank + step < size:
        out.append(rank + step)
        step *= 2
    return out


def _subtree(rank: int, size: int) -> set[int]:
    """``rank`` and every rank forked below it."""
    out = {rank}
    for child in _tree_children(rank, size):
        out |= _subtree(child, size)
    return out


def _fork_subtree(rank: int, size: int, pipes: list[tuple[Connection, Connection]], run: Callable[[], list],
                  stop: Callable[[], None], pids: list[int]) -> None:
    """Fork the children of ``rank`` (each runs ``_worker`` and never returns here), adding their pids to
    ``pids`` as they start."""
    for child in _tree_children(rank, size):
        pid = os.fork()
        if pid == 0:
            _worker(child, size, pipes, run, stop)
        pids.append(pid)


def _worker(rank: int, size: int, pipes: list[tuple[Connection, Connection]], run: Callable[[], list],
            stop: Callable[[], None]) -> None:
    """A forked child: fork its subtree, run calls, send their results, reap its children, exit."""
    pids: list[int] = []
    code = 1
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the caller's to handle
        mine = _subtree(rank, size)
        for r, (reader, writer) in enumerate(pipes, 1):
            reader.close()
            if r not in mine:
                writer.close()
        _fork_subtree(rank, size, pipes, run, stop, pids)
        for r in mine - {rank}:
            pipes[r - 1][1].close()
        torch.set_num_threads(1)
        try:
            message = ("done", run())
        except BaseException as error:  # noqa: BLE001 (sent to the caller, which raises it)
            stop()
            message = ("error", error, traceback.format_exc())
        pipes[rank - 1][1].send_bytes(_pickled(message))
        code = 0
    finally:
        try:
            for pid in pids:
                os.waitpid(pid, 0)
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


def _pickled(message: tuple) -> bytes:
    """A worker's message by value; results or an exception that cannot be pickled become an error message."""
    try:
        return pickle.dumps(message, pickle.HIGHEST_PROTOCOL)
    except Exception as error:  # noqa: BLE001 (pickling fails with any type)
        return pickle.dumps(("error", RuntimeError(f"a forked worker's message could not be pickled: {error!r}"),
                             traceback.format_exc()), pickle.HIGHEST_PROTOCOL)


def _received(reader: Connection) -> list[tuple[int, Any]]:
    """One child's results; its exception raised here, or WorkerDied if it sent nothing."""
    try:
        message = pickle.loads(reader.recv_bytes())
    except EOFError:
        raise WorkerDied("a forked Slime worker ended without its results (killed, for example out of "
                         "memory?)") from None
    if message[0] == "error":
        _, error, remote = message
        raise error from RemoteTraceback(remote)
    return message[1]


__all__ = ["RemoteTraceback", "WorkerDied", "fork_map", "torch_threads"]
