"""Flight phases of one UAV, driven through the Vehicle port (DESIGN §12).

preflight checks -> arm -> take off to mission altitude -> offboard/guided velocity control
(zero setpoint first, then the mode: MAVSDK's offboard example) -> mission -> land or
return at mission end or operator stop. Aerostack2's platform contract is the model: the
daemon asks for arming, offboard control and commands; the backend knows how.

``FlightPhases`` wraps the backend and is itself a Vehicle, so the decision round needs no
change: motion is forwarded only in the MISSION phase with a healthy link, and every
backend error becomes a hold of this UAV. Rules it enforces whatever the agent picks:

* at start-up the vehicle's state is read first; found in the air (a restarted daemon),
  it never arms or takes off: RECOVERING -> hold -> mission, with fresh decisions only;
* link loss or stale telemetry -> DEGRADED, no new motion; when the link is back the first
  command is a hold (or the configured land/return), never the motion from before the loss;
* vehicle actions (take off, land, return home) chosen by a skill pass an approval
  predicate first; take-off needs operator approval (seam: ``approve``), land and return
  never do (docs/notes/safety.md).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Literal

import msgspec

from aeroweaver_edge.contracts.actions import VehicleAction
from aeroweaver_edge.contracts.observation import VehicleState
from aeroweaver_edge.contracts.ports import Health, Vehicle
from aeroweaver_edge.contracts.wire import MAX_POINTS, Entity, VehicleStatus

log = logging.getLogger(__name__)
ALTITUDE_TOLERANCE_M = 0.3
FINISH_TIMEOUT_S = 10.0


class Phase(StrEnum):
    GROUND = "ground"  # not launched (no mission yet)
    RECOVERING = "recovering"  # found in the air at start-up
    PREFLIGHT = "preflight"
    ARMING = "arming"
    TAKING_OFF = "taking_off"
    OFFBOARD = "offboard"
    MISSION = "mission"
    DEGRADED = "degraded"  # link lost or telemetry stale: no new motion
    LANDING = "landing"
    RETURNING = "returning"
    REFUSED = "refused"  # preflight or launch failed: stays on the ground, holds


ApprovalPredicate = Callable[[str, VehicleAction], bool]
"""``approve(uav, action)``: may this vehicle action run now? The operator-approval gate
plugs in here; it is consulted before every skill-chosen vehicle action."""


def default_approval(uav: str, action: VehicleAction) -> bool:
    """Land and return home never need approval; take-off waits for an operator gate."""
    return action.kind in ("land", "return_home")


@dataclass
class PhaseStats:
    transitions: list[tuple[float, str, str]] = field(default_factory=list)  # (t, phase, why)
    refused_motion: Counter[str] = field(default_factory=Counter)
    errors: Counter[str] = field(default_factory=Counter)


class FlightPhases:
    """The phase machine, wrapping one backend; serves the Vehicle port."""

    def __init__(
        self,
        vehicle: Vehicle,
        *,
        uav: str,
        altitude_m: float,
        end_action: Literal["land", "return"] = "land",
        on_link_loss: Literal["failsafe", "land", "return"] = "failsafe",
        takeoff_timeout_s: float = 60.0,
        approve: ApprovalPredicate = default_approval,
        poll_s: float = 0.05,
        gate_launch: bool = False,
    ) -> None:
        self.inner = vehicle
        self.uav = uav
        self.altitude_m = altitude_m
        self.end_action = end_action
        self.on_link_loss = on_link_loss
        self.takeoff_timeout_s = takeoff_timeout_s
        self.approve = approve
        self.poll_s = poll_s
        # The mission's own launch (arm + take-off) passes ``approve`` too (approval level
        # strict); otherwise only skill-chosen vehicle actions do.
        self.gate_launch = gate_launch
        self.phase = Phase.GROUND
        self.stats = PhaseStats()
        self._lock = asyncio.Lock()

    def _to(self, phase: Phase, why: str) -> None:
        if phase != self.phase:
            log.info("%s: flight phase %s -> %s (%s)", self.uav, self.phase, phase, why)
            self.phase = phase
            self.stats.transitions.append((time.monotonic(), phase.value, why))

    @property
    def flying(self) -> bool:
        return self.phase in (Phase.MISSION, Phase.DEGRADED, Phase.OFFBOARD, Phase.RECOVERING)

    # -- launch and finish ----------------------------------------------------------------

    async def launch(self, *, approved: bool = False) -> bool:
        """Bring the vehicle into the MISSION phase once; True when it is there.
        ``approved``: the take-off already passed the approval check (a skill's action)."""
        async with self._lock:
            if self.phase in (Phase.LANDING, Phase.RETURNING) and not await self._airborne():
                self._to(Phase.GROUND, "landed; ready for the next mission")
            if self.phase != Phase.GROUND:
                return self._in_mission()
            try:
                await self._launch(approved or not self.gate_launch)
            except Exception as exc:  # never let a launch problem end the daemon
                self.stats.errors[type(exc).__name__] += 1
                log.error("%s: launch failed: %s", self.uav, exc)
                self._to(Phase.REFUSED, str(exc))
                await self._safe_hold()
            return self._in_mission()

    def _in_mission(self) -> bool:
        return self.phase == Phase.MISSION

    async def _airborne(self) -> bool:
        try:
            return (await self.inner.state()).in_air
        except Exception:
            return True  # unknown: assume the worst, do not relaunch

    async def _launch(self, approved: bool) -> None:
        st = await self.inner.state()
        if st.in_air:
            # A restarted daemon: never arm or take off; hold, then fresh decisions only.
            self._to(Phase.RECOVERING, "vehicle already in the air at start-up")
            await self.inner.hold()
            self._to(Phase.MISSION, "recovered in the air")
            return
        if not approved and not self.approve(self.uav, VehicleAction("takeoff")):
            await self._safe_hold()  # on the ground until an operator approves the take-off
            return
        self._to(Phase.PREFLIGHT, "mission assigned")
        health = await self.inner.health()
        if not health.ok:
            self._to(Phase.REFUSED, f"preflight: {health.detail}")
            return
        self._to(Phase.ARMING, "preflight ok")
        await self.inner.arm()
        self._to(Phase.TAKING_OFF, f"armed; climbing to {self.altitude_m:g} m")
        await self.inner.takeoff(self.altitude_m)
        await self._wait_altitude()
        self._to(Phase.OFFBOARD, "at mission altitude")
        await self.inner.set_velocity(0.0, 0.0, 0.0)  # zero setpoint, then offboard/guided
        self._to(Phase.MISSION, "offboard control")

    async def _wait_altitude(self) -> None:
        deadline = time.monotonic() + self.takeoff_timeout_s
        while True:
            st = await self.inner.state()
            if st.in_air and -st.pos[2] >= self.altitude_m - ALTITUDE_TOLERANCE_M:
                return
            if time.monotonic() > deadline:
                raise TimeoutError(
                    f"take-off to {self.altitude_m:g} m not reached in {self.takeoff_timeout_s:g} s"
                )
            await asyncio.sleep(self.poll_s)

    async def finish(self, why: str) -> None:
        """Mission end or operator stop: land or return if flying, else just hold."""
        async with self._lock:
            try:
                async with asyncio.timeout(FINISH_TIMEOUT_S):
                    if self.flying:
                        await self._end(self.end_action, why)
                    else:
                        await self._safe_hold()
            except Exception as exc:
                self.stats.errors[type(exc).__name__] += 1
                log.error("%s: %s on %s failed: %s", self.uav, self.end_action, why, exc)

    async def _end(self, action: Literal["land", "return"], why: str) -> None:
        if action == "return":
            self._to(Phase.RETURNING, why)
            await self.inner.return_home()
        else:
            self._to(Phase.LANDING, why)
            await self.inner.land()

    async def _safe_hold(self) -> None:
        try:
            await self.inner.hold()
        except Exception as exc:
            self.stats.errors[type(exc).__name__] += 1
            log.warning("%s: hold failed: %s", self.uav, exc)

    # -- link supervision ----------------------------------------------------------------

    async def _motion_allowed(self) -> bool:
        """Check health; manage DEGRADED and recovery. True if motion may go out now."""
        if self.phase not in (Phase.MISSION, Phase.DEGRADED):
            self.stats.refused_motion[self.phase.value] += 1
            return False
        health: Health = await self.inner.health()
        if not health.ok:
            if self.phase == Phase.MISSION:
                self._to(Phase.DEGRADED, health.detail)
            self.stats.refused_motion["degraded"] += 1
            return False
        if self.phase == Phase.DEGRADED:
            # Back from a loss: never resume the old motion; hold (or land/return) first.
            if self.on_link_loss in ("land", "return"):
                await self._end("land" if self.on_link_loss == "land" else "return", "link back")
            else:
                self._to(Phase.MISSION, "link back; holding before any new motion")
                await self._safe_hold()
            self.stats.refused_motion["recovery"] += 1
            return False
        return True

    def status(self, points: Sequence[Entity] = ()) -> VehicleStatus | None:
        """What the backend's link reports (mode, armed, battery...) with this phase and the
        known ``points``, for the round report; None when the backend reports nothing."""
        read = getattr(self.inner, "telemetry", None)
        try:
            st = read() if read is not None else None
        except Exception:  # telemetry for observers must never cost a round
            return None
        if not isinstance(st, VehicleStatus):
            return None
        return msgspec.structs.replace(st, phase=self.phase.value, points=list(points)[:MAX_POINTS])

    # -- the Vehicle port ----------------------------------------------------------------

    async def state(self) -> VehicleState:
        return await self.inner.state()

    async def health(self) -> Health:
        h = await self.inner.health()
        return Health(h.ok and self.phase == Phase.MISSION, f"{self.phase.value}: {h.detail}")

    async def arm(self) -> None:
        await self.launch()

    async def takeoff(self, altitude_m: float) -> None:
        await self.launch()

    async def set_velocity(self, north: float, east: float, down: float) -> None:
        if not await self._motion_allowed():
            await self._safe_hold()
            return
        try:
            await self.inner.set_velocity(north, east, down)
        except Exception as exc:
            self.stats.errors[type(exc).__name__] += 1
            log.warning("%s: velocity refused (%s); holding", self.uav, exc)
            await self._safe_hold()

    async def goto(self, north: float, east: float, down: float) -> None:
        if not await self._motion_allowed():
            await self._safe_hold()
            return
        try:
            await self.inner.goto(north, east, down)
        except Exception as exc:
            self.stats.errors[type(exc).__name__] += 1
            log.warning("%s: goto refused (%s); holding", self.uav, exc)
            await self._safe_hold()

    async def hold(self) -> None:
        await self._safe_hold()

    async def land(self) -> None:
        await self._end("land", "commanded")

    async def return_home(self) -> None:
        await self._end("return", "commanded")

    # -- skill-chosen vehicle actions --------------------------------------------------

    async def act(self, action: VehicleAction) -> str | None:
        """Carry out a vehicle action a skill chose; None when done, else why it was not."""
        if not self.approve(self.uav, action):
            return f"{action.kind} needs operator approval"
        try:
            if action.kind == "takeoff":
                if self.phase != Phase.GROUND:
                    return f"take-off refused in phase {self.phase.value}"
                if action.altitude_m is not None:
                    self.altitude_m = action.altitude_m
                launched = await self.launch(approved=True)
                return None if launched else f"take-off failed ({self.phase.value})"
            if not self.flying:
                return f"{action.kind} refused in phase {self.phase.value}"
            await self._end("land" if action.kind == "land" else "return", "skill")
        except Exception as exc:
            self.stats.errors[type(exc).__name__] += 1
            return f"{action.kind} failed: {exc}"
        return None
