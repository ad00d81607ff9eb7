"""Progress bars over the jobs of Slime's long stages (block pairs, tile pairs), on a terminal only.

Off by default: the ``slime`` command turns them on (``-q`` keeps them off). :class:`~.timing.StageTimer` names
the stage that runs, and :func:`~.forking.fork_map` asks :func:`bar` for a bar over its calls, so the stages
themselves know nothing of it. A bar is drawn only when stderr is a terminal, and removed when its calls end.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

# the stages that get a bar, with the name shown beside it
REPORTED = {"block_pairs": "block pairs", "tile_refinement": "tile pairs"}

_enabled = False
_stage: str | None = None


def enable(on: bool = True) -> None:
    """Turn the bars on (or off) in this process."""
    global _enabled
    _enabled = on


@contextmanager
def stage(name: str) -> Iterator[None]:
    """Name the stage that runs inside the block (nested blocks restore the outer name)."""
    global _stage
    outer, _stage = _stage, name
    try:
        yield
    finally:
        _stage = outer


def bar(count: int) -> Any | None:
    """A tqdm bar over ``count`` calls of the current stage, or None: bars off, a stage without a bar, fewer
    than 2 calls, or stderr not a terminal."""
    if not _enabled or _stage not in REPORTED or count < 2 or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return tqdm(total=count, desc=REPORTED[_stage], unit="job", file=sys.stderr, leave=False, dynamic_ncols=True)
