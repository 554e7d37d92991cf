"""The embedded model's default thread count follows the CPUs the process may use: its
affinity mask capped by a cgroup CPU quota (a container's --cpus, a service's CPUQuota)."""

from __future__ import annotations

from pathlib import Path

import pytest

from aeroweaver_edge.llm import cpus
from aeroweaver_edge.llm.cpus import cgroup_cpu_limit, usable_cpus


def tree(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


@pytest.fixture
def many_cpus(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(cpus, "affinity_cpus", lambda: 64)  # a big host


@pytest.mark.usefixtures("many_cpus")
@pytest.mark.parametrize(
    ("proc", "files", "expected"),
    [
        # cgroup v2, docker --cpus 2 (namespace root)
        ("0::/\n", {"cpu.max": "200000 100000\n"}, 2),
        # v2, no limit
        ("0::/\n", {"cpu.max": "max 100000\n"}, 64),
        # v2, systemd CPUQuota=150% on the service: rounded up
        ("0::/system.slice/aw.service\n", {"system.slice/aw.service/cpu.max": "150000 100000"}, 2),
        # v2, the parent slice is tighter than the service
        (
            "0::/app.slice/aw.service\n",
            {"app.slice/cpu.max": "100000 100000", "app.slice/aw.service/cpu.max": "max 100000"},
            1,
        ),
        # v1, cpu,cpuacct hierarchy, 4 CPUs
        (
            "4:cpu,cpuacct:/docker/abc\n",
            {
                "cpu,cpuacct/docker/abc/cpu.cfs_quota_us": "400000",
                "cpu,cpuacct/docker/abc/cpu.cfs_period_us": "100000",
            },
            4,
        ),
        # v1, no quota (-1)
        ("1:cpu:/\n", {"cpu/cpu.cfs_quota_us": "-1", "cpu/cpu.cfs_period_us": "100000"}, 64),
        # garbage files: no limit assumed
        ("0::/\n", {"cpu.max": "lots of cpus"}, 64),
        # a tiny quota never gives 0 threads
        ("0::/\n", {"cpu.max": "10000 100000"}, 1),
    ],
)
def test_usable_cpus_respect_a_cgroup_quota(
    tmp_path: Path, proc: str, files: dict[str, str], expected: int
) -> None:
    root = tmp_path / "cgroup"
    tree(root, files)
    proc_file = tmp_path / "proc_self_cgroup"
    proc_file.write_text(proc)
    assert usable_cpus(root, proc_file) == expected


def test_no_cgroup_information_means_no_limit(tmp_path: Path) -> None:
    assert cgroup_cpu_limit(tmp_path / "none", tmp_path / "missing") is None
    assert 1 <= usable_cpus() <= 4096  # this machine, whatever it is
