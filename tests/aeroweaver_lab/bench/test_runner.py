"""``aeroweaver bench run``: cells written with their traces, resumed, refused when the
directory holds another configuration; tables computed from the per-episode figures."""

from __future__ import annotations

import json
import statistics
from pathlib import Path
from typing import Any

import pytest

from aeroweaver_edge.cli.main import main
from aeroweaver_lab.bench.episodes import episode_metrics, read_trace
from aeroweaver_lab.bench.report import aggregate, markdown
from aeroweaver_lab.bench.runner import Cell, plan_cells

CONDS = ["aeroweaver", "centralized", "scripted"]


def quick(out: Path, *extra: str) -> int:
    return main(
        [
            "bench",
            "run",
            "--quick",
            "--tasks",
            "coverage",
            "--conditions",
            *CONDS,
            "--out",
            str(out),
            *extra,
        ]
    )


def test_plan_is_seed_major() -> None:
    cells = plan_cells(["a", "b"], ["x", "y"], [1, 2])
    first = [Cell("a", "x", 1), Cell("a", "y", 1), Cell("b", "x", 1), Cell("b", "y", 1)]
    assert cells[:4] == first
    assert len(cells) == 8


def test_quick_run_writes_cells_tables_and_resumes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "bench"
    assert quick(out, "--jobs", "2") == 0
    err = capsys.readouterr().err
    assert "3 cells, 0 already done, 3 to run, 2 at a time" in err
    assert "ETA" in err
    setup = json.loads((out / "setup" / "coverage.json").read_text())
    assert setup["setup_tokens"] > 0  # the LLM Commander's parse + roles calls, measured
    orders = {}
    for c in CONDS:
        data = json.loads((out / "runs" / "coverage" / c / "seed1.json").read_text())
        assert data["bench"]["complete"]
        assert data["bench"]["trace_check"] == []
        assert data["bench"]["llm_threads"] is None  # the fake provider: no embedded server
        assert data["bench"]["config"]["rounds"] == 2
        assert data["bench"]["config"]["option_order"] == "seeded"
        assert data["bench"]["setup_tokens"] == (setup["setup_tokens"] if c == "aeroweaver" else 0)
        trace = out / data["bench"]["trace"]
        assert trace.name == "seed1.trace.jsonl.gz"
        assert trace.is_file()
        assert not (out / "runs" / "coverage" / c / "seed1.trace.jsonl").exists()
        assert [e["rounds"] for e in data["episodes"]] == [2]
        assert episode_metrics(read_trace(trace)) == data["episodes"]  # recomputable
        lines = read_trace(trace)
        head = lines[0]
        assert head["option_order"] == "seeded"
        for row in lines:  # each pick is the option its letter names in the recorded order
            for uav, d in row.get("decisions", {}).items():
                if d.get("label") is not None and d.get("options"):
                    assert f"{d['label']}. {d['invocation']}" in d["options"]
                    skills = head["mission"]["assignments"][uav]["skills"]
                    listed = [o.split(". ", 1)[1].split("(")[0] for o in d["options"]]
                    assert listed == sorted(listed, key=skills.index)  # the plan's order
        orders[c] = head["mission"]["assignments"]["uav0"]["skills"]
    # the skills AeroWeaver and Centralized share are listed in the same relative order
    shared = [s for s in orders["centralized"] if s in orders["aeroweaver"]]
    assert shared == [s for s in orders["aeroweaver"] if s in shared]
    assert len(shared) >= 2
    rows = (out / "results.csv").read_text().splitlines()
    assert len(rows) == 1 + 3
    assert rows[0].startswith("task,condition,seed,episode,team_return")
    table = (out / "table.md").read_text()
    assert "| coverage |" in table
    assert "AeroWeaver / Centralized" in table
    assert (out / "returns.png").stat().st_size > 1000
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["sessions"][0]["cells_run"] == 3
    assert manifest["sessions"][0]["load_start"]
    assert manifest["sessions"][0]["llm_threads"] is None
    assert manifest["sessions"][0]["jobs"] == 2
    assert "kernel_flags" in manifest["sessions"][0]["machine"]["cpu"]  # which kernels ran

    # --report-only rebuilds every table and plot from the cells alone, byte for byte
    outputs = ["table.md", "results.csv", "summary.json", "returns.png", "tokens.png"]
    before = {name: (out / name).read_bytes() for name in outputs}
    for name in outputs:
        (out / name).unlink()
    assert main(["bench", "run", "--tasks", "coverage", "--out", str(out), "--report-only"]) == 0
    assert {name: (out / name).read_bytes() for name in outputs} == before
    capsys.readouterr()

    # resume: nothing to run; a damaged cell is run again, the others are kept
    cell = out / "runs" / "coverage" / "centralized" / "seed1.json"
    cell.write_text('{"bench": {"complete": tr')
    kept = (out / "runs" / "coverage" / "aeroweaver" / "seed1.json").read_text()
    assert quick(out) == 0
    assert "3 cells, 2 already done, 1 to run" in capsys.readouterr().err
    assert json.loads(cell.read_text())["bench"]["complete"] is True
    assert (out / "runs" / "coverage" / "aeroweaver" / "seed1.json").read_text() == kept

    # another configuration in the same directory: refused, nothing overwritten
    assert quick(out, "--rounds", "3") == 2
    err = capsys.readouterr().err
    assert "another configuration" in err
    assert err.count("\n") == 1
    assert (out / "runs" / "coverage" / "aeroweaver" / "seed1.json").read_text() == kept


