"""``available_cpus``: the affinity mask, the cgroup CPU quota and a scheduler's allotment bound Slime's default
worker count."""

import os
import sys

import pytest

from slime_match._runtime.cpus import allotted_cpus, available_cpus, cgroup_cpu_quota, ray_cpus
from slime_match.config import make_config
from slime_match.errors import ConfigError
from slime_match.slime.pipeline import _workers

linux_only = pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="needs CPU affinity masks (Linux)")


@linux_only
def test_affinity_mask_bounds_the_default_workers():
    mask = os.sched_getaffinity(0)
    assert available_cpus(membership="", environ={}) == len(mask)
    os.sched_setaffinity(0, {min(mask)})
    try:  # what `taskset -c 0 slime match ...` or a one-core SLURM job gives
        assert available_cpus(membership="", environ={}) == 1
        assert _workers(None) == 1
        assert _workers(3) == 3  # an explicit count is kept
    finally:
        os.sched_setaffinity(0, mask)


def _cgroup(root, relative, files):
    folder = root / relative
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (folder / name).write_text(text + "\n")


def test_cgroup_v2_quota(tmp_path):
    _cgroup(tmp_path, "job/step", {"cpu.max": "150000 100000"})
    assert cgroup_cpu_quota(tmp_path, "0::/job/step\n") == 1.5
    assert available_cpus(tmp_path, "0::/job/step\n") == min(2, available_cpus(membership=""))
    _cgroup(tmp_path, "free", {"cpu.max": "max 100000"})
    assert cgroup_cpu_quota(tmp_path, "0::/free\n") is None


def test_cgroup_v1_quota(tmp_path):
    membership = "9:name=systemd:/\n4:cpu,cpuacct:/docker/abc\n0::/\n"
    _cgroup(tmp_path, "cpu,cpuacct/docker/abc", {"cpu.cfs_quota_us": "50000", "cpu.cfs_period_us": "100000"})
    assert cgroup_cpu_quota(tmp_path, membership) == 0.5
    assert available_cpus(tmp_path, membership) == 1  # half a CPU still runs one process
    _cgroup(tmp_path, "cpu/", {"cpu.cfs_quota_us": "-1", "cpu.cfs_period_us": "100000"})
    assert cgroup_cpu_quota(tmp_path, "1:cpu:/\n") is None


def test_a_container_sees_its_cgroup_at_the_mount(tmp_path):
    """/proc/self/cgroup names the host's path, the container mounts only its own cgroup: its files are read."""
    _cgroup(tmp_path, "", {"cpu.max": "200000 100000"})
    assert cgroup_cpu_quota(tmp_path, "0::/system.slice/docker-abc.scope\n") == 2.0


def test_missing_or_odd_cgroup_files_mean_no_quota(tmp_path):
    assert cgroup_cpu_quota(tmp_path, "0::/nowhere\n1:cpu:/nowhere\n") is None
    _cgroup(tmp_path, "odd", {"cpu.max": "lots 100000"})
    assert cgroup_cpu_quota(tmp_path, "0::/odd\n") is None
    assert cgroup_cpu_quota(tmp_path, "") is None
    assert cgroup_cpu_quota(tmp_path, "not a cgroup line\n") is None


@pytest.mark.parametrize("workers", [0, -2, 1.5, "two"])
def test_bad_worker_counts_are_config_errors(workers):
    with pytest.raises(ConfigError, match="workers"):
        make_config("slime", workers=workers)


def test_a_worker_count_given_as_text_is_read_as_a_number():
    assert make_config("slime", workers="2").slime.workers == 2  # as --set slime.workers=2 reads it


@pytest.mark.parametrize("environ, cpus", [
    ({}, None),
    ({"SLURM_CPUS_PER_TASK": "3"}, 3),
    ({"SLURM_CPUS_PER_TASK": "3", "OMP_NUM_THREADS": "2"}, 2),  # the fewest
    ({"OMP_NUM_THREADS": "2.5"}, 3),
    ({"SLURM_CPUS_PER_TASK": "0", "OMP_NUM_THREADS": "many"}, None),  # not positive numbers: ignored
    ({"OMP_NUM_THREADS": "", "SLURM_CPUS_PER_TASK": "-1"}, None),
])
def test_a_scheduler_s_allotment(environ, cpus, monkeypatch):
    monkeypatch.delitem(sys.modules, "ray", raising=False)  # not a Ray worker
    assert allotted_cpus(environ) == cpus


def test_the_allotment_bounds_the_default_workers(monkeypatch):
    monkeypatch.delitem(sys.modules, "ray", raising=False)
    assert ray_cpus() is None
    assert available_cpus(membership="", environ={"OMP_NUM_THREADS": "1"}) == 1
    assert available_cpus(membership="", environ={"SLURM_CPUS_PER_TASK": "1000"}) == available_cpus(
        membership="", environ={})  # an allotment never raises the count
    monkeypatch.setenv("SLURM_CPUS_PER_TASK", "1")  # a one-CPU task of a SLURM job step
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert _workers(None) == 1
    assert _workers(3) == 3  # an explicit count is kept
