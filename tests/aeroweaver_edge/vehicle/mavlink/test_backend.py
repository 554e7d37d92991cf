"""The mavlink backend against the emulator, with real MAVLink 2 bytes on loopback UDP."""

from __future__ import annotations

import asyncio
import math
import time

import pytest

from aeroweaver_edge.config import SafetyConfig
from aeroweaver_edge.sim.emulator.autopilot import EmulatedAutopilot, Faults
from aeroweaver_edge.sim.emulator.host import EmulatorOptions
from aeroweaver_edge.vehicle.errors import VehicleError
from aeroweaver_edge.vehicle.mavlink.backend import MavlinkVehicle
from aeroweaver_edge.vehicle.mavlink.codec import mavlink
from aeroweaver_edge.vehicle.mavlink.commands import CommandError
from aeroweaver_edge.vehicle.mavlink.geo import DEFAULT_ORIGIN, GeoOrigin
from aeroweaver_edge.vehicle.mavlink.link import LinkError
from tests.helpers.mav import ThreadedEmulator, emulated, free_udp_ports, until, vehicle_config

ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF


async def fly(v: MavlinkVehicle, alt: float = 5.0) -> None:
    await v.arm()
    await v.takeoff(alt)
    await until(lambda: v.in_air and v.mode_role == "hold", 10, "take-off complete")
    await v.set_velocity(0.0, 0.0, 0.0)
    assert v.mode_role == "offboard"


def modes(ap: EmulatedAutopilot) -> list[str]:
    return [
        text.split(" -> ")[1].split(" ")[0] for _t, text in ap.events if text.startswith("mode")
    ]


def executed(ap: EmulatedAutopilot, command: int) -> int:
    return sum(1 for r in ap.log if r.command == command and r.executed)


@pytest.mark.parametrize(
    ("personality", "takeoff", "offboard", "hold", "land", "rtl"),
    [
        ("px4", "AUTO.TAKEOFF", "OFFBOARD", "AUTO.LOITER", "AUTO.LAND", "AUTO.RTL"),
        ("ardupilot", "GUIDED", "GUIDED", "BRAKE", "LAND", "RTL"),
    ],
)
async def test_mode_mapping_for_takeoff_offboard_hold_land_and_rtl(
    personality: str, takeoff: str, offboard: str, hold: str, land: str, rtl: str
) -> None:
    async with emulated(1, personality=personality) as (host, [v]):
        ap = host.vehicles[0]
        assert v.personality.name == personality  # picked from the heartbeat
        assert v.link.sysid == 1
        assert v.link.codec.src_system == 1
        await v.arm()
        assert ap.armed
        assert v.armed
        await v.takeoff(4.0)
        await until(lambda: ap.alt >= 4.0 - 1e-6 and v.in_air, 10, "climb")
        assert takeoff in modes(ap)
        await v.set_velocity(1.0, -2.0, 0.0)
        assert ap.mode == offboard
        await until(lambda: abs(ap.world.body("uav0").vn - 1.0) < 1e-3, 5, "velocity applied")
        assert ap.world.body("uav0").ve == pytest.approx(-2.0, abs=1e-3)
        await v.return_home()
        assert ap.mode == rtl
        await v.set_velocity(1.0, 0.0, 0.0)  # a fresh command re-engages offboard
        assert ap.mode == offboard
        v.stream.stop()
        await v.hold()
        assert ap.mode == hold
        await v.land()
        assert ap.mode == land
        await until(lambda: not ap.armed, 20, "touch-down and auto-disarm")
        await until(lambda: not v.in_air and not v.armed, 2, "telemetry shows it landed")


async def test_ack_results_are_matched_and_unknown_commands_are_unsupported() -> None:
    async with emulated(1) as (_host, [v]):
        result = await v.commands.send(mavlink.MAV_CMD_DO_ORBIT, 10.0, check=False)
        assert result == mavlink.MAV_RESULT_UNSUPPORTED
        with pytest.raises(CommandError, match="refused by system 1: DENIED"):
            await v.commands.send(TAKEOFF, math.nan, 0, 0, math.nan, math.nan, math.nan, 500.0)


async def test_in_progress_waits_for_the_final_ack_without_resending() -> None:
    faults = [Faults(slow_commands={ARM: 0.6})]
    async with emulated(1, faults=faults, vehicle={"command_timeout_s": 0.2}) as (host, [v]):
        await v.arm()
        assert v.armed
        assert v.commands.stats.sent[ARM] == 1  # IN_PROGRESS extended the wait: no retry
        assert executed(host.vehicles[0], ARM) == 1


