"""A daemon with the mavlink backend and no simulator: rounds on the wall clock, perception
from telemetry and known points; it launches when a mission is assigned, flies to a
landmark over real MAVLink, and lands when the Commander ends the mission."""

from __future__ import annotations

import asyncio
import contextlib

import pytest

from aeroweaver_edge.config import AgentConfig, FieldConfig, FieldPoint, UavConfig
from aeroweaver_edge.daemon.app import run_daemon
from aeroweaver_edge.sim.emulator.host import EmulatorHost, EmulatorOptions
from commander.commander import Commander
from commander.harness import plan_for_task
from tests.helpers.mav import FAST, free_udp_ports, until
from tests.helpers.zenoh_net import ZenohNet

pytestmark = pytest.mark.slow


async def test_field_daemon_flies_a_mission_against_the_emulator(zenoh_net: ZenohNet) -> None:
    cmdr_mesh = await zenoh_net.open("cmdr")
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
            vehicle={"backend": "mavlink", "url": f"udpin://127.0.0.1:{port}", **FAST},  # type: ignore[arg-type]
            field=FieldConfig(points=[FieldPoint(id="L0", kind="landmark", north=6.0, east=4.0)]),
        )
        daemon = asyncio.create_task(run_daemon(cfg))
        commander = Commander(cmdr_mesh, "field")
        await commander.start()
        try:
            plan = plan_for_task("coverage", ["uav0"], mission_id="field-1")
            commander.publish(plan)  # the daemon catches up
            assert await commander.wait_ready(["uav0"], 15.0) == set()
            await until(lambda: ap.armed and ap.mode == "OFFBOARD", 15, "launched to offboard")
            body = host.world.body("uav0")
            await until(lambda: abs(body.north - 6.0) < 0.3 and abs(body.east - 4.0) < 0.3, 15,
                        "at the landmark")  # fmt: skip
            commander.end_mission("done")
            await until(lambda: ap.mode == "AUTO.LAND", 10, "lands at mission end")
            await until(lambda: not ap.armed, 15, "touch-down")
            commands = [r.command for r in ap.log if r.executed]
            assert commands.count(400) == 1
            assert commands.count(22) == 1
            assert not daemon.done()
        finally:
            daemon.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await daemon
            await commander.aclose()
