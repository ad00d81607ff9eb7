"""A notice when numba compiles the package's loops: on a first run (or with an unwritable cache) the first call
would otherwise sit silent for up to a minute before its results.

numba announces every compilation as a "numba:compile" event, and loading a loop from its on-disk cache is not
one, so the notice appears exactly when compiling happens: once per process, in the process that installed the
listener (``install``: the ``slime`` command and every :class:`~slime_match.matcher.Matcher`; forked workers
stay quiet).
"""

from __future__ import annotations

import logging
import os

from numba.core import event

log = logging.getLogger("slime_match")

NOTICE = ("numba is compiling slime-match's loops: first use only, up to a minute on a 2-core CPU; they are "
          "cached on disk for later runs")


class FirstCompileNotice(event.Listener):
    """Logs :data:`NOTICE` (a warning, so that it shows by default) at the first compilation of a loop of this
    package, in the process that created the listener."""

    def __init__(self) -> None:
        self.pid = os.getpid()
        self.shown = False

    def on_start(self, e: event.Event) -> None:
        if self.shown or os.getpid() != self.pid:
            return
        dispatcher = (e.data or {}).get("dispatcher")
        module = getattr(getattr(dispatcher, "py_func", None), "__module__", None) or ""
        if module.startswith("slime_match."):
            self.shown = True
            log.warning(NOTICE)

    def on_end(self, e: event.Event) -> None:
        pass


_installed: list[FirstCompileNotice] = []


def install() -> None:
    """Listen for this package's first compilation in this process (once, however often it is called)."""
    if not _installed:
        _installed.append(FirstCompileNotice())
        event.register("numba:compile", _installed[0])
