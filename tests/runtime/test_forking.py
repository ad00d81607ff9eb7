"""fork_map: results in order for any split, the binomial fork tree, errors and dead workers raised, no
children left behind; torch_threads restores the caller's setting."""

import math
import os
import signal
import time

import pytest
import torch

from slime_match._runtime.forking import (
    RemoteTraceback,
    WorkerDied,
    _subtree,
    _tree_children,
    fork_map,
    torch_threads,
)

CALLER = os.getpid()


def _gone(pids, seconds: float = 10.0) -> bool:
    """Whether none of the processes pids is left, not even as a zombie, within ``seconds`` (they are reaped
    in the background)."""
    deadline = time.monotonic() + seconds
    for pid in pids:
        while True:
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                break
            if time.monotonic() > deadline:
                return False
            time.sleep(0.01)
    return True


@pytest.mark.parametrize(("count", "workers"), [(0, 4), (1, 4), (11, 2), (50, 5), (64, 8), (7, 16)])
def test_fork_map_equals_the_serial_map(count, workers):
    out = fork_map(lambda k: (k * k, os.getpid()), count, workers)
    assert [square for square, _ in out] == [k * k for k in range(count)]
    assert _gone({pid for _, pid in out} - {CALLER})


@pytest.mark.parametrize("workers", [1, 3])
def test_every_call_runs_with_one_torch_thread_and_the_caller_gets_its_own_back(workers):
    """Single-threaded torch in every process, with or without forks (the same float rounding for any number
    of workers: convolutions differ in the last bits between thread counts on some CPUs)."""
    before = torch.get_num_threads()
    assert fork_map(lambda k: torch.get_num_threads(), 6, workers) == [1] * 6
    assert torch.get_num_threads() == before


def test_the_caller_and_its_children_all_compute_and_get_tensors_back():
    threads = torch.get_num_threads()

    def fn(k):
        time.sleep(0.02)
        return os.getpid(), torch.full((3,), float(k)), torch.get_num_threads()

    out = fork_map(fn, 40, 4)
    pids = {pid for pid, _, _ in out}
    assert CALLER in pids and len(pids) >= 3
    assert all(torch.equal(t, torch.full((3,), float(k))) for k, (_, t, _) in enumerate(out))
    assert {n for _, _, n in out} == {1}  # single-threaded torch in every process
    assert torch.get_num_threads() == threads
    assert _gone(pids - {CALLER})


@pytest.mark.parametrize("size", [2, 3, 5, 8, 13, 16, 17])
def test_binomial_tree_forks_every_rank_once_in_log_rounds(size):
    forked = [child for rank in range(size) for child in _tree_children(rank, size)]
    assert sorted(forked) == list(range(1, size))
    assert _subtree(0, size) == set(range(size))
    # rank r is forked in round floor(log2(r)) by a rank that exists by then: rounds = ceil(log2(size))
    for rank in range(size):
        for round_, child in enumerate(_tree_children(rank, size), start=(rank.bit_length())):
            assert child.bit_length() - 1 == round_
    assert max(r.bit_length() for r in range(size)) == math.ceil(math.log2(size))


def _children_seen(folder) -> set[int]:
    return {int(path.name) for path in folder.iterdir()} - {CALLER}


def test_an_error_in_a_child_is_raised_in_the_caller_with_its_traceback(tmp_path):
    def fn(k):
        (tmp_path / str(os.getpid())).touch()
        if os.getpid() == CALLER:
            time.sleep(0.2)  # leave the other chunks to the children
            return k
        raise ValueError(f"bad item {k}")

    with pytest.raises(ValueError, match="bad item") as info:
        fork_map(fn, 8, 2)
    assert isinstance(info.value.__cause__, RemoteTraceback)
    assert "raise ValueError" in str(info.value.__cause__)
    assert _gone(_children_seen(tmp_path))


def test_an_error_in_the_caller_stops_the_children(tmp_path):
    def fn(k):
        (tmp_path / str(os.getpid())).touch()
        if os.getpid() == CALLER:
            raise KeyError(k)
        time.sleep(0.05)
        return k

    with pytest.raises(KeyError):
        fork_map(fn, 20, 3)
    assert _gone(_children_seen(tmp_path))


def test_a_killed_child_is_an_error_not_a_hang(tmp_path):
    def fn(k):
        (tmp_path / str(os.getpid())).touch()
        if os.getpid() != CALLER:
            os.kill(os.getpid(), signal.SIGKILL)
        time.sleep(0.1)
        return k

    with pytest.raises(WorkerDied, match="ended without its results"):
        fork_map(fn, 8, 2)
    assert _children_seen(tmp_path) and _gone(_children_seen(tmp_path))


def test_results_that_cannot_be_pickled_are_a_clear_error():
    def fn(k):
        return (lambda: k) if os.getpid() != CALLER else time.sleep(0.2)

    with pytest.raises(RuntimeError, match="could not be pickled"):
        fork_map(fn, 8, 2)


def test_torch_threads_restores_setting():
    before = torch.get_num_threads()
    with torch_threads(1):
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == before
