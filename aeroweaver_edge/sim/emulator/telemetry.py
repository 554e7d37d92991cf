"""Telemetry encoders of the emulated autopilot (what MAVSDK and QGC need to see)."""

from __future__ import annotations

import math
from typing import Any, Protocol

from aeroweaver_edge.vehicle.mavlink.codec import Message
from aeroweaver_edge.vehicle.mavlink.codec import mavlink as R
from aeroweaver_edge.vehicle.mavlink.geo import GeoOrigin
from aeroweaver_edge.vehicle.mavlink.personality import Personality
from aeroweaver_edge.world.kinematics import KinematicWorld


class _FaultSwitches(Protocol):
    no_autopilot_version: bool


class TelemetrySource(Protocol):
    """What the encoders read of an emulated autopilot (``autopilot.EmulatedAutopilot``)."""

    sysid: int
    uav: str
    p: Personality
    origin: GeoOrigin
    alt: float  # metres above home
    vz: float
    home: tuple[float, float]
    fence: list[Message]
    breached: bool

    @property
    def faults(self) -> _FaultSwitches: ...

    @property
    def landed(self) -> int: ...

    @property
    def prearm_ready(self) -> bool: ...

    @property
    def mav(self) -> Any: ...

    @property
    def world(self) -> KinematicWorld: ...

    def boot_ms(self) -> int: ...

    def param(self, name: str) -> float: ...


# ArduPilot FENCE_TYPE bits: max altitude, circle, polygon (uploaded zones), min altitude.
FENCE_ALT_MAX, FENCE_CIRCLE, FENCE_POLYGON, FENCE_ALT_MIN = 1, 2, 4, 8


def fence_bits(ap: TelemetrySource) -> tuple[bool, bool, bool]:
    """MAV_SYS_STATUS_GEOFENCE (present, enabled, healthy) as the autopilot reports it.

    ArduPilot (``AC_Fence::sys_status_*`` and ``GCS_MAVLINK::update_sensor_status_flags``):
    present when a circle or altitude fence is configured in FENCE_TYPE, or the polygon
    type with zones uploaded; enabled when present, FENCE_ENABLE is set and FENCE_ACTION is
    not 0 (report only); healthy unless present and breached (so the health bit is set even
    without a fence). PX4 reports no geofence bit in SYS_STATUS (its health report has no
    geofence component; a breach is a failsafe and a STATUSTEXT), so all three stay clear.
    """
    if ap.p.name != "ardupilot":
        return False, False, False
    kinds = int(ap.param("FENCE_TYPE"))
    present = bool(kinds & (FENCE_ALT_MAX | FENCE_CIRCLE | FENCE_ALT_MIN)) or (
        bool(kinds & FENCE_POLYGON) and bool(ap.fence)
    )
    enabled = present and ap.param("FENCE_ENABLE") >= 1 and int(ap.param("FENCE_ACTION")) != 0
    healthy = not (present and ap.breached)
    return present, enabled, healthy


def encode(ap: TelemetrySource, msg_id: int) -> Message | None:
    """The telemetry message ``msg_id`` as the autopilot would send it now (None: not one
    it sends)."""
    m = ap.mav
    b = ap.world.body(ap.uav)
    ms = ap.boot_ms()
    lat, lon = ap.origin.to_global_e7(b.north, b.east)
    amsl_mm = round((ap.origin.alt_m + ap.alt) * 1000)
    if msg_id == R.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
        return m.local_position_ned_encode(ms, b.north, b.east, -ap.alt, b.vn, b.ve, ap.vz)
    elif msg_id == R.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
        hdg = round(math.degrees(math.atan2(b.ve, b.vn)) % 360 * 100) if b.speed > 0.1 else 65535
        return m.global_position_int_encode(
            ms,
            lat,
            lon,
            amsl_mm,
            round(ap.alt * 1000),
            round(b.vn * 100),
            round(b.ve * 100),
            round(ap.vz * 100),
            hdg,
        )
    elif msg_id == R.MAVLINK_MSG_ID_ATTITUDE:
        yaw = math.atan2(b.ve, b.vn) if b.speed > 0.1 else 0.0
        return m.attitude_encode(ms, 0.0, 0.0, yaw, 0.0, 0.0, 0.0)
    elif msg_id == R.MAVLINK_MSG_ID_SYS_STATUS:
        sensors = (
            R.MAV_SYS_STATUS_SENSOR_3D_GYRO
            | R.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | R.MAV_SYS_STATUS_SENSOR_3D_MAG
            | R.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
            | R.MAV_SYS_STATUS_SENSOR_GPS
        )
        present = enabled = sensors | R.MAV_SYS_STATUS_PREARM_CHECK
        health = sensors | (R.MAV_SYS_STATUS_PREARM_CHECK * ap.prearm_ready)
        fence_present, fence_enabled, fence_healthy = fence_bits(ap)
        present |= R.MAV_SYS_STATUS_GEOFENCE * fence_present
        enabled |= R.MAV_SYS_STATUS_GEOFENCE * fence_enabled
        health |= R.MAV_SYS_STATUS_GEOFENCE * fence_healthy
        return m.sys_status_encode(
            present,
            enabled,
            health,
            100,
            16_000,
            500,
            90,
            0,
            0,
            0,
            0,
            0,
            0,
        )
    elif msg_id == R.MAVLINK_MSG_ID_GPS_RAW_INT:
        return m.gps_raw_int_encode(
            ms * 1000,
            R.GPS_FIX_TYPE_3D_FIX,
            lat,
            lon,
            amsl_mm,
            80,
            120,
            round(b.speed * 100),
            65535,
            12,
        )
    elif msg_id == R.MAVLINK_MSG_ID_HOME_POSITION:
        hlat, hlon = ap.origin.to_global_e7(*ap.home)
        return m.home_position_encode(
            hlat,
            hlon,
            round(ap.origin.alt_m * 1000),
            ap.home[0],
            ap.home[1],
            0.0,
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            ms * 1000,
        )
    elif msg_id == R.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
        return m.extended_sys_state_encode(R.MAV_VTOL_STATE_UNDEFINED, ap.landed)
    elif msg_id == R.MAVLINK_MSG_ID_BATTERY_STATUS:
        return m.battery_status_encode(
            0,
            R.MAV_BATTERY_FUNCTION_ALL,
            R.MAV_BATTERY_TYPE_LIPO,
            2500,
            [4000, 4000, 4000, 4000] + [65535] * 6,
            500,
            -1,
            -1,
            90,
        )
    elif msg_id == R.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
        if ap.faults.no_autopilot_version:
            return None
        caps = (
            R.MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | R.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | R.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
            | R.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
            | R.MAV_PROTOCOL_CAPABILITY_MISSION_INT
            | R.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE * (ap.p.name == "px4")
        )
        return m.autopilot_version_encode(
            caps,
            (1 << 24) | (15 << 16),
            0,
            0,
            0,
            [0] * 8,
            [0] * 8,
            [0] * 8,
            0,
            0,
            ap.sysid,
        )
    elif msg_id == R.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN:
        return m.gps_global_origin_encode(
            round(ap.origin.lat_deg * 1e7),
            round(ap.origin.lon_deg * 1e7),
            round(ap.origin.alt_m * 1000),
        )
    return None
