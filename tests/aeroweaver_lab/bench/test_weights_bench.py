"""``aeroweaver bench weights``: arguments, label parsing, and one short real run.

The real run records round prompts from two simulated rounds (against the fake provider),
then times two formats on a short prompt and compares their first-token label log-probs on
those prompts: structure only, never specific figures (they depend on the machine's load).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from aeroweaver_edge.cli.main import main as cli_main
from aeroweaver_lab.bench import weights as bench


def test_option_labels_and_label_logprobs() -> None:
    body = {
        "messages": [
            {"role": "system", "content": "A. not an option here\nrules"},
            {"role": "user", "content": "## Options\nA. go()\nB. hold_position()\nAnswer (A-B):"},
        ]
    }
    assert bench.option_labels(body) == ["A", "B"]
    answer = {
        "choices": [
            {
                "logprobs": {
                    "content": [
                        {
                            "token": "B",
                            "top_logprobs": [
                                {"token": "B", "logprob": -0.2},
                                {"token": " A", "logprob": -1.5},
                                {"token": "C", "logprob": -2.0},  # not an option
                                {"token": "A", "logprob": -9999.0},  # a floor, later
                            ],
                        }
                    ]
                }
            }
        ]
    }
    assert bench.label_logprobs(answer, ["A", "B"]) == {"B": -0.2, "A": -1.5}
    assert bench.label_logprobs({"choices": []}, ["A"]) == {}


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--reps", "0"], "--reps"),
        (["--formats", "q5_k"], "--formats"),
        (["--threads", "two"], "--threads"),
    ],
)
def test_bad_arguments_are_one_line(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        bench.main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert message in err
    assert len(err.strip().splitlines()) == 1


def test_unreadable_prompts_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "prompts.jsonl"
    bad.write_text('{"messages": []}\nnot json\n')
    assert bench.main(["--prompts", str(bad), "--skip-speed"]) == 2
    err = capsys.readouterr().err
    assert "--prompts" in err
    assert "bench weights --record" in err
    assert len(err.strip().splitlines()) == 1
    assert bench.main(["--prompts", str(tmp_path / "missing.jsonl"), "--skip-speed"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


@pytest.mark.embedded
@pytest.mark.timeout(900)  # a conversion, four servers and a simulated episode under load
def test_record_then_time_and_compare(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    prompts = tmp_path / "prompts.jsonl"
    argv = ["--record", str(prompts), "--tasks", "coverage", "--rounds", "2"]
    assert bench.main(argv) == 0
    recorded = json.loads(capsys.readouterr().out)
    assert recorded["recorded"] == 6  # 3 UAVs x 2 rounds
    bodies = [json.loads(line) for line in prompts.read_text().splitlines()]
    assert all(len(bench.option_labels(b)) >= 2 for b in bodies)
    assert all(isinstance(b["id_slot"], int) for b in bodies)  # no probe request
    argv = ["--formats", "q4_1", "q4_0", "--threads", "1", "--lengths", "24", "--reps", "2"]
    assert bench.main([*argv, "--prompts", str(prompts), "--limit", "4"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    speed = [r for r in rows if "median" in r]
    assert {(r["format"], r["tokens"]) for r in speed} == {("q4_1", 24), ("q4_0", 24)}
    assert all(len(r["rates"]) == 2 and r["median"] > 0 and r["of_fp32_peak"] > 0 for r in speed)
    agree = {r["format"]: r for r in rows if "top1_agree" in r}
    assert agree["q4_1"]["top1_agree"] == 1.0
    assert agree["q4_1"]["max_abs_delta"] == 0.0
    assert agree["q4_0"]["prompts"] == 4
    assert 0.0 <= agree["q4_0"]["top1_agree"] <= 1.0


def test_the_cli_lists_it(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        cli_main(["bench", "--help"])
    assert "weights" in capsys.readouterr().out
