"""MAVSDK 4.x as an independent reference client of the emulator: discovery, telemetry,
params, arm, take-off, offboard, hold, return and land, for both personalities. It maps
modes on its own, so the emulator cannot merely agree with our own backend's bugs."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

import pytest

from aeroweaver_edge.sim.emulator.host import EmulatorHost, EmulatorOptions
from tests.helpers.mav import free_udp_ports, until

pytestmark = pytest.mark.mavsdk  # fails without the extra (tests/conftest.py)
try:
    import mavsdk.asyncio as m
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.info import InfoAsync
    from mavsdk.asyncio.plugins.offboard import OffboardAsync, OffboardError
    from mavsdk.asyncio.plugins.param import ParamAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
    from mavsdk.plugins.offboard import VelocityNedYaw
except ImportError:  # the marker turns every test here into a failure (or an allowed skip)
    pass


async def has_position(tel: Any) -> bool:
    lat = (await tel.position()).latitude_deg
    return bool(lat == lat)  # NaN until the first GLOBAL_POSITION_INT


@contextlib.asynccontextmanager
async def mavsdk_client(personality: str) -> AsyncIterator[tuple[EmulatorHost, Any]]:
    opts = EmulatorOptions(uavs=1, personality=personality, local_base=0, remote_ports=[9],
                           time_scale=4.0)  # fmt: skip
    async with EmulatorHost(opts) as host:
        port = free_udp_ports(1)[0]  # chosen after the emulator bound its own ports
        host.retarget(0, port)
        async with m.Mavsdk(m.Configuration.create_manual(1, 191, True)) as sdk:
            await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
            system = await sdk.first_autopilot(timeout_s=5.0)
            assert system is not None
            yield host, system


async def eventually(get: Callable[[], Awaitable[Any]], want: Any, timeout_s: float = 5.0) -> None:
    deadline = asyncio.get_running_loop().time() + timeout_s
    while (got := await get()) != want:
        assert asyncio.get_running_loop().time() < deadline, f"still {got!r}, want {want!r}"
        await asyncio.sleep(0.05)


async def test_mavsdk_flies_an_emulated_px4() -> None:
    async with mavsdk_client("px4") as (host, system):
        ap = host.vehicles[0]
        tel, action = TelemetryAsync(system), ActionAsync(system)
        offboard, param = OffboardAsync(system), ParamAsync(system)
        version = await InfoAsync(system).get_version()
        assert version.flight_sw_major == 1
        assert await param.get_param_float("COM_OF_LOSS_T") == pytest.approx(1.0)
        assert await param.get_param_int("GF_ACTION") == 2  # PX4's bytewise int encoding
        await eventually(lambda: has_position(tel), True)
        pos = await tel.position()
        assert pos.latitude_deg == pytest.approx(ap.origin.lat_deg, abs=1e-6)
        await action.arm()
        await eventually(tel.armed, True)
        await action.set_takeoff_altitude(4.0)
        await action.takeoff()
        await until(lambda: ap.mode == "AUTO.LOITER" and ap.alt >= 4.0 - 1e-6, 10, "take-off")
        await eventually(tel.in_air, True)
        with pytest.raises(OffboardError, match="NO_SETPOINT_SET"):
            await offboard.start()
        await offboard.set_velocity_ned(VelocityNedYaw(1.5, 0.0, 0.0, 0.0))
        await offboard.start()
        assert ap.mode == "OFFBOARD"
        await until(lambda: ap.world.body("uav0").vn == pytest.approx(1.5, abs=1e-4), 3, "velocity")
        await action.hold()
        assert ap.mode == "AUTO.LOITER"
        await action.return_to_launch()
        assert ap.mode == "AUTO.RTL"
        await action.land()
        assert ap.mode == "AUTO.LAND"
        await eventually(tel.in_air, False, 15.0)
        await eventually(tel.armed, False)
        assert ap.rx["HEARTBEAT"] > 0  # MAVSDK's own heartbeats reached the vehicle
        # AUTOPILOT_VERSION was answered, so MAVSDK did not keep asking for it.
        assert sum(r.command == 512 for r in ap.log) < 5


async def test_mavsdk_maps_ardupilot_modes_itself() -> None:
    async with mavsdk_client("ardupilot") as (host, system):
        ap = host.vehicles[0]
        action, tel = ActionAsync(system), TelemetryAsync(system)
        await action.arm()
        await eventually(tel.armed, True)
        await action.set_takeoff_altitude(3.0)
        await action.takeoff()  # MAVSDK: GUIDED, then NAV_TAKEOFF
        await until(lambda: ap.alt >= 3.0 - 1e-6, 10, "take-off")
        assert ap.mode == "GUIDED"
        await action.hold()
        assert ap.mode == "BRAKE"
        await action.return_to_launch()
        assert ap.mode == "RTL"
        await action.land()
        assert ap.mode == "LAND"
