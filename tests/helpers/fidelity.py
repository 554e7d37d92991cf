"""Firmware fidelity: the same MAVLink command sequences ("cases") flown against ArduCopter
SITL (recorded once, committed as fixtures under ``tests/fixtures/sitl/``) and against the
emulator's ArduPilot personality (in CI), reduced to what a client can rely on and compared.

A case talks through the product's own link layer (``FlightLink``, ``CommandClient``,
``ParamClient``) as the companion computer (the vehicle's system id, component 191) and
records what came back: modes and armed state from HEARTBEAT, every COMMAND_ACK, every
STATUSTEXT, landed states, and named marks (``mark``) whose spacing the comparison bounds.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aeroweaver_edge.contracts.endpoints import UdpUrl
from aeroweaver_edge.vehicle.mavlink.codec import Message, mavlink
from aeroweaver_edge.vehicle.mavlink.commands import RESULT_NAMES, CommandClient, command_name
from aeroweaver_edge.vehicle.mavlink.fence import rectangle, upload_fence
from aeroweaver_edge.vehicle.mavlink.geo import GeoOrigin
from aeroweaver_edge.vehicle.mavlink.link import FlightLink
from aeroweaver_edge.vehicle.mavlink.params import ParamClient
from aeroweaver_edge.vehicle.mavlink.personality import (
    POSITION_ONLY,
    VELOCITY_ONLY,
    ArduPilot,
)

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "sitl"
ARMED = mavlink.MAV_MODE_FLAG_SAFETY_ARMED
PREARM = mavlink.MAV_SYS_STATUS_PREARM_CHECK
LANDED = {
    0: "UNDEFINED",
    1: "ON_GROUND",
    2: "IN_AIR",
    3: "TAKEOFF",
    4: "LANDING",
}


class CaseFailed(RuntimeError):
    """A step of a case did not happen in time (the vehicle is not where the case needs)."""


@dataclass
class Trace:
    case: str
    target: str  # "sitl" or "emulator"
    events: list[tuple[float, str, str]] = field(default_factory=list)  # (t, kind, value)
    marks: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "case": self.case,
            "target": self.target,
            "events": [[round(t, 3), k, v] for t, k, v in self.events],
            "marks": {k: round(v, 3) for k, v in self.marks.items()},
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Trace:
        return cls(
            data["case"],
            data["target"],
            [(float(t), str(k), str(v)) for t, k, v in data["events"]],
            {str(k): float(v) for k, v in data["marks"].items()},
        )

    def values(self, kind: str) -> list[str]:
        """The ``kind`` values in order, consecutive repeats folded."""
        out: list[str] = []
        for _t, k, v in self.events:
            if k == kind and (not out or out[-1] != v):
                out.append(v)
        return out


class Driver:
    """One vehicle as a case sees it; records into ``trace`` from ``start``."""

    def __init__(self, link: FlightLink, trace: Trace) -> None:
        self.link = link
        self.commands = CommandClient(link, timeout_s=1.0, retries=3)
        self.params = ParamClient(link, ArduPilot(), timeout_s=1.0)
        self.trace = trace
        self.p = ArduPilot()
        self.t0 = time.monotonic()
        self._last_hb: tuple[str, bool] | None = None
        self._stream: asyncio.Task[None] | None = None
        self.prearm_ok = False
        for kind in ("HEARTBEAT", "COMMAND_ACK", "STATUSTEXT", "EXTENDED_SYS_STATE", "SYS_STATUS"):
            link.on(kind, self._on)

    def now(self) -> float:
        return time.monotonic() - self.t0

    def restart(self, trace: Trace) -> None:
        self.trace, self.t0, self._last_hb = trace, time.monotonic(), None

    def _on(self, msg: Message) -> None:
        kind = msg.get_type()
        t = self.now()
        if kind == "HEARTBEAT":
            state = (self.p.mode_name(int(msg.custom_mode)), bool(msg.base_mode & ARMED))
            if state != self._last_hb:
                self._last_hb = state
                self.trace.events.append((t, "mode", state[0]))
                self.trace.events.append((t, "armed", str(state[1])))
        elif kind == "COMMAND_ACK":
            if int(msg.command) == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
                return
            result = RESULT_NAMES.get(int(msg.result), str(msg.result))
            self.trace.events.append((t, "ack", f"{command_name(int(msg.command))} {result}"))
        elif kind == "STATUSTEXT":
            self.trace.events.append((t, "text", str(msg.text).rstrip("\x00")))
        elif kind == "EXTENDED_SYS_STATE":
            landed = LANDED.get(int(msg.landed_state), str(msg.landed_state))
            if not self.trace.events or self.trace.values("landed")[-1:] != [landed]:
                self.trace.events.append((t, "landed", landed))
        elif kind == "SYS_STATUS":
            self.prearm_ok = bool(msg.onboard_control_sensors_health & PREARM)

    def mark(self, name: str) -> None:
        self.trace.marks[name] = self.now()

    # -- state -----------------------------------------------------------------------------

    @property
    def mode(self) -> str:
        return self._last_hb[0] if self._last_hb else "?"

    @property
    def armed(self) -> bool:
        return bool(self._last_hb and self._last_hb[1])

    @property
    def pos(self) -> tuple[float, float, float]:
        loc = self.link.last.get("LOCAL_POSITION_NED")
        return (0.0, 0.0, 0.0) if loc is None else (float(loc.x), float(loc.y), float(loc.z))

    @property
    def speed(self) -> float:
        loc = self.link.last.get("LOCAL_POSITION_NED")
        return 0.0 if loc is None else math.hypot(float(loc.vx), float(loc.vy))

    async def ask_telemetry(self) -> None:
        """The same message intervals the daemon's backend asks for."""
        from aeroweaver_edge.vehicle.mavlink.backend import TELEMETRY

        for msg_id, interval in TELEMETRY.items():
            await self.commands.send(
                mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, float(msg_id), float(interval), check=False
            )

    async def wait(self, cond: Callable[[], bool], timeout_s: float, what: str) -> float:
        started = time.monotonic()
        while not cond():
            if time.monotonic() - started > timeout_s:
                raise CaseFailed(f"{self.trace.case}: {what} not within {timeout_s:g} s")
            await asyncio.sleep(0.02)
        return time.monotonic() - started

    # -- commands --------------------------------------------------------------------------

    async def set_mode(self, mode: str) -> int:
        p1, p2, p3 = self.p.set_mode_params(mode, self.armed)
        return await self.commands.send(mavlink.MAV_CMD_DO_SET_MODE, p1, p2, p3, check=False)

    async def arm(self) -> int:
        return await self.commands.send(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, check=False)

    async def takeoff(self, alt: float) -> int:
        nan = math.nan
        return await self.commands.send(
            mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, alt, check=False
        )

    async def set_param(self, name: str, value: float) -> float:
        return await self.params.set(name, value)

    async def fence(self, north: tuple[float, float], east: tuple[float, float]) -> None:
        last = self.link.last
        await self.wait(
            lambda: "GLOBAL_POSITION_INT" in last and "LOCAL_POSITION_NED" in last,
            120,
            "a position to anchor the fence",
        )
        g, loc = last["GLOBAL_POSITION_INT"], last["LOCAL_POSITION_NED"]
        probe = GeoOrigin(g.lat / 1e7, g.lon / 1e7, g.alt / 1000.0)
        origin = GeoOrigin(*probe.to_global(-loc.x, -loc.y, -loc.z))
        await upload_fence(self.link, rectangle(origin, north, east), timeout_s=1.0)

    def _send_target(self, mask: int, n: float, e: float, d: float) -> None:
        sysid, compid = self.link.target
        pos, vel = ((n, e, d), (0.0, 0.0, 0.0)) if mask == POSITION_ONLY else ((0, 0, 0), (n, e, d))
        self.link.send(
            self.link.mav.set_position_target_local_ned_encode(
                int(self.now() * 1000), sysid, compid, mavlink.MAV_FRAME_LOCAL_NED, mask,
                *pos, *vel, 0.0, 0.0, 0.0, 0.0, 0.0,
            )
        )  # fmt: skip

    async def stream(self, kind: str, n: float, e: float, d: float, seconds: float) -> None:
        """Send a velocity or position target at 10 Hz for ``seconds``, then stop."""
        mask = VELOCITY_ONLY if kind == "velocity" else POSITION_ONLY
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self._send_target(mask, n, e, d)
            await asyncio.sleep(0.1)

    def silence(self) -> None:
        """The companion stops: no heartbeat, nothing else (a SIGKILLed daemon)."""
        for task in self.link._tasks[:1]:  # the heartbeat loop
            task.cancel()

    def resume(self) -> None:
        """Heartbeats again (the GCS failsafe clears; arming is refused while it is on)."""
        self.link._tasks[0] = asyncio.create_task(self.link._heartbeat_loop())

    @property
    def landed(self) -> str:
        ext = self.link.last.get("EXTENDED_SYS_STATE")
        return "?" if ext is None else LANDED.get(int(ext.landed_state), "?")

    async def take_off(self, alt: float = 5.0) -> None:
        """GUIDED, arm, NAV_TAKEOFF; done when at ``alt`` and the take-off is complete
        (landed state IN_AIR), as a careful client waits."""
        await self.wait(lambda: "LOCAL_POSITION_NED" in self.link.last, 120, "a position")
        await self.wait(lambda: self.landed == "ON_GROUND", 30, "landed state ON_GROUND")
        await self.wait(lambda: self.prearm_ok, 120, "pre-arm checks passed")
        await self.set_mode("GUIDED")
        await self.wait(lambda: self.mode == "GUIDED", 5, "GUIDED")
        if await self.arm() != mavlink.MAV_RESULT_ACCEPTED:
            await asyncio.sleep(0.5)  # the reason's STATUSTEXT follows the ACK
            raise CaseFailed(f"{self.trace.case}: arming refused")
        await self.wait(lambda: self.armed, 5, "armed")
        await self.takeoff(alt)
        await self.wait(lambda: -self.pos[2] >= alt - 0.3, 60, f"{alt:g} m")
        await self.wait(lambda: self.landed == "IN_AIR", 30, "take-off complete (IN_AIR)")
        self.mark("at_altitude")

    async def down(self, timeout_s: float = 90.0) -> None:
        """Wait until disarmed on the ground (a case ends there)."""
        await self.wait(lambda: not self.armed, timeout_s, "disarmed")
        self.mark("disarmed")
        await self.wait(lambda: self.landed == "ON_GROUND", 5, "landed state ON_GROUND")


