"""The autopilot's own failsafe for losing its companion computer: set and verified at
preflight, before the daemon may arm.

A daemon that dies (SIGKILL, out of memory) or stops (SIGSTOP, a hung loop) commands
nothing any more; only the autopilot can then bring the vehicle down. So the daemon makes
the autopilot act on the daemon's own silence, and refuses to arm when it cannot:

* ArduPilot (Copter): the daemon becomes the GCS of record. ``MAV_GCS_SYSID``
  (``SYSID_MYGCS`` before 4.7) is set to the vehicle's own system id, so the companion's
  heartbeats (that system id, component 191) are the ones the GCS failsafe watches
  (``GCS_MAVLINK::handle_heartbeat``); ``FS_GCS_ENABLE`` lands (5) or returns (1);
  ``FS_GCS_TIMEOUT`` is the bound. ArduCopter only arms this failsafe once it has heard its
  GCS, which the daemon's 1 Hz heartbeat guarantees before arming.
* PX4: the setpoint stream is the daemon's pulse. ``COM_OF_LOSS_T`` is the bound and
  ``COM_OBL_RC_ACT`` lands (4) or returns (3); Hold (5) would hover until the battery runs out.

``vehicle.companion_failsafe = "check"`` writes nothing and only verifies (for an autopilot
configured by its owner); ``land`` / ``return`` write what differs and read it back.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Literal, Protocol

from aeroweaver_edge.vehicle.errors import VehicleError
from aeroweaver_edge.vehicle.mavlink.link import LinkError

log = logging.getLogger(__name__)

CompanionAction = Literal["land", "return", "check"]
TOLERANCE = 1e-3  # float32 on the wire
ARDUPILOT_GCS_SYSID = ("MAV_GCS_SYSID", "SYSID_MYGCS")  # renamed in ArduPilot 4.7
ARDUPILOT_ACTION = {"land": 5.0, "return": 1.0}  # FS_GCS_ENABLE
PX4_ACTION = {"land": 4.0, "return": 3.0}  # COM_OBL_RC_ACT
WHAT = {5.0: "lands", 1.0: "returns (RTL)", 4.0: "lands", 3.0: "returns (RTL)"}


class Params(Protocol):
    """Read and write parameters by name (``ParamClient``, or MAVSDK's through an adapter)."""

    async def get(self, name: str) -> float | None: ...

    async def set(self, name: str, value: float) -> float: ...


@dataclass(frozen=True)
class Setting:
    """One parameter of the failsafe: the names it may go by, the value written, and the
    values accepted as they are (``low``..``high`` when ``accepted`` is empty)."""

    names: tuple[str, ...]
    target: float
    accepted: tuple[float, ...] = ()
    low: float = 0.0
    high: float = 0.0
    why: str = ""

    def fits(self, value: float) -> bool:
        if self.accepted:
            return any(abs(value - a) < TOLERANCE for a in self.accepted)
        return self.low - TOLERANCE <= value <= self.high + TOLERANCE

    def wanted(self) -> str:
        if self.accepted:
            return " or ".join(f"{a:g}" for a in self.accepted)
        return f"{self.low:g}..{self.high:g}"


@dataclass
class FailsafeReport:
    """What the preflight found, set and could not set."""

    values: dict[str, float] = field(default_factory=dict)  # name -> value now on the vehicle
    changed: list[str] = field(default_factory=list)  # "FS_GCS_ENABLE 0 -> 5"
    problems: list[str] = field(default_factory=list)
    summary: str = ""  # what the autopilot does when the daemon falls silent

    @property
    def ok(self) -> bool:
        return not self.problems


def settings(
    autopilot: str, sysid: int, action: CompanionAction, timeout_s: float
) -> list[Setting]:
    """The parameters that make ``autopilot`` land or return ``timeout_s`` after the
    companion's last sign of life."""
    if autopilot == "ardupilot":
        acts = ARDUPILOT_ACTION
        return [
            Setting(ARDUPILOT_GCS_SYSID, float(sysid), (float(sysid),),
                    why="the daemon (same system id) is the GCS the failsafe watches"),
            Setting(("FS_GCS_ENABLE",), acts.get(action, acts["land"]),
                    tuple(acts.values()) if action == "check" else (acts[action],),
                    why="companion loss: land (5) or RTL (1)"),
            Setting(("FS_GCS_TIMEOUT",), timeout_s, low=2.0, high=timeout_s,
                    why="seconds of companion silence before the action"),
        ]  # fmt: skip
    acts = PX4_ACTION
    return [
        Setting(("COM_OF_LOSS_T",), min(1.0, timeout_s), low=0.1, high=timeout_s,
                why="seconds without setpoints before the action"),
        Setting(("COM_OBL_RC_ACT",), acts.get(action, acts["land"]),
                tuple(acts.values()) if action == "check" else (acts[action],),
                why="offboard loss: land (4) or return (3); hold would hover until the battery"),
    ]  # fmt: skip


async def _read(params: Params, names: tuple[str, ...]) -> tuple[str, float | None]:
    for name in names:
        value = await params.get(name)
        if value is not None:
            return name, value
    return names[0], None


async def configure(
    params: Params,
    autopilot: str,
    sysid: int,
    action: CompanionAction,
    timeout_s: float,
) -> FailsafeReport:
    """Read each setting, write what does not fit (unless ``check``), read the echo back."""
    rep = FailsafeReport()
    for s in settings(autopilot, sysid, action, timeout_s):
        name, value = await _read(params, s.names)
        if value is None:
            rep.problems.append(
                f"companion-loss failsafe: {' / '.join(s.names)} could not be read ({s.why})"
            )
            continue
        if s.fits(value):
            rep.values[name] = value
            continue
        if action == "check":
            rep.problems.append(
                f"companion-loss failsafe: {name}={value:g}, needs {s.wanted()} ({s.why})"
            )
            rep.values[name] = value
            continue
        try:
            echoed = await params.set(name, s.target)
        except (LinkError, VehicleError) as exc:
            rep.problems.append(f"companion-loss failsafe: cannot set {name}: {exc}")
            rep.values[name] = value
            continue
        rep.values[name] = echoed
        if not s.fits(echoed):
            rep.problems.append(
                f"companion-loss failsafe: {name} stays {echoed:g} after setting "
                f"{s.target:g} ({s.why})"
            )
            continue
        rep.changed.append(f"{name} {value:g} -> {echoed:g}")
    rep.summary = describe(autopilot, rep.values)
    return rep


def describe(autopilot: str, values: dict[str, float]) -> str:
    """One line: what the autopilot does when the daemon goes silent, from its values."""
    if autopilot == "ardupilot":
        act, after = values.get("FS_GCS_ENABLE"), values.get("FS_GCS_TIMEOUT")
        pulse = "heartbeat"
    else:
        act, after = values.get("COM_OBL_RC_ACT"), values.get("COM_OF_LOSS_T")
        pulse = "setpoint"
    if act is None or after is None:
        return "companion-loss failsafe unknown"
    what = WHAT.get(round(act, 3), f"acts ({act:g})")
    return f"the autopilot {what} {after:g} s after the daemon's last {pulse}"