def cell(task: str, cond: str, seed: int, returns: list[float], tokens: int) -> dict[str, Any]:
    eps = []
    for i, r in enumerate(returns):
        eps.append(
            {
                "episode": i,
                "team_return": r,
                "rounds": 2,
                "reason": "horizon",
                "decisions": 4,
                "holds": 1,
                "holds_by_cause": {"chosen": 1},
                "invalid": 0,
                "llm_calls": {"uavs": 4, "central": 0},
                "llm_calls_total": 4,
                "tokens": {
                    "uavs": {"prompt": tokens, "prompt_cached": 0, "completion": 0},
                    "central": {"prompt": 0, "prompt_cached": 0, "completion": 0},
                },
                "tokens_total": tokens,
                "latency_s": [0.1, 0.2, 0.3, 0.4],
            }
        )
    return {
        "bench": {"task": task, "condition": cond, "title": cond, "seed": seed},
        "episodes": eps,
        "summary": {"model": "m"},
    }


def test_tables_from_episode_figures() -> None:
    cells = [
        cell("coverage", "aeroweaver", 1, [-10.0], 100),
        cell("coverage", "aeroweaver", 2, [-14.0], 300),
        cell("coverage", "hmas2", 1, [-20.0], 1000),
        cell("coverage", "no_activation", 1, [-29.077], 100),
    ]
    stats = aggregate(cells)
    s = stats[("coverage", "aeroweaver")]
    assert s.returns == [-10.0, -14.0]
    assert s.sd == pytest.approx(statistics.stdev([-10, -14]))
    assert s.percentile(0.5) == 0.3
    assert s.uncached_per_call == 400 / 8
    md = markdown(stats, ["coverage"], ["aeroweaver", "hmas2", "no_activation"])
    # mean [95 % bootstrap interval]: two episodes resample to means of -14, -12 or -10
    assert "| coverage | -12.00 [-14.00, -10.00] (n=2) | -20.00 (n=1) | -29.08 (n=1) |" in md
    assert "| coverage | 0.20 | – |" in md  # tokens 200 / 1000; no centralized cell
    # Q on the episodes both ran (seed 1 only), with the paper's K_t: 1 + (-29.077 + 10) /
    # 17.077; the unpaired means (AeroWeaver's over seeds 1 and 2) would give 0.000
    assert "| coverage | -0.117 |" in md


