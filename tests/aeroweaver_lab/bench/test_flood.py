"""The flood benchmark at tiny scale (the figures come from ``aeroweaver bench flood``):
it runs, and every flood leaves the mission whole (same returns, every process alive with
exit code 0, the attacker's stored experience bounded). No wall-time assertion: that is
what the benchmark reports, on a machine quiet enough to mean something."""

from __future__ import annotations

import pytest

from aeroweaver_edge.agent.memory.experience import MAX_RECORDS_PER_SENDER
from aeroweaver_lab.bench.flood import ATTACKS, bench


async def test_every_flood_leaves_the_mission_whole() -> None:
    out = await bench(uavs=3, rounds=4, seed=1, task="coverage", attacks=ATTACKS, rate=800.0,
                      records=600, max_ratio=100.0)  # fmt: skip
    runs = out["runs"]
    assert [r["attack"] for r in runs] == ["untouched", *ATTACKS, "untouched"]
    assert out["untouched_same_returns"]
    for row in runs:
        assert row["completed"], row.get("error")
        assert row["alive"], row
        assert set(row["exit_codes"].values()) == {0}
        assert row["lost_uavs"] == {}
    for row in runs[1:-1]:
        assert row["same_returns"], row["attack"]
        assert row["attacker"]["sent"] > 0, row["attack"]
        assert row["attacker"]["exit_code"] == 0
        assert row["wall_ratio"] > 0
        for stored in row["stored_by_sender"].values():
            assert stored.get("uav3", 0) <= MAX_RECORDS_PER_SENDER
    by_attack = {r["attack"]: r for r in runs}
    assert by_attack["unsigned"]["refused"].get("unsigned", 0) > 0  # the flood reached them
    assert (
        by_attack["random_sig"]["refused"].get("bad_signature", 0)
        + by_attack["random_sig"]["refused"].get("over_budget", 0)
        + by_attack["random_sig"]["refused"].get("no_own_position", 0)
        > 0
    )


def test_the_cli_runs_the_flood_benchmark_with_its_options(monkeypatch: pytest.MonkeyPatch) -> None:
    """``aeroweaver bench flood --rounds 48`` (docs/security.md) is this module's main."""
    from aeroweaver_edge.cli import main as cli
    from aeroweaver_lab.bench import flood

    seen: list[list[str]] = []
    monkeypatch.setattr(flood, "main", lambda argv: seen.append(list(argv)) or 0)
    assert cli.main(["bench", "flood", "--rounds", "48"]) == 0
    assert seen == [["--uavs", "3", "--rounds", "48", "--seed", "1", "--task", "coverage"]]
