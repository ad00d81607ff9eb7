"""A command's result files in a folder, replaced all at once: the new files are written to a hidden staging
folder inside it and take the place of the earlier run's files only when all are written. The command names
the files it owns (glob patterns); files it does not own are never touched."""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

STAGING_PREFIX = ".staging-"


@contextmanager
def replacing_owned_files(out: str | os.PathLike, owned: Sequence[str], last: str | None = None) -> Iterator[Path]:
    """Stage a run's files, then make them the only owned files of ``out``.

    Write the new files under the yielded folder, at their paths relative to ``out``. When the block ends
    without an error, every file of ``out`` that matches a pattern of ``owned`` and was not written again is
    removed (with the sub-folders that this empties), and the new files are moved in, ``last`` at the end. An
    error or an interruption inside the block leaves ``out`` as it was; a Ctrl-C during the moves (in the main
    thread) is held back until they are done. ``last`` (e.g. ``summary.json``) is removed first and moved in
    last, so a folder holding it holds one complete result.

    Args:
        out: the result folder (created when missing).
        owned: glob patterns, relative to ``out``, of every file name the command writes there.
        last: the owned file that marks a complete result, if any.

    Raises:
        ValueError: a staged file matches no pattern of ``owned`` (a programming error; nothing is moved).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=out, prefix=STAGING_PREFIX))
    try:
        yield staging
        new = sorted((p.relative_to(staging) for p in staging.rglob("*") if not p.is_dir()),
                     key=lambda rel: (rel.as_posix() == last, rel.as_posix()))
        strays = [rel.as_posix() for rel in new if not _owned(rel, owned)]
        if strays:
            raise ValueError(f"staged files not among the owned patterns {list(owned)}: {strays}")
        with _interrupt_deferred():
            _commit(out, staging, new, owned, last)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def remove_owned_files(out: str | os.PathLike, owned: Sequence[str], last: str | None = None) -> None:
    """Remove the owned files of an existing folder ``out`` (``last`` first), leaving every other file."""
    if Path(out).is_dir():
        with replacing_owned_files(out, owned, last):
            pass


def _owned(rel: Path, owned: Sequence[str]) -> bool:
    """Whether the relative path ``rel`` matches a pattern of ``owned`` as a whole (not only its last parts)."""
    return any(len(rel.parts) == len(Path(pattern).parts) and rel.match(pattern) for pattern in owned)


@contextmanager
def _interrupt_deferred() -> Iterator[None]:
    """Within the block, SIGINT (Ctrl-C) is recorded and acted on only when the block ends (in the main thread,
    the only one that receives Python's signal handlers; elsewhere the block runs as it is)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught and callable(previous):
        previous(signal.SIGINT, None)
    elif caught and previous == signal.SIG_DFL:
        raise KeyboardInterrupt


def _commit(out: Path, staging: Path, new: list[Path], owned: Sequence[str], last: str | None) -> None:
    if last is not None:
        (out / last).unlink(missing_ok=True)
    fresh = {rel.as_posix() for rel in new}
    emptied = set()
    for pattern in owned:
        for old in out.glob(pattern):
            rel = old.relative_to(out)
            if rel.parts[0].startswith(STAGING_PREFIX) or rel.as_posix() in fresh or old.is_dir():
                continue
            old.unlink()
            emptied.update(p for p in old.parents if p != out and out in p.parents)
    for rel in new:
        target = out / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging / rel, target)
    for folder in sorted(emptied, key=lambda p: len(p.parts), reverse=True):
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
