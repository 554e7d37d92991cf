"""User errors of ``console``, ``approve``, ``mcp`` and ``sim --console``: exit 2, one line
naming the cause, no traceback, nothing started (the real console script, all at once)."""

from __future__ import annotations

import socket
import subprocess
from pathlib import Path

import pytest

from tests.aeroweaver_edge.cli.test_main import aeroweaver


def cases(tmp: Path, busy: int) -> dict[str, tuple[tuple[str, ...], tuple[str, ...]]]:
    (tmp / "bad.jsonl").write_text('{"type": "round"}\n')
    (tmp / "empty.jsonl").write_text("")
    (tmp / "nomesh.toml").write_text('uav = "uav0"\n')
    header = '{"type": "run", "version": 1, "task": "coverage", "roles": {}}\n'
    (tmp / "norounds.jsonl").write_text(header)
    (tmp / "garbled.jsonl").write_text(header + "{not json\n")
    return {
        "missing trace": (("console", "--replay", str(tmp / "nope.jsonl")), ("cannot read",)),
        "not a trace": (("console", "--replay", str(tmp / "bad.jsonl")), ("first line must be",)),
        "empty trace": (("console", "--replay", str(tmp / "empty.jsonl")), ("empty",)),
        "no rounds": (("console", "--replay", str(tmp / "norounds.jsonl")), ("no rounds",)),
        "garbled": (("console", "--replay", str(tmp / "garbled.jsonl")), (":2: not JSON",)),
        "replay plus mesh": (
            ("console", "--replay", str(tmp / "bad.jsonl"), "--connect", "tcp/127.0.0.1:7447"),
            ("--replay plays a file",),
        ),
        "busy port": (
            ("console", "--port", str(busy), "--connect", "tcp/127.0.0.1:1"),
            (f"127.0.0.1:{busy}", "--port"),
        ),
        "no [mesh]": (("console", "--mesh-config", str(tmp / "nomesh.toml")), ("no [mesh] table",)),
        "bad endpoint": (("console", "--connect", "127.0.0.1:7447"), ("not a Zenoh endpoint",)),
        "unknown action": (
            ("approve", "--uav", "uav0", "--action", "arm"),
            ("unknown vehicle action 'arm'",),
        ),
        "ttl": (("approve", "--uav", "uav0", "--action", "land", "--ttl", "0"), ("--ttl 0",)),
        "no keys": (("mcp", "--keys", str(tmp / "nokeys")), ("--keys", "keys init")),
        "pace": (("sim", "--selector", "scripted", "--pace", "100"), ("--pace", "<= 60")),
    }


@pytest.fixture(scope="module")
def results(
    tmp_path_factory: pytest.TempPathFactory,
) -> dict[str, tuple[tuple[str, ...], subprocess.CompletedProcess[str]]]:
    tmp = tmp_path_factory.mktemp("cli")
    with socket.socket() as blocker:
        blocker.bind(("127.0.0.1", 0))
        blocker.listen(1)
        busy = blocker.getsockname()[1]
        procs = {
            name: (needles, subprocess.Popen(
                [*aeroweaver(), *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                cwd=tmp,
            ))
            for name, (argv, needles) in cases(tmp, busy).items()
        }  # fmt: skip
        out = {}
        for name, (needles, p) in procs.items():
            stdout, stderr = p.communicate(timeout=90)
            out[name] = (needles, subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr))
    return out


@pytest.mark.parametrize(
    "name",
    ["missing trace", "not a trace", "empty trace", "no rounds", "garbled", "replay plus mesh",
     "busy port", "no [mesh]", "bad endpoint", "unknown action", "ttl", "no keys", "pace"],
)  # fmt: skip
def test_user_error_is_one_line_exit_2(
    results: dict[str, tuple[tuple[str, ...], subprocess.CompletedProcess[str]]], name: str
) -> None:
    needles, proc = results[name]
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert lines[0].startswith("aeroweaver: ")
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert proc.stdout == ""


def test_sim_with_the_console_prints_its_url_and_finishes(tmp_path: Path) -> None:
    trace = tmp_path / "run.jsonl"
    proc = subprocess.run(
        [*aeroweaver(), "sim", "coverage", "--selector", "scripted", "--console",
         "--console-port", "0", "--rounds", "3", "--pace", "0", "--quiet", "--trace", str(trace)],
        capture_output=True, text=True, timeout=120, cwd=tmp_path, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    first = proc.stdout.splitlines()[0]
    assert first.startswith("console: http://127.0.0.1:")
    assert not first.endswith(":0/")  # the port it really got
    assert trace.exists()
