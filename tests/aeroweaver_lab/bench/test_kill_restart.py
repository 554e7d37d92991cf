"""``bench kill-restart`` in small: daemons SIGKILLed between rounds and started again from
their configs rejoin the running swarm, every run completes, and no acknowledged record is
lost (the benchmark does >= 200 cycles; docs/reliability.md)."""

from __future__ import annotations

import pytest

from aeroweaver_lab.bench import kill_restart

pytestmark = pytest.mark.slow


def test_killed_daemons_rejoin_and_nothing_is_lost() -> None:
    out = kill_restart.run(3, uavs=4, episodes=3, kill_p=0.5, seed=5)
    assert out["cycles"] == 3
    assert out["failed_runs"] == []
    assert out["completed_runs"] == out["runs"]
    assert out["rejoins_measured"] == 3  # every restarted process caught up and decided again
    assert len(out["restart_to_first_round_s"]) == 3
    assert out["records_checked"] > 0
    assert (out["records_lost"], out["lost"], out["check_problems"]) == (0, [], 0)
