"""Which code produced a cached prediction: the package version plus, in a git checkout, the last commit
that changed the package's own files.

A benchmark cache outlives the code that filled it; recording the code version with every prediction lets
the report say which predictions are stale (``slime bench`` warns about them, the time table lists them).
Commits that touch only docs, tests or scripts leave the version, and so the cached predictions, current.
"""

from __future__ import annotations

import subprocess
from functools import lru_cache
from pathlib import Path

import slime_match

UNKNOWN = "unknown"  # predictions written before the version was recorded


def _git(*args: str) -> str | None:
    """Output of a git command run in the package folder; None outside a checkout or without git."""
    try:
        done = subprocess.run(
            ["git", *args],
            cwd=Path(slime_match.__file__).parent,
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


@lru_cache(maxsize=1)
def code_version() -> str:
    """``"<version>"``, or ``"<version>+g<commit>"`` in a git checkout, where ``<commit>`` is the last commit
    that changed the package's files, with ``".dirty"`` appended when those files differ from the checked-out
    commit (e.g. ``"0.1.0+g2185a31.dirty"``)."""
    commit = _git("log", "-1", "--format=%h", "--", ".")
    if not commit or not _git("ls-files", "__init__.py"):  # not a checkout, or one that does not track us
        return slime_match.__version__
    dirty = _git("status", "--porcelain", "--untracked-files=no", "--", ".")
    return f"{slime_match.__version__}+g{commit}{'.dirty' if dirty else ''}"
