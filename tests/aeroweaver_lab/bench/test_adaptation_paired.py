"""``aeroweaver bench adaptation`` paired mode at tiny scale: beta = 0 against beta = 0.8 on
the same seed sequences, the summary JSON, curves, resumption, and one-line refusals."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from aeroweaver_edge.cli.main import main as cli
from aeroweaver_lab.bench import adaptation_why

TASKS = ["coverage", "line_formation"]


def test_tiny_paired_run_summary_curves_and_resume(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "hb.json"
    argv = [
        "bench", "adaptation", "--base", "hold-biased", "--estimator", "horizon:2,support:2",
        "--tasks", *TASKS, "--sequences", "2", "--episodes", "2", "--rounds", "4",
        "--json", str(out),
    ]  # fmt: skip
    assert cli(argv) == 0
    err = capsys.readouterr().err
    assert "[8/8] line_formation seq 1 beta=0.8" in err  # a progress line per cell
    data = json.loads(out.read_text())
    assert data["base"] == "hold-biased"
    assert data["estimator"] == "horizon:2,support:2"
    assert data["seeds"] == [1, 1001]
    assert set(data["tasks"]) == set(TASKS)
    runs = tmp_path / "hb-runs" / "runs" / "hold-biased"
    for task, t in data["tasks"].items():
        assert set(t) >= {"mean_diff", "ci95", "better", "worse", "equal", "p_wilcoxon"}
        assert t["better"] + t["worse"] + t["equal"] == 2
        lo, hi = t["ci95"]
        assert lo <= t["mean_diff"] <= hi
        assert 0.0 <= t["p_wilcoxon"] <= 1.0
        # mean_diff recomputed from the cells' own per-episode returns
        diffs = []
        for s in range(2):
            cells = {
                name: json.loads((runs / task / f"seq{s}" / name / "result.json").read_text())
                for name in ("b0", "b0.8-horizon2-support2")
            }
            means = {k: sum(e["team_return"] for e in c["episodes"]) / 2 for k, c in cells.items()}
            assert cells["b0"]["seed"] == 1 + 1000 * s
            assert all(e["rounds"] == 4 for c in cells.values() for e in c["episodes"])
            diffs.append(means["b0.8-horizon2-support2"] - means["b0"])
        assert t["mean_diff"] == pytest.approx(sum(diffs) / 2)
    for p in data["curves"]:
        assert Path(p).read_bytes()[:4] == b"\x89PNG"
    assert adaptation_why.main([str(tmp_path / "hb-runs")]) == 0  # the "why" of paired cells
    why = (tmp_path / "hb-runs" / "why.md").read_text()
    assert "[hold-biased] beta=0.8 horizon:2,support:2" in why
    assert "[hold-biased] beta=0 |" in why
    # the hold-biased base really is degraded: it chooses holds the reference never does
    assert sum(sum(t["chosen_holds_per_sequence"]["beta0"]) for t in data["tasks"].values()) > 0

    stamp = (runs / "coverage" / "seq0" / "b0" / "result.json").stat().st_mtime_ns
    # another estimator on the same directory reuses the beta = 0 cells
    argv2 = [*argv[:5], "paper", *argv[6:-1], str(tmp_path / "hb-paper.json")]
    argv2 += ["--out", str(tmp_path / "hb-runs")]
    assert cli(argv2) == 0
    err = capsys.readouterr().err
    assert "beta=0:" not in err  # only the beta = 0.8 paper cells ran
    assert err.count("beta=0.8") == 4
    assert cli(argv) == 0  # resumed: nothing rerun
    assert "[" not in capsys.readouterr().err
    assert (runs / "coverage" / "seq0" / "b0" / "result.json").stat().st_mtime_ns == stamp


def test_cells_run_side_by_side_give_the_same_summary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--jobs 2`` runs two cells at once (each its own swarm and memory): the same cells,
    so the same summary as one at a time."""
    summaries = []
    for jobs in ("1", "2"):
        out = tmp_path / f"j{jobs}.json"
        argv = [
            "bench", "adaptation", "--base", "hold-biased", "--estimator", "scale",
            "--tasks", *TASKS, "--sequences", "2", "--episodes", "2", "--rounds", "3",
            "--jobs", jobs, "--json", str(out),
        ]  # fmt: skip
        assert cli(argv) == 0
        assert capsys.readouterr().err.count("] ") == 8  # a progress line per cell
        summaries.append(json.loads(out.read_text())["tasks"])
    assert summaries[0] == summaries[1]


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--estimator", "horizon:0"], "horizon needs a whole number"),
        (["--base", "lazy"], "unknown scripted base 'lazy'"),
        (["--sequences", "0"], "expected a whole number >= 1"),
        (["--beta", "0"], "positive finite beta"),
        (["--seeds", "3"], "no --variants, --betas or --seeds"),
        (["--jobs", "0"], "expected a whole number >= 1"),
    ],
)
def test_bad_arguments_are_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], needle: str
) -> None:
    out = tmp_path / "x.json"
    argv = ["bench", "adaptation", "--tasks", "coverage", "--json", str(out), *args]
    with pytest.raises(SystemExit) as exit_:
        cli(argv)
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert needle in err
    assert len(err.strip().splitlines()) == 1
    assert "Traceback" not in err
    assert not out.exists()
    assert not (tmp_path / "x-runs").exists()