Case = Callable[[Driver], Awaitable[None]]


async def arm_refused_before_ekf(d: Driver) -> None:
    """At power-on, before GPS and EKF are ready: GUIDED and arming are both refused."""
    await d.set_mode("GUIDED")
    await d.arm()
    await asyncio.sleep(1.0)
    d.mark("refused")


async def guided_takeoff_and_land(d: Driver) -> None:
    await d.take_off(5.0)
    await d.set_mode("LAND")
    d.mark("land")
    await d.down()


async def velocity_target_expires(d: Driver) -> None:
    """A velocity target flies; when the stream stops, Copter stops after GUID_TIMEOUT and
    stays in GUIDED."""
    await d.take_off(5.0)
    await d.stream("velocity", 2.0, 0.0, 0.0, 3.0)
    d.mark("stream_stopped")
    await d.wait(lambda: d.speed < 0.3, 15, "stopped")
    d.mark("stopped")
    d.trace.events.append((d.now(), "mode_after_stop", d.mode))
    await d.set_mode("LAND")
    await d.down()


async def position_target_holds(d: Driver) -> None:
    """A position target (one message) 8 m away is flown to and held in GUIDED."""
    await d.wait(lambda: "LOCAL_POSITION_NED" in d.link.last, 120, "a position")
    n0, e0, _ = d.pos

    def near() -> bool:
        return math.hypot(d.pos[0] - n0 - 8.0, d.pos[1] - e0) < 1.0

    await d.take_off(5.0)
    await d.stream("position", n0 + 8.0, e0, -5.0, 0.3)
    d.mark("target_sent")
    await d.wait(near, 30, "at the target")
    d.mark("at_target")
    await asyncio.sleep(4.0)  # no more targets: it stays there, in GUIDED
    d.trace.events.append((d.now(), "mode_after_hold", d.mode))
    d.trace.events.append((d.now(), "held_within_1m", str(near())))
    await d.set_mode("LAND")
    await d.down()


