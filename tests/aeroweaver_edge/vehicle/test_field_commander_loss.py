"""A field daemon whose Commander disappears holds in the air and waits for it: it neither
lands nor exits (the simulated world's grace does not apply to it), and a Commander that
comes back takes over without a new arm or take-off (issue 8; docs/notes/safety.md "Commander
loss": hold, RTL only if configured). Real MAVLink bytes to the emulator, real zenoh."""

from __future__ import annotations

import asyncio

import pytest

from aeroweaver_edge.config import AgentConfig, FieldConfig, FieldPoint, UavConfig
from aeroweaver_edge.daemon.app import run_daemon
from aeroweaver_edge.daemon.decision_round import RoundOutcome
from aeroweaver_edge.sim.emulator.host import EmulatorHost, EmulatorOptions
from commander.commander import Commander
from commander.harness import plan_for_task
from tests.helpers.mav import FAST, free_udp_ports, stop_within, until
from tests.helpers.zenoh_net import ZenohNet

pytestmark = pytest.mark.slow

HELD_ROUNDS = 10  # rounds flown without a Commander: 10 x 0.2 s, well past world_grace_s


async def test_a_field_daemon_holds_and_waits_when_the_commander_disappears(
    zenoh_net: ZenohNet, caplog: pytest.LogCaptureFixture
) -> None:
    await zenoh_net.open("seed")  # the link both Commanders and the daemon meet on
    opts = EmulatorOptions(uavs=1, local_base=0, remote_ports=[9], time_scale=4.0)
    async with EmulatorHost(opts) as host:
        port = free_udp_ports(1)[0]
        host.retarget(0, port)
        ap = host.vehicles[0]
        cfg = UavConfig(
            uav="uav0",
            swarm="field",
            round_s=0.2,
            mesh=zenoh_net.config(seed=False),
            agent=AgentConfig(selector="scripted", beta=0.0),
            vehicle={  # type: ignore[arg-type]
                "backend": "mavlink",
                "url": f"udpin://127.0.0.1:{port}",
                "world_grace_s": 0.5,
                **FAST,
            },
            field=FieldConfig(points=[FieldPoint(id="L0", kind="landmark", north=6.0, east=4.0)]),
        )
        outcomes: list[RoundOutcome] = []

        async def on_round(out: RoundOutcome) -> None:
            outcomes.append(out)

        daemon = asyncio.create_task(run_daemon(cfg, on_round=on_round))
        plan = plan_for_task("coverage", ["uav0"], mission_id="field-cl")
        first_mesh = await zenoh_net.open("cmdr")
        first = Commander(first_mesh, "field")
        await first.start()
        second: Commander | None = None
        try:
            first.publish(plan)
            assert await first.wait_ready(["uav0"], 15.0) == set()
            await until(lambda: ap.armed and ap.mode == "OFFBOARD", 15, "launched to offboard")
            await until(lambda: any(not o.held for o in outcomes), 15, "a decided round")

            # The Commander goes (its session closes: the token disappears).
            await first.aclose()
            await first_mesh.aclose()
            await until(
                lambda: outcomes[-1].hold_cause == "no_assignment", 10, "holding without it"
            )
            lost_at = len(outcomes)
            await until(lambda: len(outcomes) >= lost_at + HELD_ROUNDS, 30, "rounds while held")
            assert not daemon.done()  # waited: no exit, whatever world_grace_s says
            assert all(o.held for o in outcomes[lost_at:])
            assert ap.armed
            assert ap.mode == "OFFBOARD"  # held under our control (zero velocity), not landing
            assert ap.alt > 1.0  # still in the air
            said = [r.getMessage() for r in caplog.records if "Commander" in r.getMessage()]
            assert said == ["uav0: the Commander went away mid-mission; holding and waiting for it"]

            # A new Commander session: the daemon catches up and decides again, in the air.
            second = Commander(await zenoh_net.open("cmdr"), "field")
            await second.start()
            second.publish(plan)
            assert await second.wait_ready(["uav0"], 15.0) == set()
            back_at = len(outcomes)
            await until(lambda: any(not o.held for o in outcomes[back_at:]), 15, "deciding again")
            commands = [r.command for r in ap.log if r.executed]
            assert commands.count(400) == 1  # armed once
            assert commands.count(22) == 1  # took off once
            assert 21 not in commands  # never landed

            second.end_mission("done")  # a live Commander ending the mission: it lands
            await until(lambda: ap.mode == "AUTO.LAND", 10, "lands at mission end")
            assert not daemon.done()
        finally:
            await stop_within(daemon, 30.0, "the daemon")
            await first.aclose()
            if second is not None:
                await second.aclose()
