"""Every user error of the ``aeroweaver`` command: exit 2, exactly one line on stderr
naming the cause (and the fix), no traceback, and no work started.

The real console script runs as a subprocess per case (stderr is what a user sees, logging
and all); all cases start at once so the file stays fast on two cores."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from aeroweaver_edge.config import MAX_UAVS
from tests.aeroweaver_edge.cli.test_main import aeroweaver


@dataclass(frozen=True)
class Case:
    argv: tuple[str, ...]
    needles: tuple[str, ...]  # substrings the one line must contain
    env: tuple[tuple[str, str], ...] = ()


def uav_toml(**sections: str) -> str:
    text = 'uav = "uav0"\n[agent]\nselector = "scripted"\n'
    for name, body in sections.items():
        text += f"[{name}]\n{body}\n" if name != "agent" else body + "\n"
    return text


def cases(tmp: Path, busy_port: int) -> dict[str, Case]:
    blocker = tmp / "a-regular-file"
    blocker.write_text("not a directory\n")
    (tmp / "latin1.toml").write_bytes(b'uav = "uav0"\n# caf\xe9 \xff\n')
    (tmp / "absurd.toml").write_text(
        uav_toml(safety="geofence_north_m = [-1e9, 1e9]\nmax_speed_mps = 1e6\nmin_separation_m = 0")
    )
    (tmp / "busy.toml").write_text(uav_toml(mesh=f'listen = ["tcp/127.0.0.1:{busy_port}"]'))
    (tmp / "memory.toml").write_text(uav_toml(agent=f'memory_path = "{blocker}/uav0.sqlite3"'))
    broken = tmp / "broken-skills" / "cover_it"
    broken.mkdir(parents=True)
    (broken / "skill.md").write_text("---\nname: Cover It\ndescription: [unclosed\n---\nbody\n")
    sim = ("sim", "--selector", "scripted", "--quiet")
    return {
        "uavs -1": Case((*sim, "--uavs", "-1"), ("--uavs", f"1..{MAX_UAVS}")),
        "uavs 0": Case((*sim, "--uavs", "0"), ("--uavs", "out of range")),
        "uavs 500": Case((*sim, "--uavs", "500"), ("--uavs", "500", f"1..{MAX_UAVS}")),
        "unknown task": Case(("sim", "herding", "--selector", "scripted"), ("herding", "coverage")),
        "rounds 0": Case((*sim, "--rounds", "0"), ("--rounds",)),
        "beta nan": Case((*sim, "--beta", "nan"), ("--beta", "finite")),
        "beta -1": Case((*sim, "--beta", "-1"), ("--beta", ">= 0")),
        "deadline 0": Case((*sim, "--deadline", "0"), ("--deadline", "> 0")),
        "episodes 0": Case((*sim, "--episodes", "0"), ("--episodes",)),
        "broken skill tree": Case(
            sim,
            ("broken skill package", "cover_it/skill.md", "AEROWEAVER_SKILLS_DIR"),
            (("AEROWEAVER_SKILLS_DIR", str(tmp / "broken-skills")),),
        ),
        "non-UTF-8 config": Case(
            ("daemon", "--config", str(tmp / "latin1.toml")), ("latin1.toml", "not UTF-8")
        ),
        "zenoh port in use": Case(
            ("daemon", "--config", str(tmp / "busy.toml")), (str(busy_port), "already in use")
        ),
        "bad listen endpoint": Case(
            ("mission", "start", "cover", "--no-llm", "--listen", "nonsense"),
            ("--listen", "nonsense", "not a Zenoh endpoint"),
        ),
        "bad namespace": Case(
            ("mission", "start", "cover", "--no-llm", "--namespace", "swarm/*"),
            ("mesh.namespace", "swarm/*"),
        ),
        "json unwritable": Case(
            (*sim, "--json", str(blocker / "summary.json")), ("--json", "not a directory")
        ),
        "memory-dir unwritable": Case(
            (*sim, "--memory-dir", str(blocker / "memory")), ("--memory-dir", "writable")
        ),
        "daemon memory unwritable": Case(
            ("daemon", "--config", str(tmp / "memory.toml")),
            ("agent.memory_path", "memory_required = false"),
        ),
        "absurd safety": Case(
            ("daemon", "--config", str(tmp / "absurd.toml")),
            ("safety.geofence_north_m", "safety.max_speed_mps", "safety.min_separation_m"),
        ),
        "unset api key variable": Case(
            ("sim", "--llm", "http://127.0.0.1:9/v1", "--api-key-env", "AW_TEST_UNSET_KEY"),
            ("AW_TEST_UNSET_KEY", "export"),
        ),
        "unreachable endpoint": Case(
            ("sim", "--llm", "http://127.0.0.1:9/v1", "--model", "m"),
            ("did not answer the start-up probe [unreachable]", "127.0.0.1:9"),
        ),
        "bench unreachable endpoint": Case(
            ("bench", "run", "--llm", "http://127.0.0.1:9/v1", "--model", "m"),
            ("did not answer the start-up probe [unreachable]", "127.0.0.1:9"),
        ),
        "probe unset api key variable": Case(
            ("probe", "--llm", "http://127.0.0.1:9/v1", "--api-key-env", "AW_TEST_UNSET_KEY"),
            ("AW_TEST_UNSET_KEY",),
        ),
        "memory stats missing dir": Case(
            ("memory", "stats", str(tmp / "no-such-dir")), ("does not exist",)
        ),
    }


@pytest.fixture(scope="module")
def results(
    tmp_path_factory: pytest.TempPathFactory,
) -> dict[str, tuple[Case, subprocess.CompletedProcess[str]]]:
    tmp = tmp_path_factory.mktemp("cli-errors")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        all_cases = cases(tmp, busy.getsockname()[1])
        env = {k: v for k, v in os.environ.items() if not k.startswith(("AEROWEAVER_", "AW_"))}
        procs = {
            name: subprocess.Popen(
                [*aeroweaver(), *case.argv],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                stdin=subprocess.DEVNULL,
                text=True,
                cwd=tmp,
                env={**env, **dict(case.env)},
            )
            for name, case in all_cases.items()
        }
        done = {}
        try:
            for name, proc in procs.items():
                out, err = proc.communicate(timeout=120)
                completed = subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
                done[name] = (all_cases[name], completed)
        finally:
            for proc in procs.values():
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
    return done


def _names() -> list[str]:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        return list(cases(Path(tmp), 1))


@pytest.mark.parametrize("name", _names())
def test_user_error_is_one_line_exit_2_no_traceback(
    results: dict[str, tuple[Case, subprocess.CompletedProcess[str]]], name: str
) -> None:
    case, proc = results[name]
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert lines[0].startswith("aeroweaver: ")
    for needle in case.needles:
        assert needle in lines[0], (needle, lines[0])
    assert ";" in lines[0]  # the cause, then what to do about it
    assert proc.stdout == ""  # nothing ran


def test_verbose_shows_the_traceback(tmp_path: Path) -> None:
    proc = subprocess.run(
        [*aeroweaver(), "-v", "memory", "check", str(tmp_path / "nope")],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 2
    assert "Traceback" in proc.stderr
    assert proc.stderr.rstrip().splitlines()[-1].startswith("aeroweaver: ")


def test_an_internal_error_is_one_line_exit_1(
    monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    from aeroweaver_edge.cli import main as cli

    def boom(_args: object) -> int:
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(cli, "cmd_memory", boom)
    assert cli.main(["memory", "stats", "x"]) == 1
    err = capfd.readouterr().err
    assert err == (
        "aeroweaver: internal error: ZeroDivisionError: a bug (run with -v for the traceback)\n"
    )


def test_json_summary_never_holds_nan(tmp_path: Path) -> None:
    from aeroweaver_edge.runtime.json_out import dumps, write_json_file

    path = tmp_path / "x" / "s.json"
    write_json_file(path, {"a": float("nan"), "b": [float("inf"), 1.5], "c": {"d": -float("inf")}})
    assert path.read_text() == dumps({"a": None, "b": [None, 1.5], "c": {"d": None}}) + "\n"
    assert "NaN" not in path.read_text()


if sys.platform != "linux":  # pragma: no cover
    pytestmark = pytest.mark.skip("subprocess CLI cases assume Linux paths")