async def test_no_acks_fail_after_bounded_retries_with_a_clear_error() -> None:
    async with emulated(1, vehicle={"command_retries": 2}) as (host, [v]):
        host.vehicles[0].faults.no_acks = True
        with pytest.raises(
            CommandError, match=r"DO_ORBIT: no COMMAND_ACK from system 1 after 3 tries"
        ):
            await v.commands.send(mavlink.MAV_CMD_DO_ORBIT, 10.0)
        recs = [r for r in host.vehicles[0].log if r.command == mavlink.MAV_CMD_DO_ORBIT]
        assert [r.confirmation for r in recs] == [0, 1, 2]  # confirmation counts the retries


async def test_ten_percent_loss_both_ways_acked_commands_succeed_without_duplicated_actions() -> (
    None
):
    faults = [Faults(drop_rx=0.1, drop_tx=0.1)]
    async with emulated(1, faults=faults, vehicle={"command_retries": 8}) as (host, [v]):
        ap = host.vehicles[0]
        for _ in range(3):
            await fly(v)
            await v.set_velocity(2.0, 0.0, 0.0)
            await v.land()
            await until(lambda: not ap.armed, 20, "landed")
            await until(lambda: not v.in_air and not v.armed, 10, "telemetry shows landed")
        # Every action ran exactly once per flight although frames (and ACKs) were lost.
        assert executed(ap, ARM) == 3
        assert executed(ap, TAKEOFF) == 3
        assert executed(ap, mavlink.MAV_CMD_NAV_LAND) == 3
        assert modes(ap).count("OFFBOARD") == 3
        assert v.preflight.fence_uploaded


async def test_lease_expiry_hands_the_vehicle_to_the_autopilot_hold() -> None:
    async with emulated(1, vehicle={"lease_s": 0.3}) as (host, [v]):
        ap = host.vehicles[0]
        await fly(v)
        await v.set_velocity(3.0, 0.0, 0.0)
        await until(lambda: ap.mode == "AUTO.LOITER", 3, "hold after the lease")
        assert v.stream.stats.expired == 1
        n = ap.setpoints
        await until(lambda: v.link.age("HEARTBEAT") < 0.05 and ap.setpoints == n, 2, "quiet")
        assert ap.world.body("uav0").sp_n == 0.0  # hold zeroes the setpoint


async def test_a_command_racing_the_lease_expiry_is_not_overridden_by_the_hold() -> None:
    async with emulated(1) as (host, [v]):
        await fly(v)
        await v.set_velocity(2.0, 0.0, 0.0)
        await v._lease_expired()  # the expiry task, running after a fresh command came in
        assert host.vehicles[0].mode == "OFFBOARD"
        assert v.stream.active


async def test_link_loss_is_detected_and_motion_never_resumes_on_its_own() -> None:
    # real time: the failsafe's landing (7 s from 5 m) outlasts the link's recovery below
    async with emulated(1, vehicle={"link_timeout_s": 1.5}, time_scale=1.0) as (host, [v]):
        ap = host.vehicles[0]
        await fly(v)
        await v.set_velocity(2.0, 1.0, 0.0)
        ap.faults.mute = ap.faults.deaf = True  # the radio dies both ways
        took = await until(lambda: v.link.lost, 3.0, "link loss detected")
        assert took < 3.0
        assert not (await v.health()).ok
        assert not v.stream.active  # the stream stopped with the link
        ap.faults.deaf = False
        # the companion-loss failsafe the daemon set at preflight: land (COM_OBL_RC_ACT 4)
        await until(lambda: ap.mode == "AUTO.LAND", 3, "offboard-loss failsafe")
        with pytest.raises(VehicleError, match="no new motion"):
            await v.set_velocity(1.0, 0.0, 0.0)
        ap.faults.mute = False
        await until(lambda: not v.link.lost, 3, "link back")
        seen = ap.setpoints
        hb = v.link.stats.datagrams
        await until(lambda: v.link.stats.datagrams > hb + 20, 5, "traffic after recovery")
        assert ap.setpoints == seen  # nothing was streamed again on its own
        assert ap.mode == "AUTO.LAND"
        await v.set_velocity(1.0, 0.0, 0.0)  # a fresh command: offboard again
        assert ap.mode == "OFFBOARD"


