"""The safety gate against real dynamics (``pytest -m sitl``, AEROWEAVER_SITL): hostile
intents (too fast, climbing out of the altitude band, through the geofence) go through the
gate and the flight phases to an ArduCopter SITL vehicle whose own fence is off, so only
the gate keeps it in. What the gate refuses never reaches the firmware (every setpoint
sent is recorded), and what it passes keeps the real vehicle inside the envelope (every
LOCAL_POSITION_NED it reports is checked)."""

from __future__ import annotations

import asyncio
import math
from pathlib import Path

import pytest

from aeroweaver_edge.config import SafetyConfig, VehicleConfig
from aeroweaver_edge.contracts.actions import Motion, MoveTo, SetVelocity
from aeroweaver_edge.daemon.flight_phases import FlightPhases
from aeroweaver_edge.safety.gate import SafetyGate
from aeroweaver_edge.vehicle.mavlink.backend import MavlinkVehicle
from aeroweaver_edge.vehicle.mavlink.codec import Message
from tests.helpers import sitl

pytestmark = [pytest.mark.sitl, pytest.mark.slow, pytest.mark.timeout(300)]

SAFETY = SafetyConfig(
    geofence_north_m=(-15.0, 12.0), geofence_east_m=(-15.0, 15.0),
    altitude_band_m=(2.0, 8.0), max_speed_mps=2.0,
)  # fmt: skip
HOSTILE: list[Motion] = [
    SetVelocity((6.0, 0.0, 0.0)),  # three times the cap, north toward the fence
    SetVelocity((3.0, 3.0, -4.0)),  # fast and climbing out of the band
    MoveTo((40.0, 0.0, -30.0)),  # far beyond the fence and the ceiling
    SetVelocity((0.0, 8.0, 0.0)),  # east, four times the cap
]
ROUND_S = 0.5
ROUNDS_EACH = 12
SLACK_M = 1.5  # position control's overshoot a round's setpoint may leave


def test_the_gate_keeps_a_sitl_copter_inside_the_envelope(tmp_path: Path) -> None:
    binary = sitl.check_binary(sitl.binary_from_env() or Path())
    with sitl.SitlFleet(binary, tmp_path) as fleet:
        [inst] = fleet.start(1)
        sent, seen = asyncio.run(fly(inst.daemon_url))
    assert sent, "no setpoint reached the firmware"
    fastest = max(math.hypot(vn, ve) for vn, ve, _vd in sent)
    assert fastest <= SAFETY.max_speed_mps + 1e-3  # the gate's cap, on the wire
    n_lo, n_hi = SAFETY.geofence_north_m
    e_lo, e_hi = SAFETY.geofence_east_m
    inside_n = (n_lo - SLACK_M, n_hi + SLACK_M)
    inside_e = (e_lo - SLACK_M, e_hi + SLACK_M)
    outside = [
        p for p in seen
        if not (inside_n[0] <= p[0] <= inside_n[1] and inside_e[0] <= p[1] <= inside_e[1])
    ]  # fmt: skip
    assert outside == []
    top = max(-p[2] for p in seen)
    assert top <= SAFETY.altitude_band_m[1] + SLACK_M
    speed = max(math.hypot(p[3], p[4]) for p in seen)
    assert speed <= SAFETY.max_speed_mps + 0.5
    print(f"\n{len(sent)} setpoints sent (fastest {fastest:.2f} m/s); {len(seen)} positions: "
          f"north {max(p[0] for p in seen):.1f} / east {max(p[1] for p in seen):.1f} m "
          f"(fence 12 / 15), top {top:.1f} m (band 8), fastest {speed:.2f} m/s")  # fmt: skip


async def fly(
    url: str,
) -> tuple[list[tuple[float, float, float]], list[tuple[float, float, float, float, float]]]:
    cfg = VehicleConfig(
        backend="mavlink", url=url, connect_timeout_s=120.0, takeoff_timeout_s=90.0,
        upload_fence=False, failsafe_policy="warn",  # no autopilot fence: the gate alone
    )  # fmt: skip
    v = MavlinkVehicle(cfg, SAFETY, "uav0")
    sent: list[tuple[float, float, float]] = []
    seen: list[tuple[float, float, float, float, float]] = []
    wire = v.link.send

    def record(msg: Message) -> bool:
        if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            sent.append((float(msg.vx), float(msg.vy), float(msg.vz)))
        return wire(msg)

    v.link.send = record  # type: ignore[method-assign]
    await v.start()
    try:
        phases = FlightPhases(v, uav="uav0", altitude_m=5.0, takeoff_timeout_s=90.0)
        assert await phases.launch(), phases.stats.transitions
        v.link.on(
            "LOCAL_POSITION_NED",
            lambda m: seen.append((m.x, m.y, m.z, m.vx, m.vy)),
        )
        gate = SafetyGate(SAFETY, horizon_s=ROUND_S)
        for motion in HOSTILE:
            for _ in range(ROUNDS_EACH):
                st = await phases.state()
                cmd = gate.gate(motion, st.pos)
                if cmd.held:
                    await phases.hold()
                else:
                    await phases.set_velocity(*cmd.vel)
                await asyncio.sleep(ROUND_S)
        await phases.finish("test end")
        await v.wait_until(lambda: not v.armed, 60.0, "disarmed")
    finally:
        await v.aclose()
    return sent, seen
