"""Per-stage wall-clock timing recorded into the output summary."""

from __future__ import annotations

import logging
import time
from collections import defaultdict
from contextlib import contextmanager

import torch

from . import progress

logger = logging.getLogger("slime_match")


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
        start = time.perf_counter()
        try:
            with progress.stage(stage):
                yield
        finally:
            _sync()
            elapsed = time.perf_counter() - start
            self.seconds[stage] += elapsed
            logger.info("%s: %.2f s", stage, elapsed)

    def as_dict(self) -> dict[str, float]:
        return {name: round(value, 4) for name, value in self.seconds.items()}


def _sync() -> None:
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        torch.cuda.synchronize()
