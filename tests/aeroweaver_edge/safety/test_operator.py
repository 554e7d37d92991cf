"""Operator actions over a real simulated swarm: a strict swarm stays on the ground until an
operator approves a take-off (over the mesh, acknowledged and recorded by the UAV itself),
``aeroweaver approve`` does the same from the command line, and the stop goes through the
Commander. Refusals (not an operator, the wrong mission) change nothing."""

from __future__ import annotations

import asyncio
import sys
from typing import Any

import pytest

from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.orchestration.swarm import RunSummary, SwarmHandle, SwarmOptions, run_swarm
from aeroweaver_edge.safety.operator import OperatorError, OperatorLink, StopPlan
from aeroweaver_edge.sim.runner import RoundLog
from commander.progress import ProgressBoard

pytestmark = pytest.mark.timeout(120)


async def wait_for(cond: Any, what: str, timeout_s: float = 20.0) -> None:
    """Poll a UAV's state over the mesh until ``cond`` holds (bounded; fails naming it)."""
    try:
        async with asyncio.timeout(timeout_s):
            while not await cond():  # noqa: ASYNC110 - remote state: no local event
                await asyncio.sleep(0.05)
    except TimeoutError:
        pytest.fail(f"timed out waiting for {what}")


async def test_strict_swarm_launches_only_what_an_operator_approved() -> None:
    started = asyncio.Event()
    box: dict[str, SwarmHandle] = {}
    held: list[dict[str, bool]] = []
    moved = asyncio.Event()

    async def on_started(h: SwarmHandle) -> None:
        box["h"] = h
        started.set()

    async def on_round(log: RoundLog, _board: ProgressBoard) -> None:
        row = {u: c.held for u, c in log.commands.items()}
        held.append(row)
        if row.get("uav0") is False:
            moved.set()

    opts = SwarmOptions(
        task="coverage", selector="scripted", max_rounds=400, pace_s=0.05, approval="strict",
        secure=False,  # the application's checks alone (secured: security/test_operator_secured)
    )  # fmt: skip
    run: asyncio.Task[RunSummary] = asyncio.create_task(
        run_swarm(opts, on_round=on_round, on_started=on_started)
    )
    try:
        await asyncio.wait_for(started.wait(), 60)
        h = box["h"]
        async with await Mesh.open(h.mesh_for("operator"), node_id="operator") as mesh:
            op = OperatorLink(mesh, h.swarm, person="tester")

            async def pending() -> bool:
                st = await op.approval_status("uav0")
                return st is not None and [p.action for p in st.pending] == ["takeoff"]

            await wait_for(pending, "uav0's take-off pending")
            st = await op.approval_status("uav1")
            assert st is not None
            assert st.level == "strict"
            assert [(p.action, p.skill) for p in st.pending] == [("takeoff", "")]  # the launch
            rounds_before = len(held)
            assert all(all(row.values()) for row in held[:rounds_before])  # all on the ground

            # not an operator: refused by the UAV, nothing flies
            rogue = OperatorLink(mesh, h.swarm, identity="uav9", person="mallory")
            rogue.headers.sender = "uav9"  # type: ignore[misc]
            with pytest.raises(OperatorError, match="'uav9' is not an approver"):
                await rogue.approve("uav1", "takeoff", 60)
            rec = await op.approve("uav0", "takeoff", 60)
            assert rec.state == "granted"
            assert rec.by == "tester"
            assert rec.sender == "operator"
            assert rec.expires - rec.received == pytest.approx(60)
            await asyncio.wait_for(moved.wait(), 20)

            async def used() -> bool:
                st = await op.approval_status("uav0")
                return st is not None and [r.state for r in st.records] == ["used"]

            await wait_for(used, "the approval used by the launch")
            plan = await op.plan_stop()
            assert plan == StopPlan("coverage-s1", "coverage", ("uav0", "uav1", "uav2"))
            with pytest.raises(OperatorError, match="did not end mission other"):
                await op.stop(StopPlan("other", "coverage", ()), timeout_s=1.0)
            assert not run.done()
            note = await op.stop(plan, "done watching")
            assert note == "ended: operator stop by tester: done watching"
        summary = await asyncio.wait_for(run, 30)
    finally:
        run.cancel()
    after = held[rounds_before:]
    assert any(row["uav0"] is False for row in after)  # uav0 flew once approved
    assert all(row["uav1"] and row["uav2"] for row in held)  # the others never launched
    assert summary.stopped == "operator stop by tester: done watching"
    assert summary.holds_by_cause is not None


async def test_approve_cli_reaches_a_uav_and_reports_refusals() -> None:
    started = asyncio.Event()
    box: dict[str, SwarmHandle] = {}

    async def on_started(h: SwarmHandle) -> None:
        box["h"] = h
        started.set()

    # strict: nobody launches unasked, so the mission cannot complete before the test ends
    opts = SwarmOptions(
        task="coverage", selector="scripted", max_rounds=400, pace_s=0.05, approval="strict",
        secure=False,  # the application's checks alone (secured: security/test_operator_secured)
    )  # fmt: skip
    run = asyncio.create_task(run_swarm(opts, on_started=on_started))
    try:
        await asyncio.wait_for(started.wait(), 60)
        cfg = box["h"].mesh_for("operator")
        flags = ["--swarm", box["h"].swarm, "--connect", cfg.connect[0],
                 "--namespace", str(cfg.namespace)]  # fmt: skip

        async def approve(*extra: str) -> tuple[int, str, str]:
            proc = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "aeroweaver_edge", "approve", *flags, *extra,
                stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
            )  # fmt: skip
            out, err = await asyncio.wait_for(proc.communicate(), 60)
            assert proc.returncode is not None
            return proc.returncode, out.decode(), err.decode()

        code, out, err = await approve("--uav", "uav1", "--action", "take_off", "--ttl", "90",
                                       "--by", "ana")  # fmt: skip
        assert code == 0, err
        assert out.startswith("uav1: takeoff approved by ana (id ")
        assert "valid for 90 s, recorded by the UAV" in out
        code, _out, err = await approve("--uav", "uav1", "--action", "land", "--mission", "m9")
        assert code == 2
        assert "uav1 refused the approval: for mission m9, flying coverage-s1" in err
        code, _out, err = await approve("--uav", "uav1", "--action", "arm")
        assert code == 2
        assert "unknown vehicle action 'arm'; choose takeoff, land or return_home" in err
        code, _out, err = await approve("--uav", "uav7", "--action", "land", "--wait", "1")
        assert code == 2
        assert "uav7 is not on the mesh (waited 1 s)" in err
        assert not run.done()
    finally:
        run.cancel()
        with pytest.raises(asyncio.CancelledError):
            await run
