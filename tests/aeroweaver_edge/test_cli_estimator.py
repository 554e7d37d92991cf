"""``aeroweaver sim --estimator``: the daemons (in-process and --processes) use the named
estimator, and a bad name is one line, exit 2, nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from aeroweaver_edge.agent.estimators import ENV_ESTIMATOR
from aeroweaver_edge.cli import main


def advantages(trace: Path) -> list[dict[str, float]]:
    out = []
    for line in trace.read_text().splitlines():
        row = json.loads(line)
        if row.get("type") == "round":
            out += [d.get("advantage") or {} for _, d in sorted(row["decisions"].items())]
    return out


def sim(tmp_path: Path, name: str, *extra: str) -> list[dict[str, float]]:
    trace = tmp_path / f"{name}.jsonl"
    argv = ["sim", "coverage", "--selector", "scripted", "--episodes", "2", "--rounds", "6"]
    assert main([*argv, "--quiet", "--insecure", "--trace", str(trace), *extra]) == 0
    return advantages(trace)


def test_estimator_reaches_the_daemons(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv(ENV_ESTIMATOR, "paper")  # restored after the test
    paper = sim(tmp_path, "paper")
    assert paper == sim(tmp_path, "paper-again", "--estimator", "paper")  # the default
    horizon = sim(tmp_path, "h", "--estimator", "horizon:2")
    assert any(paper)
    assert any(horizon)
    assert paper != horizon
    assert horizon == sim(tmp_path, "hp", "--estimator", "horizon:2", "--processes")
    capsys.readouterr()


@pytest.mark.parametrize("bad", ["horizon", "horizon:0", "bayes", "support:x"])
def test_bad_estimator_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], bad: str
) -> None:
    out = tmp_path / "run.json"
    with pytest.raises(SystemExit) as exit_:
        main(["sim", "--selector", "scripted", "--estimator", bad, "--json", str(out)])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "estimator" in err
    assert repr(bad) in err
    assert not out.exists()


def test_bad_scripted_base_in_the_environment_is_one_line_exit_2(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("AEROWEAVER_SCRIPTED_BASE", "lazy")
    out = tmp_path / "run.json"
    assert main(["sim", "--selector", "scripted", "--quiet", "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "AEROWEAVER_SCRIPTED_BASE" in err
    assert "'lazy'" in err
    assert not out.exists()