async def companion_loss_lands(d: Driver) -> None:
    """The companion (GCS of record) falls silent: FS_GCS_ENABLE 5 lands after FS_GCS_TIMEOUT."""
    assert d.link.sysid is not None
    for name, value in (
        ("MAV_GCS_SYSID", d.link.sysid),
        ("FS_GCS_ENABLE", 5),
        ("FS_GCS_TIMEOUT", 3),
    ):
        await d.set_param(name, value)
    await d.take_off(5.0)
    await asyncio.sleep(1.5)  # a heartbeat in the air
    d.silence()
    d.mark("silenced")
    try:
        await d.wait(lambda: d.mode != "GUIDED", 15, "the failsafe's mode")
        d.mark("failsafe_mode")
        await d.down()
    finally:
        d.resume()
        await d.set_param("FS_GCS_ENABLE", 0)
    await asyncio.sleep(2.0)  # heard again: "GCS Failsafe Cleared"


async def fence_breach_returns(d: Driver) -> None:
    """A polygon fence 8 m north of home. In GUIDED ArduCopter never flies through it: a
    velocity target north stops short (its fence avoidance, AVOID_ENABLE, FENCE_MARGIN 2 m)
    and a position target beyond it is ignored. A fence moved in flight to behind the
    vehicle is a breach: FENCE_ACTION 1 returns (RTL) and lands."""
    await d.set_param("FENCE_ENABLE", 0)
    await d.wait(lambda: "LOCAL_POSITION_NED" in d.link.last, 120, "a position")
    n0, e0, _ = d.pos  # where the vehicle stands (an earlier case may have landed it away)
    await d.fence((n0 - 20.0, n0 + 8.0), (e0 - 20.0, e0 + 20.0))
    await d.set_param("FENCE_ACTION", 1)
    await d.set_param("FENCE_ENABLE", 1)
    try:
        await d.take_off(5.0)
        await d.stream("velocity", 3.0, 0.0, 0.0, 6.0)
        d.trace.events.append((d.now(), "velocity_stopped_inside", str(d.pos[0] < n0 + 8.0)))
        await d.stream("position", n0 + 20.0, e0, -5.0, 0.3)
        await asyncio.sleep(3.0)
        d.trace.events.append((d.now(), "target_beyond_ignored", str(d.pos[0] < n0 + 8.0)))
        d.trace.events.append((d.now(), "mode_after_push", d.mode))
        await d.fence((n0 - 20.0, n0 + 2.0), (e0 - 20.0, e0 + 20.0))  # the vehicle is outside
        d.mark("fence_moved")
        await d.wait(lambda: d.mode != "GUIDED", 20, "the fence's mode")
        d.mark("breach_mode")
        await d.down(120.0)
    finally:
        await d.set_param("FENCE_ENABLE", 0)


