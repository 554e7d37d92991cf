"""The ``aeroweaver`` command line: bad config exits 2 naming the key; help works."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from aeroweaver_edge.cli.main import build_parser, main
from aeroweaver_edge.tasks import TASK_NAMES


def aeroweaver() -> list[str]:
    """The installed console script (falls back to ``python -m``)."""
    script = Path(sys.executable).with_name("aeroweaver")
    if script.exists():
        return [str(script)]
    found = shutil.which("aeroweaver")
    return [found] if found else [sys.executable, "-m", "aeroweaver_edge"]


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*aeroweaver(), *args], capture_output=True, text=True, timeout=60, cwd=cwd, check=False
    )


def test_daemon_with_a_typo_in_its_config_exits_2_naming_the_key(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('uav = "uav0"\n[safety]\nmax_sped_mps = 3.0\n', encoding="utf-8")
    proc = run("daemon", "--config", str(bad), cwd=tmp_path)
    assert proc.returncode == 2
    assert "config error" in proc.stderr
    assert "safety.max_sped_mps" in proc.stderr
    assert str(bad) in proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ('uav = "UAV 0"\n', "uav"),
        ('uav = "uav0"\n[safety]\ngeofence_north_m = [70.0, -70.0]\n', "safety.geofence_north_m"),
        ('uav = "uav0"\n[mesh\n', "TOML"),
        ('uav = "uav0"\n[vehicle]\nbackend = "mavlink"\n', "url is required for backend 'mavlink'"),
    ],
)
def test_daemon_config_errors_exit_2_in_process(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, needle: str
) -> None:
    path = tmp_path / "uav.toml"
    path.write_text(text, encoding="utf-8")
    assert main(["daemon", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("aeroweaver: config error: ")
    assert needle in err


def test_daemon_with_a_missing_config_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["daemon", "--config", str(tmp_path / "absent.toml")]) == 2
    assert "absent.toml: cannot read" in capsys.readouterr().err


def test_an_in_process_daemon_leaves_sigterm_as_it_found_it(tmp_path: Path) -> None:
    """``cmd_daemon`` ignores SIGTERM while it leaves; a program that called it (a test,
    an embedding) must not keep SIG_IGN, which every process it starts would inherit."""

    def mine(_signum: int, _frame: object) -> None:
        pass

    before = signal.signal(signal.SIGTERM, mine)
    try:
        assert main(["daemon", "--config", str(tmp_path / "absent.toml")]) == 2
        assert signal.getsignal(signal.SIGTERM) is mine
    finally:
        signal.signal(signal.SIGTERM, before)


def test_help_lists_every_command(tmp_path: Path) -> None:
    proc = run("--help", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("usage: aeroweaver")
    for command in ("sim", "daemon", "probe", "bench"):
        assert command in proc.stdout


@pytest.mark.parametrize(
    ("command", "flag"),
    [("daemon", "--config"), ("sim", "--selector"), ("probe", "--llm"), ("bench", "--kills")],
)
def test_subcommand_help(capsys: pytest.CaptureFixture[str], command: str, flag: str) -> None:
    with pytest.raises(SystemExit) as info:
        main([command, "--help"])
    assert info.value.code == 0
    assert flag in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv",
    [
        [], ["daemon"], ["sim", "--selector", "oracle"], ["fly"], ["sim", "--uavs", "three"],
        ["sim", "--history", "-1"], ["sim", "--history", "x"], ["sim", "--state-text", "all"],
    ],
)  # fmt: skip
def test_usage_errors_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("aeroweaver: error: ")
    assert err.count("\n") == 1  # one line, naming the command's --help
    assert "--help'" in err


def test_sim_defaults_match_the_paper_horizon() -> None:
    args = build_parser().parse_args(["sim"])
    # No task: coverage, unless a --mission names another (the plan decides).
    assert (args.task, args.uavs, args.rounds, args.selector) == (None, None, 24, "llm")


def test_sim_method_switches_default_to_the_paper_and_reach_the_options() -> None:
    args = build_parser().parse_args(["sim"])
    assert (args.history, args.state_text, args.llm_slots) == (8, "full", False)
    args = build_parser().parse_args(["sim", "--history", "0", "--state-text", "observation"])
    assert (args.history, args.state_text) == (0, "observation")


def test_bench_llm_latency_refuses_a_bad_shape_in_one_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["bench", "llm_latency", "--uavs", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "--uavs and --rounds must be >= 1" in err


@pytest.mark.parametrize("task", TASK_NAMES)
def test_sim_accepts_every_task_name(task: str) -> None:
    assert build_parser().parse_args(["sim", task, "--uavs", "50"]).task == task


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["sim", "coverage", "--uavs", "51"], "--uavs: 51 is out of range (1..50)"),
        (["sim", "coverage", "--uavs", "0"], "--uavs: 0 is out of range (1..50)"),
        (["sim", "coverage", "--uavs", "many"], "'many' is not a whole number"),
        (["sim", "search_and_rescue"], "invalid choice: 'search_and_rescue'"),
    ],
)
def test_bad_sim_arguments_exit_2_with_one_line(
    capsys: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert words in err
    assert "Traceback" not in err


def test_a_size_the_task_does_not_take_exits_2_without_traceback(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["sim", "private_communication", "--uavs", "5", "--selector", "scripted"]) == 2
    err = capsys.readouterr().err
    assert "private_communication needs exactly 2 UAVs (sender, receiver), got 5" in err
    assert "Traceback" not in err


def test_verbosity_flags_work_after_any_subcommand(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``aeroweaver daemon --config X -v`` is no usage error: the config is read (and here
    refused: it does not exist); a bad level is a usage error naming the choices."""
    missing = str(tmp_path / "nope.toml")
    assert main(["daemon", "--config", missing, "-v", "--log-level", "info"]) == 2
    err = capsys.readouterr().err
    assert "cannot read" in err
    assert "unrecognized arguments" not in err
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(["daemon", "--config", missing, "--log-level", "loud"])
    assert exc.value.code == 2
    assert "invalid choice: 'LOUD'" in capsys.readouterr().err
