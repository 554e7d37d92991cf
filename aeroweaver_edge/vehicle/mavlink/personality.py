"""What differs between PX4 and ArduPilot (Copter): mode numbers, how each action is
commanded, how integer parameters travel, and which failsafe parameters to check.

Facts from docs/notes/mavlink.md and docs/notes/safety.md. Both the daemon's backend and the vehicle
emulator read these tables, so a wrong number here fails the MAVSDK conformance test, which
maps modes independently.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import ClassVar, Literal

from aeroweaver_edge.vehicle.mavlink.codec import mavlink

Role = Literal["hold", "offboard", "takeoff", "land", "rtl"]
"""The mode roles the daemon needs; each personality names one mode per role."""

PARAM_INT32 = mavlink.MAV_PARAM_TYPE_INT32
PARAM_REAL32 = mavlink.MAV_PARAM_TYPE_REAL32
VELOCITY_ONLY = 0x0DC7  # ignore position, acceleration, yaw and yaw rate: vx, vy, vz used
POSITION_ONLY = 0x0DF8  # ignore velocity, acceleration, yaw and yaw rate: x, y, z used


@dataclass(frozen=True)
class ParamRule:
    """An approved-profile rule for one parameter (values the daemon accepts)."""

    name: str
    allowed: tuple[float, ...] | None = None  # exact values; None: use the range
    low: float = -math.inf
    high: float = math.inf
    why: str = ""

    def check(self, value: float | None) -> str | None:
        """None when ``value`` fits; else a one-line reason."""
        if value is None:
            return f"{self.name} could not be read"
        if self.allowed is not None:
            if not any(abs(value - a) < 1e-6 for a in self.allowed):
                return f"{self.name}={value:g} not in {list(self.allowed)} ({self.why})"
            return None
        if not self.low <= value <= self.high:
            return f"{self.name}={value:g} outside [{self.low:g}, {self.high:g}] ({self.why})"
        return None


class Personality:
    """Base: subclasses fill the tables."""

    name: ClassVar[str]
    autopilot: ClassVar[int]
    modes: ClassVar[dict[str, int]]  # mode name -> custom_mode as sent in HEARTBEAT
    roles: ClassVar[dict[Role, str]]
    failsafe_rules: ClassVar[tuple[ParamRule, ...]]
    fence_action_param: ClassVar[str]

    def mode_name(self, custom_mode: int) -> str:
        for name, value in self.modes.items():
            if value == custom_mode:
                return name
        return f"UNKNOWN({custom_mode})"

    def role_of(self, custom_mode: int) -> Role | None:
        name = self.mode_name(custom_mode)
        for role, mode in self.roles.items():
            if mode == name:
                return role
        return None

    def set_mode_params(self, mode: str, armed: bool) -> tuple[float, float, float]:
        """DO_SET_MODE param1..3 for ``mode``."""
        raise NotImplementedError

    def mode_from_set_mode(self, p1: float, p2: float, p3: float) -> str | None:
        """The mode a DO_SET_MODE asks for (emulator side); None if unknown."""
        raise NotImplementedError

    # Parameters: PX4 sends an int's bytes inside the float; ArduPilot casts.
    def encode_param(self, value: float, ptype: int) -> float:
        raise NotImplementedError

    def decode_param(self, raw: float, ptype: int) -> float:
        raise NotImplementedError


class PX4(Personality):
    name = "px4"
    autopilot = mavlink.MAV_AUTOPILOT_PX4
    # custom_mode = main << 16 | sub << 24
    modes: ClassVar[dict[str, int]] = {
        name: (main << 16) | (sub << 24)
        for name, (main, sub) in {
            "MANUAL": (1, 0),
            "ALTCTL": (2, 0),
            "POSCTL": (3, 0),
            "AUTO.READY": (4, 1),
            "AUTO.TAKEOFF": (4, 2),
            "AUTO.LOITER": (4, 3),
            "AUTO.MISSION": (4, 4),
            "AUTO.RTL": (4, 5),
            "AUTO.LAND": (4, 6),
            "ACRO": (5, 0),
            "OFFBOARD": (6, 0),
            "STABILIZED": (7, 0),
        }.items()
    }
    roles: ClassVar[dict[Role, str]] = {
        "hold": "AUTO.LOITER",
        "offboard": "OFFBOARD",
        "takeoff": "AUTO.TAKEOFF",
        "land": "AUTO.LAND",
        "rtl": "AUTO.RTL",
    }
    # Offboard loss (COM_OF_LOSS_T, COM_OBL_RC_ACT) is the companion-loss failsafe, set and
    # checked by ``companion_failsafe``.
    failsafe_rules = (
        ParamRule(
            "GF_ACTION", allowed=(2.0, 3.0, 5.0), why="geofence breach: Hold, Return or Land"
        ),
    )
    fence_action_param = "GF_ACTION"

    def set_mode_params(self, mode: str, armed: bool) -> tuple[float, float, float]:
        cm = self.modes[mode]
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (
            mavlink.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0
        )
        return float(base), float((cm >> 16) & 0xFF), float((cm >> 24) & 0xFF)

    def mode_from_set_mode(self, p1: float, p2: float, p3: float) -> str | None:
        if not int(p1) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return None
        main, sub = int(p2), int(p3)
        if main == 4 and sub == 0:
            sub = 3  # AUTO without a sub mode: PX4 picks LOITER
        cm = (main << 16) | (sub << 24)
        name = self.mode_name(cm)
        return None if name.startswith("UNKNOWN") else name

    def encode_param(self, value: float, ptype: int) -> float:
        if ptype == PARAM_INT32:
            return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])
        return float(value)

    def decode_param(self, raw: float, ptype: int) -> float:
        if ptype == PARAM_INT32:
            return float(struct.unpack("<i", struct.pack("<f", raw))[0])
        return float(raw)


class ArduPilot(Personality):
    name = "ardupilot"
    autopilot = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    modes: ClassVar[dict[str, int]] = {
        "STABILIZE": 0,
        "ACRO": 1,
        "ALT_HOLD": 2,
        "AUTO": 3,
        "GUIDED": 4,
        "LOITER": 5,
        "RTL": 6,
        "CIRCLE": 7,
        "LAND": 9,
        "BRAKE": 17,
    }
    # Copter has no separate take-off mode: NAV_TAKEOFF runs in GUIDED (as MAVSDK maps it).
    roles: ClassVar[dict[Role, str]] = {
        "hold": "BRAKE",
        "offboard": "GUIDED",
        "takeoff": "GUIDED",
        "land": "LAND",
        "rtl": "RTL",
    }
    failsafe_rules = (
        ParamRule("FENCE_ENABLE", allowed=(1.0,), why="the autopilot fence is the second layer"),
        ParamRule(
            "FENCE_ACTION", allowed=(1.0, 2.0, 4.0), why="breach: RTL/land, land, or brake/land"
        ),
        ParamRule("GUID_TIMEOUT", low=0.1, high=5.0, why="guided velocity targets must expire"),
    )  # the GCS failsafe (FS_GCS_*, MAV_GCS_SYSID) is set and checked by companion_failsafe
    fence_action_param = "FENCE_ACTION"

    def set_mode_params(self, mode: str, armed: bool) -> tuple[float, float, float]:
        return float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(self.modes[mode]), 0.0

    def mode_from_set_mode(self, p1: float, p2: float, p3: float) -> str | None:
        if not int(p1) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return None
        name = self.mode_name(int(p2))
        return None if name.startswith("UNKNOWN") else name

    def encode_param(self, value: float, ptype: int) -> float:
        return float(value)

    def decode_param(self, raw: float, ptype: int) -> float:
        return float(raw)


PERSONALITIES: dict[str, type[Personality]] = {"px4": PX4, "ardupilot": ArduPilot}


def personality(name: str) -> Personality:
    try:
        return PERSONALITIES[name]()
    except KeyError:
        raise ValueError(
            f"unknown autopilot personality {name!r}; choose {' or '.join(PERSONALITIES)}"
        ) from None


def for_autopilot(autopilot: int) -> Personality | None:
    """The personality a HEARTBEAT's autopilot field names (None: unsupported)."""
    for cls in PERSONALITIES.values():
        if cls.autopilot == autopilot:
            return cls()
    return None
