"""Faults a swarm must survive: an LLM endpoint that hangs, a mid-mission reassignment,
and an operator stop."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm
from aeroweaver_edge.sim.runner import RoundLog
from commander.commander import Commander
from commander.harness import plan_for_task
from commander.plan import MissionPlan, UavAssignment
from commander.progress import ProgressBoard


async def test_hanging_endpoint_holds_every_uav_inside_the_round_and_opens_the_breaker() -> None:
    rounds = 5
    async with FakeProvider(Policy(hang=True)) as fake:
        llm = LLMConfig(
            # 2 s: long enough for every request to reach the server on a loaded machine
            # (the exact count below is taken there), short enough for a quick test.
            base_url=fake.base_url, model="fake-model", deadline_s=2.0, retries=0,
            breaker_failures=2, breaker_reset_s=60.0,
        )  # fmt: skip
        opts = SwarmOptions(uavs=3, seed=2, max_rounds=rounds, selector="llm", beta=0.0, llm=llm)
        summary = await run_swarm(opts)
        requests = len(fake.chat_bodies())  # every request that reached it (none answered)

    assert summary.episodes[0]["rounds"] == rounds
    assert summary.holds == 3 * rounds  # every decision became a hold of that UAV only
    assert summary.holds_by_cause["llm_failure"] == 3 * rounds  # ...because the LLM failed
    assert summary.deadline_misses == 0  # ...inside the round: the world never waited it out
    # The run's probe, then per daemon its probe (failure 1) and one round's request
    # (failure 2: the breaker opens and stays open). Fewer means a daemon never asked the
    # endpoint (an always-hold selector); more means the breaker did not stop the calls.
    assert summary.llm_calls == 3
    assert requests == 1 + 3 * 2


async def test_a_reassignment_mid_mission_is_picked_up_by_the_running_daemons() -> None:
    commander: list[Commander] = []
    switched = False

    async def watch(log: RoundLog, board: ProgressBoard) -> None:
        nonlocal switched
        if log.round == 2 and not switched:
            switched = True
            base = plan_for_task("coverage", ["uav0", "uav1", "uav2"], mission_id="coverage-s4")
            hold_only = UavAssignment("observer", "Hold.", ("hold_position",))
            plan = MissionPlan(
                mission_id=base.mission_id,
                task="coverage",
                text="Hold where you are.",
                assignments=dict.fromkeys(base.assignments, hold_only),
            )
            commander[0].publish(plan)

    opts = SwarmOptions(uavs=3, seed=4, max_rounds=8, selector="scripted", beta=0.0)
    summary = await run_swarm(opts, on_round=watch, on_commander=commander.append)
    board = commander[0].board

    assert summary.episodes[0]["rounds"] == 8
    # Each UAV shared records of two roles; the barrier still opened without its bound.
    barrier = summary.experience_barrier
    assert (barrier["confirmed"], barrier["timeouts"]) == (1, 0), barrier
    for uav in ("uav0", "uav1", "uav2"):
        last = board.uavs[uav].last
        assert last is not None
        assert (last.role, last.invocation) == ("observer", "hold_position()")
        assert board.ready[uav] == "observer"  # the daemon acknowledged its rebuilt context


def test_operator_stop_ends_the_run_cleanly(tmp_path: os.PathLike[str]) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "aeroweaver_edge", "sim", "coverage", "--selector", "scripted",
         "--episodes", "200"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    try:
        # Into the episodes (a round flown), whatever the machine's load: not a fixed sleep.
        assert proc.stdout is not None
        deadline = time.monotonic() + 120.0
        for line in proc.stdout:
            if line.startswith("ep ") and " round " in line:
                break
            assert time.monotonic() < deadline, "no round within the bound"
        else:
            raise AssertionError(f"the run ended before any round: {proc.wait()}")
        proc.send_signal(signal.SIGINT)
        _out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err[-2000:]
    assert "every UAV was told to hold" in err
