"""Progress bars over the jobs of Slime's long stages: drawn on a terminal when turned on, never otherwise."""

import io
import sys

import pytest

from slime_match._runtime import progress
from slime_match._runtime.forking import fork_map
from slime_match._runtime.timing import StageTimer


class Terminal(io.StringIO):
    """A stderr that says it is a terminal."""

    def isatty(self) -> bool:
        return True


@pytest.fixture
def terminal(monkeypatch):
    """Makes stderr a terminal when called (in the test itself: pytest sets its own stderr between phases)."""
    stream = Terminal()

    def attach() -> Terminal:
        monkeypatch.setattr(sys, "stderr", stream)
        return stream

    yield attach
    progress.enable(False)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_reported_stage_draws_a_bar_over_its_jobs_on_a_terminal(terminal, workers):
    terminal = terminal()
    progress.enable()
    timer = StageTimer()
    with timer("block_pairs"):
        assert fork_map(lambda k: k * k, 6, workers) == [0, 1, 4, 9, 16, 25]
    assert "block pairs:" in terminal.getvalue() and "/6 [" in terminal.getvalue()  # drawn, then cleared


def test_no_bar_when_off_outside_a_reported_stage_or_off_a_terminal(terminal, monkeypatch):
    terminal = terminal()
    timer = StageTimer()
    with timer("block_pairs"):
        assert progress.bar(6) is None  # off by default
    progress.enable()
    with timer("expansion"):
        assert progress.bar(6) is None  # not a reported stage
    with timer("tile_refinement"):
        assert progress.bar(1) is None  # a single job
        monkeypatch.setattr(sys, "stderr", io.StringIO())
        assert progress.bar(6) is None  # not a terminal
    assert terminal.getvalue() == ""


def test_the_stage_name_is_restored_after_a_nested_stage():
    timer = StageTimer()
    with timer("block_pairs"):
        with timer("ransac"):
            assert progress._stage == "ransac"
        assert progress._stage == "block_pairs"
    assert progress._stage is None
