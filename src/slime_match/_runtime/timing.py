"""Per-stage wall-clock timing recorded into the output summary."""

from __future__ import annotations

import logging
import time
from collections import defaultdict
from collections.abc import Callable
from contextlib import contextmanager

import torch

from . import progress

logger = logging.getLogger("slime_match")

# callbacks told of every stage as it starts, ``(stage, None)``, and ends, ``(stage, seconds)`` (progress)
_listeners: list[Callable[[str, float | None], None]] = []


@contextmanager
def stage_listener(callback: Callable[[str, float | None], None]):
    """Within the block, ``callback(stage, None)`` as each StageTimer stage of this process starts and
    ``callback(stage, seconds)`` as it ends (``slime web`` shows them as progress)."""
    _listeners.append(callback)
    try:
        yield
    finally:
        _listeners.remove(callback)


def _tell(stage: str, seconds: float | None) -> None:
    for callback in _listeners:
        callback(stage, seconds)


class StageTimer:
    """Accumulates seconds per named stage; ``with timer("dtm"): ...``.

    CUDA work is synchronised at stage boundaries so that the seconds are not attributed to a later stage.
    Each finished stage is logged at INFO level (``slime match -v`` shows them as progress).
    """

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)

    @contextmanager
    def __call__(self, stage: str):
        _sync()
        _tell(stage, None)
        start = time.perf_counter()
        try:
            with progress.stage(stage):
                yield
        finally:
            _sync()
            elapsed = time.perf_counter() - start
            self.seconds[stage] += elapsed
            logger.info("%s: %.2f s", stage, elapsed)
            _tell(stage, elapsed)

    def as_dict(self) -> dict[str, float]:
        return {name: round(value, 4) for name, value in self.seconds.items()}


def _sync() -> None:
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        torch.cuda.synchronize()
