"""Flight phases through the Vehicle port, on the mavlink backend and an emulated PX4."""

from __future__ import annotations

import asyncio

import pytest

from aeroweaver_edge.config import SafetyConfig
from aeroweaver_edge.contracts.actions import VehicleAction
from aeroweaver_edge.daemon.flight_phases import FlightPhases, Phase, default_approval
from aeroweaver_edge.vehicle.mavlink.backend import MavlinkVehicle
from aeroweaver_edge.vehicle.mavlink.codec import mavlink
from tests.helpers.mav import emulated, until, vehicle_config

ARM, TAKEOFF = mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_CMD_NAV_TAKEOFF


def phases_of(p: FlightPhases) -> list[str]:
    return [ph for _t, ph, _why in p.stats.transitions]


async def test_launch_goes_preflight_arm_takeoff_offboard_mission() -> None:
    async with emulated(1) as (host, [v]):
        p = FlightPhases(v, uav="uav0", altitude_m=6.0)
        assert await p.launch()
        assert phases_of(p) == ["preflight", "arming", "taking_off", "offboard", "mission"]
        ap = host.vehicles[0]
        assert ap.mode == "OFFBOARD"
        assert ap.alt == pytest.approx(6.0)
        assert await p.launch()  # idempotent: nothing is sent twice
        assert sum(r.command == ARM for r in ap.log) == 1
        await p.set_velocity(1.0, 0.0, 0.0)
        await until(lambda: ap.world.body("uav0").sp_n == 1.0, 2, "velocity")
        await p.finish("mission end")
        assert p.phase == Phase.LANDING
        assert ap.mode == "AUTO.LAND"


async def test_a_restarted_daemon_in_the_air_never_arms_or_takes_off() -> None:
    # COM_OF_LOSS_T 3 s (accepted as found): the restart comes before the companion-loss
    # failsafe lands the vehicle
    async with emulated(1, params={"COM_OF_LOSS_T": 3.0}) as (host, [v]):
        ap = host.vehicles[0]
        first = FlightPhases(v, uav="uav0", altitude_m=5.0)
        await first.launch()
        url = v.cfg.url
        await v.aclose()  # the daemon dies; the vehicle is still in the air
        await asyncio.sleep(0.1)  # the socket's close runs on the next loop iteration
        port = int(str(url).rsplit(":", 1)[1])
        v2 = MavlinkVehicle(vehicle_config(port), SafetyConfig(), "uav0")
        await v2.start()
        try:
            again = FlightPhases(v2, uav="uav0", altitude_m=5.0)
            assert await again.launch()
            assert phases_of(again) == ["recovering", "mission"]
            assert [r.command for r in ap.log if r.command in (ARM, TAKEOFF)] == [ARM, TAKEOFF]
            assert ap.mode == "AUTO.LOITER"  # held; motion only from fresh decisions
        finally:
            await v2.aclose()


async def test_link_loss_degrades_and_the_first_command_after_it_is_a_hold() -> None:
    async with emulated(1) as (host, [v]):
        ap = host.vehicles[0]
        p = FlightPhases(v, uav="uav0", altitude_m=5.0)
        await p.launch()
        ap.faults.mute = True
        await until(lambda: v.link.lost, 5, "loss")
        await p.set_velocity(2.0, 0.0, 0.0)
        assert p.phase == Phase.DEGRADED
        ap.faults.mute = False
        await until(lambda: not v.link.lost and v._fresh(), 3, "link back")
        n = ap.setpoints
        await p.set_velocity(2.0, 0.0, 0.0)  # the round that notices recovery only holds
        assert p.phase == Phase.MISSION
        assert ap.setpoints == n
        assert p.stats.refused_motion["recovery"] == 1
        await p.set_velocity(2.0, 0.0, 0.0)  # the next, fresh decision flies
        await until(lambda: ap.world.body("uav0").sp_n == 2.0, 3, "fresh motion")


async def test_a_refused_preflight_keeps_the_vehicle_on_the_ground() -> None:
    check = {"companion_failsafe": "check"}
    async with emulated(1, params={"COM_OBL_RC_ACT": 0}, vehicle=check) as (host, [v]):
        p = FlightPhases(v, uav="uav0", altitude_m=5.0)
        assert not await p.launch()
        assert p.phase == Phase.REFUSED
        await p.set_velocity(1.0, 0.0, 0.0)
        assert host.vehicles[0].log == [] or all(
            r.command not in (ARM, TAKEOFF) for r in host.vehicles[0].log
        )
        assert not host.vehicles[0].armed


async def test_vehicle_actions_pass_the_approval_predicate() -> None:
    assert default_approval("uav0", VehicleAction("land"))
    assert not default_approval("uav0", VehicleAction("takeoff"))
    async with emulated(1) as (host, [v]):
        ap = host.vehicles[0]
        p = FlightPhases(v, uav="uav0", altitude_m=5.0)
        assert await p.act(VehicleAction("takeoff")) == "takeoff needs operator approval"
        assert ap.log == [] or all(r.command != ARM for r in ap.log)
        approved = FlightPhases(v, uav="uav0", altitude_m=5.0, approve=lambda _u, _a: True)
        assert await approved.act(VehicleAction("takeoff", 7.0)) is None
        assert ap.alt == pytest.approx(7.0)
        assert approved.phase == Phase.MISSION
        assert await approved.act(VehicleAction("takeoff")) == "take-off refused in phase mission"
        assert await approved.act(VehicleAction("return_home")) is None
        assert approved.phase == Phase.RETURNING
        assert ap.mode == "AUTO.RTL"


async def test_finish_returns_home_when_configured() -> None:
    async with emulated(1) as (host, [v]):
        p = FlightPhases(v, uav="uav0", altitude_m=5.0, end_action="return")
        await p.launch()
        await p.finish("operator stop")
        assert p.phase == Phase.RETURNING
        assert host.vehicles[0].mode == "AUTO.RTL"
