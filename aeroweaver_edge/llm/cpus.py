"""How many CPUs this process can really use: the embedded model's default thread count.

``os.cpu_count()`` counts the host's CPUs. In a container limited to 2 CPUs on a 64-core
host (``docker --cpus 2``), or a systemd service with ``CPUQuota=200%``, it says 64, and
llama.cpp would start 64 threads that meet at a barrier in every layer: each waits for the
others to be scheduled inside a 2-CPU quota, and decoding slows by an order of magnitude
(notes in ``embedded.default_threads``). The usable count is the affinity mask, capped by
any CFS quota on the process's cgroup or its ancestors (v2 ``cpu.max``, v1
``cpu.cfs_quota_us`` / ``cpu.cfs_period_us``), rounded up, never below 1.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

CGROUP_ROOT = Path("/sys/fs/cgroup")
PROC_CGROUP = Path("/proc/self/cgroup")


def affinity_cpus() -> int:
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def _read(path: Path) -> str | None:
    try:
        return path.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        return None


def _v2_quota(directory: Path) -> float | None:
    text = _read(directory / "cpu.max")  # "max 100000" or "200000 100000"
    if text is None:
        return None
    parts = text.split()
    try:
        if len(parts) == 2 and parts[0] != "max" and int(parts[1]) > 0:
            return int(parts[0]) / int(parts[1])
    except ValueError:
        pass
    return None


def _v1_quota(directory: Path) -> float | None:
    quota, period = _read(directory / "cpu.cfs_quota_us"), _read(directory / "cpu.cfs_period_us")
    try:
        if quota is not None and period is not None and int(quota) > 0 and int(period) > 0:
            return int(quota) / int(period)
    except ValueError:
        pass
    return None


def _ancestors(base: Path, rel: str) -> list[Path]:
    """``base/rel`` and every directory above it up to ``base`` (a quota on a parent slice
    limits its children too)."""
    out = [base]
    current = base
    for part in [p for p in rel.split("/") if p and p not in (".", "..")]:
        current = current / part
        out.append(current)
    return out


def cgroup_cpu_limit(root: Path = CGROUP_ROOT, proc_cgroup: Path = PROC_CGROUP) -> float | None:
    """The tightest CFS quota (in CPUs) on this process's cgroup path, or None."""
    text = _read(proc_cgroup)
    if text is None:
        return None
    quotas: list[float] = []
    for line in text.splitlines():
        fields = line.split(":", 2)
        if len(fields) != 3:
            continue
        _, controllers, rel = fields
        if controllers == "":  # cgroup v2 (unified)
            for d in _ancestors(root, rel):
                q = _v2_quota(d)
                if q is not None:
                    quotas.append(q)
        elif "cpu" in controllers.split(","):  # cgroup v1 cpu controller
            for mount in dict.fromkeys((root / controllers, root / "cpu", root / "cpu,cpuacct")):
                for d in _ancestors(mount, rel):
                    q = _v1_quota(d)
                    if q is not None:
                        quotas.append(q)
    return min(quotas) if quotas else None


def usable_cpus(root: Path = CGROUP_ROOT, proc_cgroup: Path = PROC_CGROUP) -> int:
    n = affinity_cpus()
    limit = cgroup_cpu_limit(root, proc_cgroup)
    if limit is not None:
        n = min(n, math.ceil(limit - 1e-9))
    return max(1, n)


__all__ = ["affinity_cpus", "cgroup_cpu_limit", "usable_cpus"]