@pytest.mark.parametrize("flag", [["--estimator", "horizon:3"], ["--jobs", "2"]])
def test_legacy_flags_refuse_paired_only_options(
    capsys: pytest.CaptureFixture[str], flag: list[str]
) -> None:
    with pytest.raises(SystemExit) as exit_:
        cli(["bench", "adaptation", *flag])
    assert exit_.value.code == 2
    assert "paired mode" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("env", "value"), [("AEROWEAVER_ESTIMATOR", "bogus"), ("AEROWEAVER_SCRIPTED_BASE", "lazy")]
)
def test_a_bad_override_in_the_environment_is_one_line_exit_2(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    env: str, value: str,
) -> None:  # fmt: skip
    """The bench resolves flag > environment > default like ``aeroweaver sim``."""
    monkeypatch.setenv(env, value)
    out = tmp_path / "x.json"
    with pytest.raises(SystemExit) as exit_:
        cli(["bench", "adaptation", "--tasks", "coverage", "--json", str(out)])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert f"{env}:" in err
    assert repr(value) in err
    assert not out.exists()


async def test_a_cell_whose_decisions_failed_at_the_llm_stops_the_run(tmp_path: Path) -> None:
    """The endpoint answers the probes, then fails every call: the cell is kept to read but
    not complete (a rerun runs it again), and the run stops with one line instead of
    summarising hours of holds as adaptation evidence."""
    from aeroweaver_edge.config import LLMConfig
    from aeroweaver_edge.contracts.errors import RunFailed
    from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
    from aeroweaver_lab.bench.adaptation import Variant, _load, run_one

    run_dir = tmp_path / "cell"
    async with FakeProvider(Policy(status=500, status_after=4)) as fake:  # run's + 3 probes
        llm = LLMConfig(base_url=fake.base_url, model=fake.model, deadline_s=2.0, retries=0)
        with pytest.raises(RunFailed, match=r"9 of 9 decisions held because the LLM call"):
            await run_one(
                "coverage", 1, Variant(0.8), 1, None, "llm", llm, run_dir, False, 10.0,
                max_rounds=3,
            )  # fmt: skip
    data = json.loads((run_dir / "result.json").read_text())
    assert data["complete"] is False
    assert data["base"] == "llm"  # the model decided, not the scripted base
    assert "the endpoint was failing" in data["unusable"]
    assert _load(run_dir / "result.json") is None  # resumed runs do it again


@pytest.mark.parametrize("paired", [True, False])
def test_an_unreachable_endpoint_is_one_line_before_any_cell(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], paired: bool
) -> None:
    out = tmp_path / "x.json"
    argv = ["bench", "adaptation", "--llm", "http://127.0.0.1:9", "--episodes", "1"]
    if paired:
        argv += ["--base", "llm", "--sequences", "1", "--json", str(out)]
    else:
        argv += ["--out", str(tmp_path / "x-runs")]
    assert cli(argv) == 2
    err = capsys.readouterr().err
    assert "did not answer the start-up probe" in err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()
    assert not (tmp_path / "x-runs" / "runs").exists()