def test_an_endpoint_that_does_not_answer_is_refused_before_any_cell(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "bench"
    args = ["bench", "run", "--tasks", "coverage", "--conditions", "aeroweaver", "--seeds", "1"]
    status = main([*args, "--llm", "http://127.0.0.1:9/v1", "--model", "m", "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1
    assert "did not answer the start-up probe [unreachable]" in err
    assert not list(out.rglob("*.json"))  # no cell, no session: nothing to mistake for a result


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--model", "m"], "--model is for an endpoint given with --llm URL"),
        (["--out", "/proc/aw-no-such-dir"], "cannot be created"),
    ],
)
def test_bench_flag_mistakes_are_one_line(
    argv: list[str], says: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["bench", "run", "--quick", *argv]) == 2
    err = capsys.readouterr().err
    assert says in err
    assert err.count("\n") == 1


async def test_a_cell_whose_decisions_failed_at_the_llm_is_not_a_result(tmp_path: Path) -> None:
    """The endpoint answers the probes, then fails every call: the cell is kept to read but
    not complete, so the table never counts it and a resume runs it again."""
    import argparse

    from aeroweaver_edge.config import LLMConfig
    from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
    from aeroweaver_lab.bench.conditions import CONDITIONS
    from aeroweaver_lab.bench.runner import CellUnusable, config_key, load_done, run_cell

    out = tmp_path / "bench"
    args = argparse.Namespace(out=str(out), episodes=1, rounds=3, deadline=None)
    c = Cell("coverage", "aeroweaver", 1)
    async with FakeProvider(Policy(status=500, status_after=4)) as fake:  # run's + 3 probes
        llm = LLMConfig(base_url=fake.base_url, model=fake.model, deadline_s=2.0, retries=0)
        key = config_key(3, 1, llm, "endpoint")
        with pytest.raises(CellUnusable, match=r"9 of 9 decisions held because the LLM call"):
            await run_cell(c, args, llm, key)
    data = json.loads(c.json_path(out).read_text())
    assert data["bench"]["complete"] is False
    assert "the endpoint was failing" in data["bench"]["unusable"]
    assert load_done(c.json_path(out), key, CONDITIONS["aeroweaver"]) is None


def test_report_only_on_a_directory_without_cells_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A mistyped --out used to get an empty table and exit 0 (and was created)."""
    missing = tmp_path / "no-such-run"
    assert main(["bench", "run", "--report-only", "--out", str(missing)]) == 2
    err = capsys.readouterr().err
    assert "not a benchmark directory" in err
    assert err.count("\n") == 1
    assert not missing.exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["bench", "run", "--report-only", "--out", str(empty)]) == 2
    err = capsys.readouterr().err
    assert "holds no finished cell" in err
    assert err.count("\n") == 1
    assert list(empty.iterdir()) == []


def test_a_task_or_condition_named_twice_is_one_cell_and_one_row(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    argv = ["bench", "--quick", "--tasks", "coverage", "simple_spread_v3", "Coverage"]
    assert main([*argv, "--conditions", "scripted", "scripted", "--out", str(out)]) == 0
    rows = (out / "results.csv").read_text().splitlines()
    assert len(rows) == 1 + 1
    table = (out / "table.md").read_text()
    tables = table.count("### ") - table.count("### Run time")  # the run time is prose
    assert table.count("| coverage |") == tables  # one row per table
    assert "| task | Scripted reference |" in table
    assert main(["bench", "run", "--report-only", "--out", str(out)]) == 0


def test_bench_without_a_benchmark_name_is_the_runner(tmp_path: Path) -> None:
    """The issue's form, ``aeroweaver bench --quick ...``, is ``aeroweaver bench run``."""
    out = tmp_path / "bench"
    argv = ["bench", "--quick", "--tasks", "coverage", "--conditions", "scripted"]
    assert main([*argv, "--out", str(out)]) == 0
    assert json.loads((out / "runs" / "coverage" / "scripted" / "seed1.json").read_text())


@pytest.mark.parametrize(
    ("quirk", "kind"),
    [
        ("unauthorized", "auth"),
        ("wrong_model", "not_found"),
        ("server_error", "server_error"),
        ("bad_json", "bad_response"),
        ("hang", "timeout"),
    ],
)
def test_an_endpoint_that_cannot_answer_is_named_before_any_cell(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], quirk: str, kind: str
) -> None:
    from aeroweaver_edge.llm.fake_provider import QUIRKS, FakeProvider

    out = tmp_path / "bench"
    model = "gpt-nonexistent" if quirk == "wrong_model" else "fake-model"
    argv = ["bench", "--model", model, "--llm-deadline", "0.5", "--tasks", "coverage"]
    argv += ["--conditions", "aeroweaver", "centralized", "--seeds", "1", "--out", str(out)]
    with FakeProvider(QUIRKS[quirk], model="fake-model").in_thread() as fake:
        status = main([*argv, "--llm", fake.base_url])
        chat_calls = fake.chat_calls
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1, err
    assert f"did not answer the start-up probe [{kind}]" in err
    assert chat_calls <= 4  # the probe (and its retries), never a cell's rounds
    assert not list(out.rglob("*.json"))


