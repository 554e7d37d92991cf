"""``aeroweaver sim --estimator``: the daemons (in-process and --processes) use the named
estimator, and a bad name is one line, exit 2, nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from aeroweaver_edge.agent.estimators import ENV_ESTIMATOR
from aeroweaver_edge.cli.main import main


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


def first_gaps(trace: Path) -> dict[str, float]:
    """Per UAV, at its first decision: base score of hold_position minus the best other's."""
    out: dict[str, float] = {}
    for line in trace.read_text().splitlines():
        row = json.loads(line)
        if row.get("type") != "round":
            continue
        for uav, d in row["decisions"].items():
            labels = {o.split(". ", 1)[1].split("(")[0]: o.split(".")[0] for o in d["options"]}
            if uav in out or "hold_position" not in labels or len(labels) < 2:
                continue
            hold = d["base"][labels.pop("hold_position")]
            out[uav] = hold - max(d["base"][lb] for lb in labels.values())
    return out


def test_base_and_estimator_reach_the_daemons_selector(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    """In-process: ``--base`` changes the daemons' base scores by exactly the hold bias, the
    daemons say what they decide with, and the summary names the base."""
    monkeypatch.delenv(ENV_ESTIMATOR, raising=False)
    monkeypatch.delenv("AEROWEAVER_SCRIPTED_BASE", raising=False)
    caplog.set_level("INFO", logger="aeroweaver_edge.daemon.app")
    out = tmp_path / "hb.json"
    sim(tmp_path, "hb", "--base", "hold-biased", "--estimator", "horizon:2", "--json", str(out))
    assert json.loads(out.read_text())["selector"] == "scripted:hold-biased"
    said = [r.getMessage() for r in caplog.records if " decides with " in r.getMessage()]
    assert said
    want = "decides with scripted:hold-biased; experience correction beta 0.8, estimator horizon:2"
    assert all(m.endswith(want) for m in said), said
    sim(tmp_path, "ref")
    ref, hb = first_gaps(tmp_path / "ref.jsonl"), first_gaps(tmp_path / "hb.jsonl")
    assert ref
    assert ref.keys() == hb.keys()
    for uav in ref:
        assert hb[uav] - ref[uav] == pytest.approx(3.0)  # HOLD_BIAS, at the same first state
    capsys.readouterr()


def test_flag_beats_environment_in_process_and_in_processes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv(ENV_ESTIMATOR, "paper")
    paper = sim(tmp_path, "paper")
    monkeypatch.setenv(ENV_ESTIMATOR, "horizon:2")
    from_env = sim(tmp_path, "env")  # no flag: the environment's
    assert from_env != paper
    assert sim(tmp_path, "flag", "--estimator", "paper") == paper  # the flag wins
    # a spawned daemon gets the run's resolved config, not the parent's variable
    assert sim(tmp_path, "flag-p", "--estimator", "paper", "--processes") == paper
    capsys.readouterr()


def test_base_needs_the_scripted_selector(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run.json"
    assert main(["sim", "--base", "hold-biased", "--quiet", "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "--selector scripted" in err
    assert not out.exists()


def test_the_configuration_doc_command(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """docs/configuration.md's command, verbatim (continuation lines joined)."""
    import shlex

    doc = (Path(__file__).parents[3] / "docs" / "configuration.md").read_text(encoding="utf-8")
    block = doc.split("```bash\n", 1)[1].split("```", 1)[0]
    argv = shlex.split(block.replace("\\\n", " "))
    assert argv[:2] == ["aeroweaver", "sim"]
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv(ENV_ESTIMATOR, raising=False)
    monkeypatch.delenv("AEROWEAVER_SCRIPTED_BASE", raising=False)
    assert main(argv[1:]) == 0
    assert json.loads((tmp_path / "run.json").read_text())["selector"] == "scripted:hold-biased"
    capsys.readouterr()
