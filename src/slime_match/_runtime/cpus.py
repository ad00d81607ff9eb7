"""How many CPUs this process may use: the default number of Slime's worker processes.

``os.cpu_count()`` counts the machine's CPUs, not this process's. A job given 4 cores of a 64-core node (an
affinity mask: ``taskset``, SLURM, a cpuset) or a container limited to 2 CPUs (a cgroup CPU quota: ``docker
--cpus 2``) would otherwise fork 64 workers onto 4 or 2 cores.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

CGROUP_ROOT = Path("/sys/fs/cgroup")


def available_cpus(cgroup_root: Path = CGROUP_ROOT, membership: str | None = None) -> int:
    """CPUs this process may run on: its affinity mask, capped by its cgroup's CPU quota; at least 1.

    Args:
        cgroup_root: where the cgroup file systems are mounted.
        membership: the text of ``/proc/self/cgroup`` (read when None).
    """
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity masks (macOS, Windows)
        cpus = os.cpu_count() or 1
    quota = cgroup_cpu_quota(cgroup_root, membership)
    if quota is not None:
        cpus = min(cpus, math.ceil(quota))
    return max(1, cpus)


def cgroup_cpu_quota(cgroup_root: Path = CGROUP_ROOT, membership: str | None = None) -> float | None:
    """CPUs' worth of time per period that this process's cgroup may use (cgroup v2 ``cpu.max``, v1
    ``cpu.cfs_quota_us`` / ``cpu.cfs_period_us``), or None when unlimited or unknown.

    The cgroup's folder is its path from ``membership`` under the mount, else the mount itself (a container
    that sees only its own cgroup there while ``/proc/self/cgroup`` names the host's path).
    """
    if membership is None:
        try:
            membership = Path("/proc/self/cgroup").read_text()
        except OSError:
            return None
    for line in membership.splitlines():
        parts = line.split(":", 2)
        if len(parts) != 3:
            continue
        _, controllers, path = parts
        if controllers == "":  # v2: "0::/path"
            fields = _read_first(cgroup_root, path, "cpu.max").split()
            if len(fields) == 2 and fields[0] != "max":
                return _ratio(fields[0], fields[1])
        elif "cpu" in controllers.split(","):  # v1: "4:cpu,cpuacct:/path"
            mount = cgroup_root / controllers
            return _ratio(_read_first(mount, path, "cpu.cfs_quota_us"), _read_first(mount, path, "cpu.cfs_period_us"))
    return None


def _read_first(mount: Path, path: str, name: str) -> str:
    """The file ``name`` of the cgroup ``path`` under ``mount``, else of the mount's own folder ("" if neither)."""
    return _read(mount / path.lstrip("/") / name) or _read(mount / name)


def _read(path: Path) -> str:
    try:
        return path.read_text().strip()
    except OSError:
        return ""


def _ratio(quota: str, period: str) -> float | None:
    """quota / period in CPUs, None for no quota (v1 writes -1) or unreadable values."""
    try:
        q, p = int(quota), int(period)
    except ValueError:
        return None
    return q / p if q > 0 and p > 0 else None
