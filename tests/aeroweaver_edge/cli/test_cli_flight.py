"""Flight commands: ``aeroweaver emulator``, ``signing-key``, ``bench mavlink`` and a daemon
whose vehicle cannot be reached (one clear line, non-zero exit, no traceback)."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

from aeroweaver_edge.cli.main import main
from aeroweaver_edge.vehicle.mavlink.signing import load_key
from tests.helpers.mav import free_udp_ports


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--param", "COM_OBL_RC_ACT"], "--param 'COM_OBL_RC_ACT': expected NAME=NUMBER"),
        (["--param", "NO_SUCH_PARAM=1"], "unknown px4 parameter 'NO_SUCH_PARAM'"),
        (["--uavs", "0"], "uavs must be 1..250, got 0"),
        (["--drop", "120"], "--drop 120.0: expected a percentage in [0, 100)"),
        (["--port-base", "65535", "--uavs", "2"], "are not valid UDP ports"),
        (["--time-scale", "0"], "time_scale must be > 0"),
    ],
)
def test_emulator_bad_arguments_exit_2_with_one_line(
    capsys: pytest.CaptureFixture[str], argv: list[str], needle: str
) -> None:
    assert main(["emulator", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("aeroweaver emulator: ")
    assert needle in err
    assert "Traceback" not in err
    assert err.count("\n") == 1


def test_emulator_refuses_a_world_readable_signing_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["signing-key", str(tmp_path / "uav0.key")]) == 0
    (tmp_path / "uav0.key").chmod(0o644)
    assert main(["emulator", "--signing-key-dir", str(tmp_path)]) == 2
    assert "chmod 600" in capsys.readouterr().err


def test_signing_key_is_created_private_and_never_overwritten(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "keys" / "uav3.key"
    assert main(["signing-key", str(path)]) == 0
    key = load_key(path)
    assert main(["signing-key", str(path)]) == 2
    assert "exists; use --force" in capsys.readouterr().err
    assert load_key(path) == key
    assert main(["signing-key", str(path), "--force"]) == 0
    assert load_key(path) != key


def test_a_daemon_whose_vehicle_is_silent_exits_1_naming_the_link(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    port = free_udp_ports(1)[0]
    cfg = tmp_path / "uav.toml"
    cfg.write_text(
        'uav = "uav0"\n[mesh]\nlisten = ["tcp/127.0.0.1:0"]\n[agent]\nselector = "scripted"\n'
        f'[vehicle]\nbackend = "mavlink"\nurl = "udpin://127.0.0.1:{port}"\n'
        "connect_timeout_s = 0.5\n",
        encoding="utf-8",
    )
    assert main(["daemon", "--config", str(cfg)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("aeroweaver: vehicle: uav0: no heartbeat from an autopilot on udpin://")
    assert "Traceback" not in err


def test_bench_mavlink_prints_the_link_figures(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "mavlink", "--seconds", "0.5"]) == 0
    out = capsys.readouterr().out
    assert "command round trip (COMMAND_LONG -> COMMAND_ACK, n=200): p50" in out
    assert "Hz received by the autopilot (configured 20 Hz)" in out


def test_sim_link_mavsdk_without_the_extra_is_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "mavsdk" else real(name, *a)
    )
    assert main(["sim", "coverage", "--selector", "scripted", "--link", "mavsdk"]) == 2
    assert "pip install 'aeroweaver-edge[mavsdk]'" in capsys.readouterr().err


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGTERM, 0), (signal.SIGINT, 130)])
def test_emulator_is_a_service_sigterm_exits_0(sig: signal.Signals, code: int) -> None:
    """systemd stops a service with SIGTERM: a normal end (0); Ctrl-C stays 130."""
    port = free_udp_ports(1)[0]
    proc = subprocess.Popen(
        [sys.executable, "-m", "aeroweaver_edge", "emulator", "--uavs", "1",
         "--port-base", str(port)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        proc.stdout.readline()  # it is up once it says where it listens
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == code, err
    assert "Traceback" not in err


@pytest.mark.mavsdk
@pytest.mark.slow
def test_sim_quiet_over_mavsdk_prints_nothing_from_mavsdk(tmp_path: Path) -> None:
    """MAVSDK's C library prints its own log on stdout; it now goes through Python logging
    (logger ``mavsdk``), so ``--quiet`` leaves the terminal to the summary. A subprocess:
    the library's output goes to the file descriptors, below any Python capture."""
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-m", "aeroweaver_edge", "sim", "coverage", "--link", "mavsdk",
         "--selector", "scripted", "--rounds", "2", "--quiet", "--insecure"],
        capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""  # before: 12 lines of MAVSDK's "[Info ] ..." per run
    assert "[Info" not in done.stdout
    assert "team mean return" in done.stdout
