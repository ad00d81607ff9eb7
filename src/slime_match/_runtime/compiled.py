"""The package's compiled loops (numba): the one decorator they share, the warm-ups that load them, and the
notice shown while a first run compiles them.

Every loop is compiled once per machine and cached on disk (``NUMBA_CACHE_DIR`` moves the cache, e.g. to a
folder shared by a cluster's nodes). A process loads a loop on its first call; forked workers inherit the
loops their parent loaded, so the parent warms up the groups its workers will run before it forks
(:func:`warm_up`). A group is a module whose ``warm_up`` runs each of its loops on a tiny input with the
argument types the package passes.

numba announces every compilation as a "numba:compile" event, and loading a loop from its on-disk cache is not
one, so the notice (:func:`install_notice`: the ``slime`` command and every
:class:`~slime_match.matcher.Matcher` install it) appears exactly when compiling happens: once per process, in
the process that installed it (forked workers stay quiet).
"""

from __future__ import annotations

import importlib
import logging
import os
import time

from numba import njit
from numba.core import event

log = logging.getLogger("slime_match")

kernel = njit(cache=True, nogil=True)
"""Decorator of a compiled loop: cached on disk, releasing the GIL (threads run loops side by side)."""

vector_kernel = njit(cache=True, nogil=True, error_model="numpy")
"""``kernel`` without Python's division checks (x / 0 gives inf or nan), so that arithmetic loops vectorise."""

GROUPS = {
    "patches": "slime_match.features.extractor",  # patch sampling, Baumberg moments, orientation, SIFT
    "blob": "slime_match.matching.blob",  # nearest neighbours of Blob matching and FGINN
    "dtm": "slime_match.matching.dtm",  # the Delaunay triangulation matching filter
    "ransac": "slime_match.geometry.ransac_kernels",  # sampling, minimal homographies, inlier counts
}


def warm_up(*groups: str) -> dict[str, float]:
    """Load the compiled loops of ``groups`` (default: all of :data:`GROUPS`) in this process: from the disk
    cache, or compiled on first use (up to a minute on a 2-core CPU). Returns the seconds per group."""
    seconds = {}
    for group in groups or tuple(GROUPS):
        if group not in GROUPS:
            raise ValueError(f"unknown group of compiled loops {group!r}: one of {', '.join(GROUPS)}")
        start = time.perf_counter()
        importlib.import_module(GROUPS[group]).warm_up()
        seconds[group] = time.perf_counter() - start
    return seconds


NOTICE = ("numba is compiling slime-match's loops: first use only, up to a minute on a 2-core CPU; they are "
          "cached on disk for later runs")


class FirstCompileNotice(event.Listener):
    """Logs :data:`NOTICE` (a warning, so that it shows by default) at the first compilation of a loop of this
    package, in the process that created the listener, and adds up the seconds numba spends compiling there
    (:func:`compile_seconds`; a compilation inside another counts once)."""

    def __init__(self) -> None:
        self.pid = os.getpid()
        self.shown = False
        self.depth = 0
        self.started = 0.0
        self.seconds = 0.0

    def on_start(self, e: event.Event) -> None:
        if os.getpid() != self.pid:
            return
        if self.depth == 0:
            self.started = time.perf_counter()
        self.depth += 1
        if self.shown:
            return
        dispatcher = (e.data or {}).get("dispatcher")
        module = getattr(getattr(dispatcher, "py_func", None), "__module__", None) or ""
        if module.startswith("slime_match."):
            self.shown = True
            log.warning(NOTICE)

    def on_end(self, e: event.Event) -> None:
        if os.getpid() != self.pid or self.depth == 0:
            return
        self.depth -= 1
        if self.depth == 0:
            self.seconds += time.perf_counter() - self.started


_installed: list[FirstCompileNotice] = []


def install_notice() -> None:
    """Listen for this package's first compilation in this process (once, however often it is called)."""
    if not _installed:
        _installed.append(FirstCompileNotice())
        event.register("numba:compile", _installed[0])


def compile_seconds() -> float:
    """Seconds numba has spent compiling in this process since :func:`install_notice` (0 before it, and in
    forked workers, whose compilations their own processes pay)."""
    return _installed[0].seconds if _installed and _installed[0].pid == os.getpid() else 0.0
