"""The SITL launcher takes the binary as a user's input: missing, not executable or exiting
at once gives one line naming it, without a hang and without a process or namespace left
behind. These run in CI without any SITL build (the "binaries" are made here)."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import pytest

from tests.helpers import sitl
from tests.helpers.netlab import NetLab


def namespaces() -> set[str]:
    out = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, timeout=30)
    return {line.split()[0] for line in out.stdout.splitlines() if line.strip()}


def test_a_missing_binary_is_named(tmp_path: Path) -> None:
    with pytest.raises(sitl.SitlError, match=r"^AEROWEAVER_SITL=.*/nope: no such file$"):
        sitl.check_binary(tmp_path / "nope")


def test_a_directory_or_a_file_that_cannot_run_is_named(tmp_path: Path) -> None:
    with pytest.raises(sitl.SitlError, match="is a directory"):
        sitl.check_binary(tmp_path)
    plain = tmp_path / "arducopter"
    plain.write_text("not a program\n")
    plain.chmod(0o644)
    with pytest.raises(sitl.SitlError, match=r"arducopter: not executable"):
        sitl.check_binary(plain)


def test_without_the_variable_the_skip_says_what_to_provide(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(sitl.ENV, raising=False)
    why = sitl.unavailable()
    assert why == sitl.SKIP
    assert "AEROWEAVER_SITL=/path/to/arducopter" in why
    assert "\n" not in why


@pytest.mark.skipif(NetLab.unavailable() is not None, reason=str(NetLab.unavailable()))
def test_an_instance_that_exits_at_once_is_named_and_nothing_is_left(tmp_path: Path) -> None:
    fake = tmp_path / "arducopter"
    fake.write_text("#!/bin/sh\necho 'bad option or missing library'\nexit 3\n")
    fake.chmod(0o755)
    before = namespaces()
    started = time.monotonic()
    fleet = sitl.SitlFleet(sitl.check_binary(fake), tmp_path / "run")
    with pytest.raises(sitl.SitlError) as err:
        fleet.start(2)
    assert time.monotonic() - started < sitl.EARLY_EXIT_S + 5  # no hang
    line = str(err.value)
    assert "\n" not in line
    assert "exited at once (status 3): bad option or missing library" in line
    assert str(fake) in line
    assert namespaces() == before  # every namespace and link removed
    assert fleet.instances == []


@pytest.mark.skipif(NetLab.unavailable() is not None, reason=str(NetLab.unavailable()))
def test_close_stops_a_running_instance_and_its_children(tmp_path: Path) -> None:
    fake = tmp_path / "arducopter"
    # a long-lived "instance" with a child of its own, like SITL under a wrapper script
    fake.write_text("#!/bin/sh\nsleep 600 &\nwait\n")
    fake.chmod(0o755)
    before = namespaces()
    with sitl.SitlFleet(sitl.check_binary(fake), tmp_path / "run") as fleet:
        [inst] = fleet.start(1)
        pid = inst.proc.pid
        assert inst.proc.poll() is None
        assert (tmp_path / "run" / "sitl0" / "aeroweaver-sitl.parm").is_file()
    assert inst.proc.returncode is not None
    deadline = time.monotonic() + 5
    while (
        subprocess.run(["pgrep", "-g", str(pid)], capture_output=True, timeout=30).returncode == 0
    ):
        assert time.monotonic() < deadline, "a process of the instance's group is left"
        time.sleep(0.05)
    assert namespaces() == before
