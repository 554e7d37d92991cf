"""Every benchmark's entry point at tiny sizes: it runs, and what it prints parses into the
figures its docstring promises (values are the machine's: only their shape is checked)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from aeroweaver_edge.cli import main as cli
from aeroweaver_edge.llm.embedded import EmbeddedServer, EmbeddedUnavailable
from aeroweaver_lab.bench import (
    adaptation,
    adaptation_why,
    kill_restart,
    llm_latency,
    mavlink,
    scale,
    security,
    world_speed,
)


def json_lines(text: str) -> list[dict[str, Any]]:
    return [json.loads(line) for line in text.splitlines() if line.startswith("{")]


def positive(x: object) -> bool:
    return isinstance(x, int | float) and math.isfinite(x) and x > 0


def test_world_speed_prints_per_call_microseconds(capsys: pytest.CaptureFixture[str]) -> None:
    assert world_speed.main(["--calls", "3", "--batches", "2", "--uavs", "2"]) == 0
    [row] = json_lines(capsys.readouterr().out)
    assert (row["bench"], row["task"], row["uavs"]) == ("world_speed", "coverage", 2)
    for key in ("world_step_us", "reward_eval_us", "complete_us", "sense_us"):
        assert positive(row[key]), key
    assert row["ticks_per_step"] == 10  # 0.5 s rounds of 0.05 s ticks


def test_reference_prints_one_line_per_run_and_a_table(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert (
        cli.main(["bench", "reference", "--tasks", "private_communication", "--seeds", "1", "2"])
        == 0
    )
    out = capsys.readouterr().out
    rows = json_lines(out)
    assert [(r["task"], r["seed"], r["rounds"], r["end"]) for r in rows] == [
        ("private_communication", 1, 3, "complete"),
        ("private_communication", 2, 3, "complete"),
    ]
    mean = sum(r["team_return"] for r in rows) / 2
    [line] = [ln for ln in out.splitlines() if ln.startswith("| private_communication |")]
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[1] == "2"  # UAVs
    assert float(cells[2].split("±")[0]) == pytest.approx(mean, abs=5e-4)
    assert (cells[3], cells[4]) == ("3.0", "2/2")


def test_scale_prints_a_line_per_size(capsys: pytest.CaptureFixture[str]) -> None:
    assert scale.main(["--sizes", "2", "3", "--rounds", "2", "--in-process"]) == 0
    rows = json_lines(capsys.readouterr().out)
    assert [(r["uavs"], r["rounds"], r["mode"]) for r in rows] == [
        (2, 2, "in-process"),
        (3, 2, "in-process"),
    ]
    for r in rows:
        assert r["peak_rss_mb"] is None  # only measured with one process per daemon
        assert set(r["round_wall_s"]) == {"p50", "p95"}
        assert set(r["decision_s"]) == {"p50", "p95"}
        assert r["deadline_misses"] == 0
        assert r["broadcasts_per_round"] >= 0


@pytest.mark.slow
def test_scale_measures_each_daemon_process(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["bench", "scale", "--sizes", "2", "--rounds", "2"]) == 0
    [row] = json_lines(capsys.readouterr().out)
    assert row["mode"] == "processes"
    assert positive(row["peak_rss_mb"]["max"])
    assert row["peak_rss_mb"]["mean"] <= row["peak_rss_mb"]["max"]


@pytest.mark.slow
def test_kill_restart_kills_one_daemon_and_it_rejoins_with_nothing_lost(
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = ["--cycles", "1", "--uavs", "2", "--episodes", "2", "--kill-p", "1.0", "--seed", "0"]
    assert kill_restart.main(argv) == 0
    [row] = json_lines(capsys.readouterr().out)
    assert (row["cycles"], row["runs"], row["completed_runs"], row["failed_runs"]) == (1, 1, 1, [])
    assert (row["records_lost"], row["lost"], row["check_problems"]) == (0, [], 0)
    assert row["records_checked"] > 0
    assert (row["world_rejoins"], row["rejoins_measured"]) == (1, 1)
    assert positive(row["restart_to_rejoin_s"]["p50"])
    assert row["restart_to_first_round_s"]["p50"] >= row["restart_to_rejoin_s"]["p50"]


def test_adaptation_writes_json_csv_table_and_plot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "adapt"
    argv = ["--episodes", "2", "--uavs", "2", "--betas", "0.8", "0", "--selector", "scripted"]
    assert adaptation.main([*argv, "--out", str(out)]) == 0
    data = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert [(r["task"], r["seed"], r["variant"]) for r in data["runs"]] == [
        ("coverage", 1, "beta=0.8"),
        ("coverage", 1, "beta=0"),
    ]
    for r in data["runs"]:
        assert [e["episode"] for e in r["episodes"]] == [0, 1]
        assert [e["tokens"] for e in r["episodes"]] == [0, 0]  # scripted: no LLM
    csv_rows = (out / "results.csv").read_text(encoding="utf-8").splitlines()
    assert csv_rows[0].startswith("task,seed,variant,episode,team_return,rounds,reason,")
    assert len(csv_rows) == 1 + 2 * 2
    table = (out / "table.md").read_text(encoding="utf-8")
    assert table in capsys.readouterr().out
    assert f"Command: `python -m aeroweaver_lab.bench.adaptation {' '.join(argv)}" in table
    assert (out / "team_return.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the figures read back from the traces it kept
    assert adaptation_why.main([str(out)]) == 0
    why = (out / "why.md").read_text(encoding="utf-8")
    assert why in capsys.readouterr().out
    rows = {r["variant"]: r for r in json.loads((out / "why.json").read_text(encoding="utf-8"))}
    assert set(rows) == {"beta=0.8", "beta=0"}
    assert rows["beta=0"]["corrected"] == 0  # no correction without beta
    assert rows["beta=0"]["correction_push_median"] == 0
    assert all(r["decisions"] > 0 and r["task"] == "coverage" for r in rows.values())
    assert adaptation_why.main([str(tmp_path)]) == 2  # no runs there
    assert capsys.readouterr().err == f"no adaptation runs under {tmp_path}/runs\n"


def test_security_prints_every_figure(capsys: pytest.CaptureFixture[str]) -> None:
    assert security.main(["--rtt", "3", "--opens", "1", "--crypto", "3"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) == {"pki", "open", "rtt", "crypto", "per_round"}
    assert set(data["rtt"]) == set(security.MODES)
    assert set(data["open"]) == set(security.MODES)
    assert all(
        positive(v["median_us"]) and v["p95_us"] >= v["median_us"] for v in data["rtt"].values()
    )
    assert all(positive(v["median_ms"]) for v in data["open"].values())
    assert [r["uavs"] for r in data["per_round"]] == [3, 10]


def test_mavlink_bench_writes_its_figures(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "mav.json"
    assert mavlink.main(["--seconds", "0.5", "--commands", "3", "--json", str(path)]) == 0
    out = capsys.readouterr().out
    data = json.loads(path.read_text(encoding="utf-8"))
    assert data["command_rtt_ms"]["n"] == 3
    assert f"n={data['command_rtt_ms']['n']}" in out
    assert positive(data["setpoints"]["received_hz"])
    assert mavlink.main(["--rate", "5"]) == 2
    assert "need 10 <= --rate <= 100" in capsys.readouterr().err


def test_llm_latency_without_the_model_is_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def absent(*_args: object, **_kw: object) -> None:
        raise EmbeddedUnavailable("no model here")

    monkeypatch.setattr(EmbeddedServer, "__aenter__", absent)
    assert llm_latency.main(["--rounds", "1"]) == 2
    assert capsys.readouterr().err == "embedded model unavailable: no model here\n"


def test_llm_latency_rejects_a_bad_shape_and_ranks_percentiles(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The timed part needs the model for ~10 s per request on a loaded CI machine, so it
    is run by hand (docs/performance.md); its arguments and arithmetic are checked here."""
    for argv in (["--uavs", "0"], ["--rounds", "0"], ["--history", "65"]):
        assert llm_latency.main(argv) == 2
        assert capsys.readouterr().err == (
            "llm_latency: --uavs and --rounds must be >= 1, --history 0..64\n"
        )
    xs = [5.0, 1.0, 4.0, 2.0, 3.0]
    assert [llm_latency.percentile(xs, q) for q in (0, 20, 50, 95, 100)] == [
        1.0,
        1.0,
        3.0,
        5.0,
        5.0,
    ]