def test_an_event_loop_stall_stops_the_stream_and_the_autopilot_failsafe_fires() -> None:
    opts = EmulatorOptions(
        uavs=1, local_base=0, remote_ports=[9], time_scale=4.0, params={"COM_OF_LOSS_T": 0.5},
    )  # fmt: skip
    with ThreadedEmulator(opts) as host:
        port = free_udp_ports(1)[0]  # chosen after the emulator bound its own ports
        host.retarget(0, port)
        ap = host.vehicles[0]

        async def scenario() -> None:
            v = MavlinkVehicle(
                vehicle_config(port, lease_s=1.0, link_timeout_s=3.0), SafetyConfig(), "uav0"
            )
            await v.start()
            try:
                await fly(v)
                await v.set_velocity(2.0, 0.0, 0.0)
                stalled_at = time.monotonic()
                time.sleep(1.5)  # noqa: ASYNC251 - the stall under test: the loop is blocked
                # The emulator (another thread) saw the stream stop and failed safe.
                assert any("offboard loss" in e for _t, e in ap.events)
                assert ap.mode == "AUTO.LAND"  # the companion-loss failsafe set at preflight
                assert time.monotonic() - stalled_at >= 1.5
                await until(lambda: v.stream.stats.expired == 1, 2, "lease expiry noticed")
                assert not v.stream.active  # the old setpoint is never resumed
                assert v.stream.stats.stalls >= 1
            finally:
                await v.aclose()

        asyncio.run(scenario())


