"""``slime pairs --ray``: pairs matched by the actors of a local Ray cluster of two 1-CPU nodes on the
loopback address, as a local run matches them; an actor killed in a pair; resuming; Ray's CPUs of a task."""

import json
import os
import shutil
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli

os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")  # read when ray loads: nodes on 127.0.0.1
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
os.environ.setdefault("RAY_AUTH_MODE", "disabled")  # a throw-away cluster on the loopback address
ray = pytest.importorskip("ray", reason="needs Ray, the ray extra (pip install 'slime-match[ray]')")

from ray.cluster_utils import Cluster

from slime_match._runtime.cpus import available_cpus, ray_cpus
from slime_match.config import make_config
from slime_match.errors import ConfigError
from slime_match.runs.batch import PairJob, match_pairs, read_pairs

FAST = ["--method", "rootsift"]  # the base RootSIFT alone: the run logic, not the matcher, is under test
PAIRS = ("left.png right.png\nright.png left.png\nleft.png sub/right.png\nsub/right.png left.png\n"
         "right.png sub/right.png\nsub/right.png right.png\n")


@pytest.fixture(scope="module")
def cluster():
    """A head node and a second node, 1 CPU each, on 127.0.0.1; this process connected to them."""
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    try:
        cluster.add_node(num_cpus=1)
        ray.init(address=cluster.address, logging_level="WARNING")
        cluster.wait_for_nodes()
        yield cluster
    finally:
        ray.shutdown()
        cluster.shutdown()


def test_a_ray_run_writes_what_a_local_run_writes_and_resumes(cluster, images, tmp_path, capsys):
    pairs = tmp_path / "pairs.txt"
    pairs.write_text(PAIRS)
    local, remote = tmp_path / "local", tmp_path / "ray"
    code, stdout, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", local, *FAST, "--workers", 2)
    assert code == 0 and "6 pairs: 6 matched" in stdout, err
    code, stdout, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", remote, *FAST,
                                "--ray", cluster.address)
    assert code == 0 and "6 pairs: 6 matched, 0 already done, 0 failed" in stdout, err

    def without_seconds(folder):
        index = json.loads((folder / "pairs.json").read_text())
        return [{k: v for k, v in r.items() if k != "seconds"} for r in index["pairs"]], index["finished"]

    assert without_seconds(remote) == without_seconds(local)
    assert (remote / "run.json").read_text() == (local / "run.json").read_text()
    assert sorted(p.name for p in (remote / "records").iterdir()) == sorted(p.name for p in (local / "records").iterdir())
    for record in json.loads((local / "pairs.json").read_text())["pairs"]:
        a, b = (np.load(run / record["folder"] / "matches.npz") for run in (local, remote))
        assert len(a["scores"]) > 100 and all(np.array_equal(a[key], b[key]) for key in a.files)

    shutil.rmtree(remote / "right.png__sub-right.png")  # a pair lost: the rerun matches it alone
    (remote / "records" / "right.png__sub-right.png.json").unlink()
    code, stdout, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", remote, *FAST, "--ray")
    assert code == 0 and "6 pairs: 1 matched, 5 already done, 0 failed" in stdout, err
    assert without_seconds(remote) == without_seconds(local)

    code, _, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", remote, *FAST, "--upright", "--ray")
    assert code == 2 and "another configuration" in err  # the configuration check of a local run


def _blocked_actor(skip: set[int], deadline: float) -> int:
    """A Ray worker process (not in ``skip``) blocked opening a FIFO that has no writer."""
    while True:
        for proc in Path("/proc").glob("[0-9]*"):
            try:
                if (int(proc.name) not in skip and (proc / "cmdline").read_bytes().startswith(b"ray::")
                        and (proc / "wchan").read_text() == "wait_for_partner"):
                    return int(proc.name)
            except (OSError, ValueError):  # an ended process
                continue
        assert time.monotonic() < deadline, "no Ray actor opened the FIFO"
        time.sleep(0.05)


def _kill_readers(fifo: Path, deaths: int, image: Path) -> None:
    """Kill the actor that opens ``fifo`` (its pair's image), ``deaths`` times; before the last, when only one,
    put ``image`` in its place for the next actor."""
    deadline = time.monotonic() + 120
    killed: set[int] = set()
    try:
        for death in range(deaths):
            pid = _blocked_actor(killed, deadline)
            if deaths == 1:
                shutil.copy(image, fifo.with_suffix(".tmp"))
                os.replace(fifo.with_suffix(".tmp"), fifo)  # the blocked actor still waits on the FIFO
            os.kill(pid, signal.SIGKILL)
            killed.add(pid)
    except BaseException:
        if fifo.is_fifo():  # lets a blocked actor go on (it reads nothing: its pair fails), the run end
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        raise


@pytest.mark.skipif(not Path("/proc/self/wchan").is_file(), reason="finds the actors' processes in /proc (Linux)")
@pytest.mark.parametrize("deaths, status", [(1, "done"), (2, "failed")])
def test_a_killed_actor_s_pair_goes_to_another_actor_once(cluster, images, tmp_path, caplog, deaths, status):
    """An actor stuck opening its pair's image (a FIFO) is killed: the pair goes to another actor, which
    matches it (the image back in place) or is killed too, and the pair is recorded as failed; the run ends,
    the other pair matched."""
    os.mkfifo(images / "stuck.png")
    jobs = [PairJob("stuck.png", "right.png", images / "stuck.png", images / "right.png", "stuck.png__right.png")]
    jobs += read_pairs(_pairs_file(tmp_path, "left.png right.png\n"), images)
    killer = threading.Thread(target=_kill_readers, args=(images / "stuck.png", deaths, images / "left.png"))
    killer.start()
    records = match_pairs(make_config("rootsift"), jobs, tmp_path / "run", backend="ray")
    killer.join()
    assert [r["status"] for r in records] == [status, "done"], records
    assert records[1]["matches"] > 100
    if status == "done":
        assert records[0]["matches"] > 100
    else:
        assert "its Ray actor died twice" in records[0]["error"]
    assert "stuck.png right.png: its Ray actor died" in caplog.text  # the first death, before the retry
    index = json.loads((tmp_path / "run" / "pairs.json").read_text())
    assert index["finished"] and [r["status"] for r in index["pairs"]] == [status, "done"]


def _pairs_file(tmp_path, text):
    path = tmp_path / "pairs.txt"
    path.write_text(text)
    return path


def test_ray_cpus_of_an_actor_bound_its_workers(cluster):
    assert ray_cpus() is None  # this process is the driver: no CPUs assigned

    @ray.remote(num_cpus=1, runtime_env={"env_vars": {"OMP_NUM_THREADS": "8"}})
    def inside() -> tuple[int | None, int]:
        return ray_cpus(), available_cpus(environ={})

    assert ray.get(inside.remote()) == (1, 1)


def test_more_cpus_per_actor_than_a_node_has_is_refused(cluster, images, tmp_path):
    jobs = read_pairs(_pairs_file(tmp_path, "left.png right.png\nright.png left.png\n"), images)
    with pytest.raises(ConfigError, match="more than any node"):
        match_pairs(make_config("rootsift"), jobs, tmp_path / "run", backend="ray", cpus_per_worker=2)
    assert not (tmp_path / "run").exists()
