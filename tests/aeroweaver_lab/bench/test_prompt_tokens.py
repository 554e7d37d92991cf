"""``python -m aeroweaver_lab.bench.prompt_tokens``: the offline uncached-token count.

The real run flies three coverage rounds against the fake provider and counts them with the
embedded model's template and tokenizer: structure and the counting rule, not figures.
"""

from __future__ import annotations

import json
from typing import Any

import pytest

from aeroweaver_edge.llm.embedded import EmbeddedServer
from aeroweaver_lab.bench import prompt_tokens as bench


@pytest.mark.parametrize("argv", [["--rounds", "0"], ["--tasks", "nope"], ["--seed", "x"]])
def test_bad_arguments_are_one_line(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        bench.main(argv)
    assert exit_info.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


@pytest.mark.embedded
@pytest.mark.timeout(600)
def test_a_short_coverage_flight_is_counted_as_the_slot_cache_does(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert bench.main(["--tasks", "coverage", "--rounds", "3"]) == 0
    (row,) = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert row["task"] == "coverage"
    assert (row["uavs"], row["decisions"]) == (3, 9)  # 3 UAVs x 3 rounds, no probe request
    assert 0 < row["uncached_per_decision"] < 400  # a round's text, not a whole prompt

    system = {"role": "system", "content": "You decide. " * 20}
    first = {"role": "user", "content": "You are UAV uav0.\n## Options\nA. a()\nB. b()\nyou 0,0"}
    grown = {**first, "content": first["content"] + "\nlandmark: L0 5 N"}
    bodies: list[dict[str, Any]] = [
        {"id_slot": 0, "messages": [system, first]},
        {"id_slot": 1, "messages": [system, first]},
        {"id_slot": 0, "messages": [system, grown]},
    ]
    with EmbeddedServer(threads=1) as server:
        counter = bench.Counter(server)
        try:
            whole = len(counter.tokens(bodies[0]["messages"]))
            counts = counter.uncached(bodies)
        finally:
            counter.close()
    # Each slot's first prompt: only what follows "You are UAV uav0." is new; the grown
    # prompt in slot 0: only its new line (and the template's closing turn) is.
    assert counts[0] == counts[1]
    assert 0 < counts[0] < whole - 20
    assert 0 < counts[2] < counts[0]