@pytest.mark.parametrize(
    ("jobs", "says"), [("0", "0 is out of range (1..256)"), ("two", "'two' is not a whole number")]
)
def test_a_bad_jobs_count_is_one_line(
    jobs: str, says: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["bench", "run", "--quick", "--jobs", jobs, "--out", str(tmp_path / "b")])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert f"argument --jobs: {says}" in err
    assert err.count("\n") == 1
    assert not (tmp_path / "b").exists()


def test_default_jobs_are_the_physical_cores_this_process_may_use() -> None:
    from aeroweaver_edge.llm.cpus import usable_cpus
    from aeroweaver_lab.bench.runner import physical_cores

    assert 1 <= physical_cores() <= usable_cpus()


def test_a_stopped_run_records_the_cells_it_finished_and_resumes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """SIGTERM mid-run: the session in manifest.json counts the cells that finished (also
    with two running at once), and the same command runs only the rest."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "bench"
    argv = [sys.executable, "-m", "aeroweaver_edge", "bench", "run", "--quick"]
    argv += ["--tasks", "coverage", "line_formation", "--jobs", "2", "--out", str(out)]
    proc = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True, env=dict(os.environ))
    try:
        deadline = time.monotonic() + 240
        while not list(out.glob("runs/*/*/seed1.json")) and time.monotonic() < deadline:
            time.sleep(0.2)
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        assert proc.stderr is not None
        proc.stderr.close()
    assert proc.returncode != 0
    done = [
        p for p in out.glob("runs/*/*/seed1.json") if json.loads(p.read_text())["bench"]["complete"]
    ]
    assert done
    session = json.loads((out / "manifest.json").read_text())["sessions"][-1]
    assert session["cells_run"] == len(done)
    assert session["jobs"] == 2
    assert not list(out.glob("runs/*/*/*.trace.jsonl"))  # every kept trace is archived
    # the same command runs only the rest
    assert main(argv[3:]) == 0
    err = capsys.readouterr().err
    assert f"14 cells, {len(done)} already done, {14 - len(done)} to run" in err


def test_report_only_with_seeds_reports_those_seeds_only(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A run still adding seeds publishes a table where every condition has the same ones."""
    out = tmp_path / "bench"
    argv = ["bench", "--quick", "--tasks", "coverage", "--conditions", "scripted"]
    assert main([*argv, "--seeds", "3", "--out", str(out)]) == 0

    def seeds_in_csv() -> list[str]:
        return [row.split(",")[2] for row in (out / "results.csv").read_text().splitlines()[1:]]

    report = ["bench", "run", "--report-only", "--out", str(out)]
    assert main([*report, "--seeds", "2"]) == 0
    assert seeds_in_csv() == ["1", "2"]
    assert "(n=2)" in (out / "table.md").read_text()
    assert main([*report, "--first-seed", "2", "--seeds", "1"]) == 0
    assert seeds_in_csv() == ["2"]
    assert main(report) == 0  # no seed named: every finished seed
    assert seeds_in_csv() == ["1", "2", "3"]
    capsys.readouterr()
    assert main([*report, "--first-seed", "7"]) == 2
    err = capsys.readouterr().err
    assert "no finished cell of seeds 7..9" in err
    assert err.count("\n") == 1
