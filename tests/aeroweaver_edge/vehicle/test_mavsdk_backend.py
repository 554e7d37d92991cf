"""The optional mavsdk backend behind the Vehicle port, against the emulator."""

from __future__ import annotations

import asyncio
import time

import pytest

from aeroweaver_edge.config import SafetyConfig, VehicleConfig
from aeroweaver_edge.sim.emulator.host import EmulatorOptions
from aeroweaver_edge.vehicle.errors import VehicleError
from aeroweaver_edge.vehicle.mavsdk_backend import MavsdkVehicle
from tests.helpers.mav import FAST, ThreadedEmulator, free_udp_ports, until

pytestmark = pytest.mark.mavsdk  # fails without the extra (tests/conftest.py)


def config(port: int, **over: object) -> VehicleConfig:
    return VehicleConfig(
        backend="mavsdk",
        url=f"udpin://127.0.0.1:{port}",
        sysid=1,
        **FAST,
        **over,  # type: ignore[arg-type]
    )


def test_the_watchdog_thread_holds_when_the_loop_stalls_despite_mavsdk_resending() -> None:
    """MAVSDK re-sends the last setpoint at 20 Hz from its own thread, so the autopilot's
    offboard-loss failsafe never sees a stalled daemon; our watchdog thread must hold."""
    opts = EmulatorOptions(uavs=1, local_base=0, remote_ports=[9], time_scale=4.0,
                           params={"COM_OF_LOSS_T": 0.5})  # fmt: skip
    with ThreadedEmulator(opts) as host:
        port = free_udp_ports(1)[0]  # chosen after the emulator bound its own ports
        host.retarget(0, port)
        ap = host.vehicles[0]

        async def scenario() -> None:
            v = MavsdkVehicle(config(port, lease_s=1.0), SafetyConfig(), "uav0")
            await v.start()
            try:
                assert v.refused is None, v.problems
                await v.arm()
                await v.takeoff(4.0)
                await until(lambda: v.in_air and ap.alt >= 3.99, 10, "take-off")
                await v.set_velocity(2.0, 0.0, 0.0)
                assert ap.mode == "OFFBOARD"
                time.sleep(1.5)  # noqa: ASYNC251 - the stall under test
                assert v.watchdog_holds == 1
                assert ap.mode == "AUTO.LOITER"
                assert not any("offboard loss" in e for _t, e in ap.events)  # MAVSDK kept sending
            finally:
                await v.aclose()

        asyncio.run(scenario())


def test_signing_is_refused_with_a_clear_reason() -> None:
    with pytest.raises(VehicleError, match="MAVSDK cannot sign MAVLink 2"):
        MavsdkVehicle(config(14540, signing_key="/tmp/k"), SafetyConfig(), "uav0")