async def rtl_returns_and_lands(d: Driver) -> None:
    """RTL from 8 m away: back to home (where it armed), down, disarmed."""
    await d.wait(lambda: "LOCAL_POSITION_NED" in d.link.last, 120, "a position")
    n0, e0, _ = d.pos
    await d.take_off(5.0)
    await d.stream("position", n0 + 8.0, e0, -5.0, 0.3)
    await d.wait(lambda: math.hypot(d.pos[0] - n0 - 8.0, d.pos[1] - e0) < 1.0, 30, "8 m away")
    await d.set_mode("RTL")
    d.mark("rtl")
    await d.down(120.0)
    home = math.hypot(d.pos[0] - n0, d.pos[1] - e0) < 2.0
    d.trace.events.append((d.now(), "landed_near_home", str(home)))


CASES: dict[str, Case] = {
    "arm_refused_before_ekf": arm_refused_before_ekf,
    "guided_takeoff_and_land": guided_takeoff_and_land,
    "velocity_target_expires": velocity_target_expires,
    "position_target_holds": position_target_holds,
    "fence_breach_returns": fence_breach_returns,
    "rtl_returns_and_lands": rtl_returns_and_lands,
    "companion_loss_lands": companion_loss_lands,
}


async def fly_cases(url: str, target: str, names: list[str]) -> list[Trace]:
    """Connect as the companion and run ``names`` in order on one vehicle."""
    link = FlightLink(UdpUrl.parse(url), link_timeout_s=5.0)
    await link.open()
    traces: list[Trace] = []
    try:
        trace = Trace(names[0], target)
        d = Driver(link, trace)
        await link.connect(60.0)
        await d.ask_telemetry()
        for name in names:
            trace = Trace(name, target)
            d.restart(trace)
            try:
                await CASES[name](d)
            except CaseFailed as exc:
                texts = [v for _t, k, v in trace.events if k == "text"][-5:]
                raise CaseFailed(f"{exc}; last texts: {texts}") from None
            traces.append(trace)
    finally:
        await link.aclose()
    return traces


def save(traces: list[Trace], directory: Path = FIXTURES) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    for t in traces:
        path = directory / f"{t.case}.json"
        path.write_text(json.dumps(t.to_json(), indent=1) + "\n")


def load(case: str, directory: Path = FIXTURES) -> Trace:
    return Trace.from_json(json.loads((directory / f"{case}.json").read_text()))


# the texts compared: arming, failsafes, fences, mode refusals (not EKF/GPS start-up chatter)
TEXT_KEEP = re.compile(r"^Arm:|motors|fence|Failsafe|GCS|Mode change|RTL|Land", re.I)
