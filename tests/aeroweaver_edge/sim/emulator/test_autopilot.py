"""Emulated autopilot behaviour a real PX4/ArduPilot shows, exercised over real bytes."""

from __future__ import annotations

import asyncio

import pytest

from aeroweaver_edge.sim.emulator.autopilot import Faults
from aeroweaver_edge.vehicle.mavlink.backend import MavlinkVehicle
from aeroweaver_edge.vehicle.mavlink.codec import mavlink
from aeroweaver_edge.vehicle.mavlink.fence import FENCE
from aeroweaver_edge.vehicle.mavlink.personality import PX4
from aeroweaver_edge.vehicle.mavlink.stream import ZERO_VELOCITY
from tests.helpers.mav import emulated, until

SET_MODE = mavlink.MAV_CMD_DO_SET_MODE


async def airborne(v: MavlinkVehicle) -> None:
    await v.arm()
    await v.takeoff(4.0)
    await until(lambda: v.in_air and v.link.last["LOCAL_POSITION_NED"].z <= -3.99, 10, "climb")
    await until(lambda: v.mode_role in ("hold", "offboard"), 5, "take-off complete")


async def test_px4_refuses_offboard_without_a_live_setpoint_stream() -> None:
    async with emulated(1) as (host, [v]):
        await airborne(v)
        p = PX4().set_mode_params("OFFBOARD", armed=True)
        result = await v.commands.send(SET_MODE, *p, check=False)
        assert result == mavlink.MAV_RESULT_DENIED
        v.stream.set(ZERO_VELOCITY)
        await until(lambda: host.vehicles[0].setpoints >= 3, 2, "stream")
        assert await v.commands.send(SET_MODE, *p, check=False) == mavlink.MAV_RESULT_ACCEPTED
        assert host.vehicles[0].mode == "OFFBOARD"


@pytest.mark.parametrize(
    ("action", "mode"), [(4, "AUTO.LAND"), (3, "AUTO.RTL"), (5, "AUTO.LOITER")]
)
async def test_offboard_loss_applies_com_obl_rc_act(action: int, mode: str) -> None:
    params = {"COM_OBL_RC_ACT": action, "COM_OF_LOSS_T": 0.3}
    as_found = {"failsafe_policy": "warn", "companion_failsafe": "check"}  # nothing rewritten
    async with emulated(1, params=params, vehicle=as_found) as (host, [v]):
        ap = host.vehicles[0]
        await airborne(v)
        await v.set_velocity(1.0, 0.0, 0.0)
        v.stream.stop()  # the daemon goes quiet
        await until(lambda: ap.mode == mode, 3, mode)
        assert any(f"COM_OBL_RC_ACT={action}" in e for _t, e in ap.events)


async def test_ardupilot_guided_velocity_targets_expire() -> None:
    async with emulated(1, personality="ardupilot", params={"GUID_TIMEOUT": 0.3}) as (host, [v]):
        ap = host.vehicles[0]
        await airborne(v)
        await v.set_velocity(2.0, 0.0, 0.0)
        await until(lambda: ap.world.body("uav0").sp_n == 2.0, 2, "velocity")
        v.stream.stop()
        await until(lambda: ap.world.body("uav0").sp_n == 0.0, 3, "target expired")
        assert ap.mode == "GUIDED"  # Copter stops but stays in GUIDED


async def test_parameters_round_trip_with_each_encoding() -> None:
    for personality, name, value in (
        ("px4", "COM_OBL_RC_ACT", 3),
        ("ardupilot", "FENCE_ACTION", 2),
    ):
        async with emulated(1, personality=personality) as (host, [v]):
            assert await v.params.set(name, value) == value
            assert await v.params.get(name) == value
            assert host.vehicles[0].param(name) == value


async def test_the_uploaded_fence_downloads_again() -> None:
    async with emulated(1) as (host, [v]):
        sysid, compid = v.link.target
        counted = v.link.expect("MISSION_COUNT", lambda m: m.mission_type == FENCE)
        v.link.send(v.link.mav.mission_request_list_encode(sysid, compid, FENCE))
        count = await asyncio.wait_for(counted, 2)
        assert count.count == 4
        item = v.link.expect("MISSION_ITEM_INT", lambda m: m.seq == 2)
        v.link.send(v.link.mav.mission_request_int_encode(sysid, compid, 2, FENCE))
        got = await asyncio.wait_for(item, 2)
        assert got.command == mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
        assert (got.x, got.y) == (host.vehicles[0].fence[2].x, host.vehicles[0].fence[2].y)


async def test_no_heartbeats_means_no_connection() -> None:
    with pytest.raises(Exception, match="no heartbeat"):
        async with emulated(1, faults=[Faults(no_heartbeats=True)],
                            vehicle={"connect_timeout_s": 0.5}):  # fmt: skip
            pass