async def test_own_body_scoping_only_the_configured_system_is_ever_addressed() -> None:
    # Two vehicles (sysid 1 and 2) both talk to one daemon port; the daemon flies sysid 2.
    opts = EmulatorOptions(uavs=2, local_base=0, remote_ports=[9, 9], time_scale=4.0)
    from aeroweaver_edge.sim.emulator.host import EmulatorHost

    async with EmulatorHost(opts) as host:
        port = free_udp_ports(1)[0]
        host.retarget(0, port)
        host.retarget(1, port)
        v = MavlinkVehicle(vehicle_config(port, sysid=2), SafetyConfig(), "uav1")
        await v.start()
        try:
            await fly(v)
            await v.set_velocity(1.0, 0.0, 0.0)
            await v.land()
            other, mine = host.vehicles
            assert other.log == []
            assert other.setpoints == 0
            assert other.rx["PARAM_REQUEST_READ"] == 0
            assert mine.log
            assert all(r.target[0] == 2 for r in mine.log)
            assert set(v.link.stats.sent_to) == {2}
            assert v.link.stats.foreign[1] > 0  # the other vehicle's traffic was dropped
            stray = v.link.mav.command_long_encode(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
            with pytest.raises(LinkError, match="refusing to address system 1"):
                v.link.send(stray)
        finally:
            await v.aclose()


async def test_failsafe_check_refuses_to_arm_an_unsafe_profile_and_names_the_parameter() -> None:
    check = {"companion_failsafe": "check"}  # verify only: the daemon writes nothing
    async with emulated(1, params={"COM_OBL_RC_ACT": 0}, vehicle=check) as (host, [v]):
        assert v.refused is not None
        assert "COM_OBL_RC_ACT=0, needs 4 or 3" in v.refused
        assert not (await v.health()).ok
        assert host.vehicles[0].param("COM_OBL_RC_ACT") == 0  # nothing written
        with pytest.raises(VehicleError, match="refusing to arm: companion-loss failsafe: COM_OBL"):
            await v.arm()
        assert executed(host.vehicles[0], ARM) == 0


async def test_failsafe_check_only_warns_with_the_warn_policy() -> None:
    async with emulated(1, params={"GF_ACTION": 1}, vehicle={"failsafe_policy": "warn"}) as (
        _host,
        [v],
    ):
        assert v.preflight.problems == [
            "GF_ACTION=1 not in [2.0, 3.0, 5.0] (geofence breach: Hold, Return or Land)"
        ]
        assert v.refused is None
        await v.arm()


async def test_ardupilot_failsafe_parameters_are_read_with_their_encoding() -> None:
    async with emulated(1, personality="ardupilot", params={"FENCE_ACTION": 0}) as (_h, [v]):
        assert v.preflight.params["GUID_TIMEOUT"] == 3.0
        assert v.preflight.params["FENCE_ENABLE"] == 1.0
        assert v.refused is not None
        assert "FENCE_ACTION=0" in v.refused


async def test_the_safety_geofence_is_uploaded_and_the_autopilot_enforces_it() -> None:
    safety = SafetyConfig(geofence_north_m=(-10.0, 10.0), geofence_east_m=(-10.0, 10.0))
    async with emulated(1, safety=safety) as (host, [v]):
        ap = host.vehicles[0]
        assert v.preflight.fence_uploaded
        assert len(ap.fence) == 4
        corners = [ap.origin.to_local(it.x / 1e7, it.y / 1e7, 0.0)[:2] for it in ap.fence]
        expected = [(-10, -10), (10, -10), (10, 10), (-10, 10)]
        for (n, e), (en, ee) in zip(corners, expected, strict=True):
            assert n == pytest.approx(en, abs=0.05)
            assert e == pytest.approx(ee, abs=0.05)
        await fly(v)
        await v.set_velocity(8.0, 0.0, 0.0)  # straight through the northern edge
        await until(lambda: any("geofence breach" in e for _t, e in ap.events), 5, "breach")
        assert ap.mode == "AUTO.LOITER"  # GF_ACTION 2: hold
        assert ap.world.body("uav0").north < 14.0


async def test_no_heartbeat_means_a_clear_connect_error_and_nothing_left_open() -> None:
    port = free_udp_ports(1)[0]
    v = MavlinkVehicle(vehicle_config(port, connect_timeout_s=0.3), SafetyConfig(), "uav0")
    with pytest.raises(
        VehicleError,
        match=r"uav0: no heartbeat from an autopilot on udpin://127.0.0.1:\d+ within 0.3 s",
    ):
        await v.start()
    assert v.link._ep is None


async def test_no_takeoff_while_airborne_and_no_motion_on_the_ground() -> None:
    async with emulated(1) as (_host, [v]):
        with pytest.raises(VehicleError, match="no motion on the ground"):
            await v.set_velocity(1.0, 0.0, 0.0)
        await fly(v)
        with pytest.raises(VehicleError, match="already in the air"):
            await v.takeoff(5.0)


async def test_stale_position_telemetry_degrades_even_with_heartbeats() -> None:
    async with emulated(1) as (host, [v]):
        ap = host.vehicles[0]
        await fly(v)
        ap.intervals.pop(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED)  # position stream stops
        await until(lambda: v.link.age("LOCAL_POSITION_NED") > 2.5, 5, "position stale")
        health = await v.health()
        assert not health.ok
        assert health.detail == "position telemetry stale"
        assert v.link.alive  # heartbeats still flow
        with pytest.raises(VehicleError, match="telemetry stale; no new motion"):
            await v.set_velocity(1.0, 0.0, 0.0)


async def test_vehicle_origin_shifts_positions_targets_and_the_fence_into_the_swarm_frame() -> None:
    """Each real autopilot's local frame is centred where it booted; ``vehicle.origin`` puts
    every vehicle into one shared frame (SITL instances at different homes, a real swarm)."""
    south = DEFAULT_ORIGIN.to_global(-10.0, 4.0, 0.0)  # the swarm's origin: 10 m S, 4 m E
    async with emulated(1, vehicle={"origin": list(south)}) as (host, [v]):
        ap = host.vehicles[0]
        raw = v.link.last["LOCAL_POSITION_NED"]
        st = await v.state()
        assert st.pos[0] == pytest.approx(float(raw.x) + 10.0, abs=0.05)
        assert st.pos[1] == pytest.approx(float(raw.y) - 4.0, abs=0.05)
        fence = ap.fence  # the gate's rectangle, anchored at the swarm origin
        lat0 = min(item.x for item in fence) / 1e7
        n_min = SafetyConfig().geofence_north_m[0]
        assert lat0 == pytest.approx(GeoOrigin(*south).to_global(n_min, 0.0)[0], abs=1e-6)
        await fly(v)
        await v.goto(st.pos[0] + 3.0, st.pos[1], -5.0)  # in the swarm frame
        await until(lambda: ap.setpoint is not None and ap.setpoint[0] == "position", 2, "target")
        assert ap.setpoint is not None
        assert ap.setpoint[1] == pytest.approx(float(raw.x) + 3.0, abs=0.1)  # autopilot frame
