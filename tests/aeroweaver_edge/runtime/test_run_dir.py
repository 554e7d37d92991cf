"""A run's directory is removed by whoever of the run goes last, or by the next run's sweep,
never while anyone of the run still holds it; directories that are not ours stay."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aeroweaver_edge.contracts.errors import RunFailed
from aeroweaver_edge.runtime.run_dir import (
    ENV_DIR,
    LOCK_NAME,
    OWNER_NAME,
    RunDir,
    RunMember,
    attach_to_run,
    sweep_stale,
)
from aeroweaver_lab.bench.orphans import running

HOLDER = """
import sys, time
from pathlib import Path
from aeroweaver_edge.runtime.run_dir import RunMember
member = RunMember.join(Path(sys.argv[1]))
print("joined" if member else "gone", flush=True)
time.sleep(600)
"""


def hold_in_child(path: Path) -> subprocess.Popen[str]:
    """A separate process holding the run's lock (as a daemon process does)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(path)], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "joined"
    return proc


def kill9(proc: subprocess.Popen[str]) -> None:
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)


def test_the_run_removes_its_directory_at_the_end(tmp_path: Path) -> None:
    with RunDir.create(parent=tmp_path) as run:
        assert run.path.is_dir()
        assert (run.path / LOCK_NAME).is_file()
        assert (run.path / OWNER_NAME).read_text().strip() == str(os.getpid())
        (run.path / "uav0.log").write_text("x")
    assert not run.path.exists()


def test_a_member_leaving_while_the_run_lives_removes_nothing(tmp_path: Path) -> None:
    with RunDir.create(parent=tmp_path) as run:
        member = RunMember.join(run.path)
        assert member is not None
        assert member.leave() is False
        assert run.path.is_dir()


def test_the_last_member_out_of_a_killed_run_removes_the_directory(tmp_path: Path) -> None:
    run = RunDir.create(parent=tmp_path)
    other = hold_in_child(run.path)
    member = RunMember.join(run.path)
    assert member is not None
    # The run's own process "dies": its lock goes (as the kernel drops it on SIGKILL).
    assert run._fd is not None
    os.close(run._fd)
    run._fd = None
    try:
        assert member.leave() is False  # another daemon of the run is still running
        assert run.path.is_dir()
    finally:
        kill9(other)
    last = RunMember.join(run.path)
    assert last is not None
    assert last.leave() is True
    assert not run.path.exists()


def test_the_sweep_removes_only_directories_nobody_holds(tmp_path: Path) -> None:
    live = RunDir.create(parent=tmp_path)
    dead = RunDir.create(parent=tmp_path)
    held = RunDir.create(parent=tmp_path)
    holder = hold_in_child(held.path)
    foreign = tmp_path / "aeroweaver-not-ours"  # no lock file: an older release, or not a run
    foreign.mkdir()
    unrelated = tmp_path / "somebody-else"
    unrelated.mkdir()
    for run in (dead, held):  # their runs were killed
        assert run._fd is not None
        os.close(run._fd)
        run._fd = None
    try:
        assert sweep_stale(tmp_path) == [dead.path]
        assert live.path.is_dir()
        assert held.path.is_dir()
        assert foreign.is_dir()
        assert unrelated.is_dir()
    finally:
        kill9(holder)
    assert sweep_stale(tmp_path) == [held.path]  # its last daemon was killed too
    assert live.path.is_dir()
    live.close()
    assert not live.path.exists()


def test_a_daemon_of_a_run_that_is_gone_does_not_start(tmp_path: Path) -> None:
    gone = tmp_path / "aeroweaver-gone"
    with pytest.raises(RunFailed, match="is gone"):
        attach_to_run({ENV_DIR: str(gone)})
    assert attach_to_run({}) is None  # not started by a run: nothing to hold


def test_die_with_parent_sends_sigterm_when_the_parent_is_killed(tmp_path: Path) -> None:
    """A parent process spawns a child that asks for PR_SET_PDEATHSIG; SIGKILL the parent:
    the child gets SIGTERM (exit -15) right away instead of living on."""
    if not sys.platform.startswith("linux"):
        pytest.skip("PR_SET_PDEATHSIG is Linux only")
    pidfile = tmp_path / "child.pid"
    child = (
        "import os, sys, time; from aeroweaver_edge.runtime.lifecycle import die_with_parent; "
        "assert die_with_parent(int(sys.argv[1])); "
        f"open({str(pidfile)!r}, 'w').write(str(os.getpid())); time.sleep(600)"
    )
    parent = (
        "import os, subprocess, sys, time; "
        f"subprocess.Popen([sys.executable, '-c', {child!r}, str(os.getpid())]); time.sleep(600)"
    )
    proc = subprocess.Popen([sys.executable, "-c", parent])
    deadline = time.monotonic() + 60
    while not pidfile.exists() or not pidfile.read_text():
        assert time.monotonic() < deadline, "the child never started"
        time.sleep(0.05)
    pid = int(pidfile.read_text())
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert wait_gone(pid, 10.0), f"child {pid} outlived its parent"


def wait_gone(pid: int, timeout_s: float) -> bool:
    """Bounded wait until ``pid`` no longer runs (a zombie counts as gone)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not running(pid):
            return True
        time.sleep(0.05)
    return not running(pid)


def test_a_daemon_stopped_during_start_up_still_removes_the_directory(tmp_path: Path) -> None:
    """SIGTERM (what the parent-death signal sends) reaching a daemon process of a killed
    run while it is still starting (imports, config: before its event loop handles
    signals) must not kill it outright: it stops cleanly, and as the last one out it
    removes the run's directory. Before: it died of the signal and, when every daemon of
    the run was still starting, the directory stayed behind."""
    from aeroweaver_edge.config import AgentConfig, UavConfig
    from aeroweaver_edge.runtime.run_dir import ENV_PARENT

    run = RunDir.create(parent=tmp_path)
    config = run.path / "uav0.json"
    config.write_text(
        UavConfig(uav="uav0", agent=AgentConfig(selector="scripted", beta=0.0)).model_dump_json(),
        encoding="utf-8",
    )
    daemon = subprocess.Popen(
        [sys.executable, "-m", "aeroweaver_edge", "daemon", "--config", str(config)],
        env={**os.environ, ENV_DIR: str(run.path), ENV_PARENT: str(os.getpid())},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        # The run's own process "dies" (its lock goes); the daemon is the last member.
        assert run._fd is not None
        os.close(run._fd)
        run._fd = None
        # Wait (bounded) until the daemon has joined: our exclusive try then fails.
        probe = os.open(run.path / LOCK_NAME, os.O_RDWR)
        try:
            deadline = time.monotonic() + 60
            while _exclusive_free(probe):
                assert daemon.poll() is None, daemon.stderr.read() if daemon.stderr else ""
                assert time.monotonic() < deadline, "the daemon never joined its run"
                time.sleep(0.002)
        finally:
            os.close(probe)
        daemon.send_signal(signal.SIGTERM)  # at once: most likely still importing
        _out, err = daemon.communicate(timeout=60)
    finally:
        if daemon.poll() is None:
            kill9(daemon)  # type: ignore[arg-type]
    assert daemon.returncode == 0, err
    assert "Traceback" not in err
    assert not run.path.exists()


def _exclusive_free(fd: int) -> bool:
    """Whether nobody holds the lock (we take it exclusively and release it at once)."""
    import fcntl

    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    fcntl.flock(fd, fcntl.LOCK_UN)
    return True
