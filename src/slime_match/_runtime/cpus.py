"""How many CPUs this process may use: the default number of Slime's worker processes.

``os.cpu_count()`` counts the machine's CPUs, not this process's. A job given 4 cores of a 64-core node (an
affinity mask: ``taskset``, SLURM, a cpuset) or a container limited to 2 CPUs (a cgroup CPU quota: ``docker
--cpus 2``) would otherwise fork 64 workers onto 4 or 2 cores. A task of a cluster scheduler may also be
allotted fewer CPUs than its node lets it run on: Ray's CPUs of the task or actor, SLURM's
``SLURM_CPUS_PER_TASK``, or ``OMP_NUM_THREADS`` set for it.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Mapping
from pathlib import Path

CGROUP_ROOT = Path("/sys/fs/cgroup")

# environment variables that allot a number of CPUs to a task (``allotted_cpus``)
ALLOTMENT_VARIABLES = ("SLURM_CPUS_PER_TASK", "OMP_NUM_THREADS")


def available_cpus(cgroup_root: Path = CGROUP_ROOT, membership: str | None = None,
                   environ: Mapping[str, str] | None = None) -> int:
    """CPUs this process may use: its affinity mask, capped by its cgroup's CPU quota and by the CPUs allotted
    to its task (``allotted_cpus``); at least 1.

    Args:
        cgroup_root: where the cgroup file systems are mounted.
        membership: the text of ``/proc/self/cgroup`` (read when None).
        environ: the environment variables (``os.environ`` when None).
    """
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity masks (macOS, Windows)
        cpus = os.cpu_count() or 1
    quota = cgroup_cpu_quota(cgroup_root, membership)
    if quota is not None:
        cpus = min(cpus, math.ceil(quota))
    allotted = allotted_cpus(environ)
    if allotted is not None:
        cpus = min(cpus, allotted)
    return max(1, cpus)


def allotted_cpus(environ: Mapping[str, str] | None = None) -> int | None:
    """CPUs a cluster scheduler allotted to this process's task, or None where none says: the fewest of Ray's
    CPUs of the current task or actor (``ray_cpus``), ``SLURM_CPUS_PER_TASK`` and ``OMP_NUM_THREADS``;
    fractions round up, and values that are not positive numbers are ignored.

    Args:
        environ: the environment variables (``os.environ`` when None).
    """
    environ = os.environ if environ is None else environ
    counts = [_positive(environ.get(name, "")) for name in ALLOTMENT_VARIABLES] + [ray_cpus()]
    known = [count for count in counts if count is not None]
    return min(known) if known else None


def ray_cpus() -> int | None:
    """The CPUs Ray assigned to the task or actor this process runs (rounded up), or None: not a Ray worker
    process (Ray is not imported for this), or a task or actor that asked for no CPU."""
    ray = sys.modules.get("ray")
    if ray is None or not ray.is_initialized():
        return None
    context = ray.get_runtime_context()
    if context.worker.mode != ray.WORKER_MODE:  # the driver has no assigned resources
        return None
    cpus = context.get_assigned_resources().get("CPU", 0)
    return math.ceil(cpus) if cpus > 0 else None


def _positive(text: str) -> int | None:
    """A positive count from an environment variable ("4" -> 4, "2.5" -> 3), else None."""
    try:
        value = float(text)
    except ValueError:
        return None
    return math.ceil(value) if math.isfinite(value) and value > 0 else None


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
