"""STATUSTEXT lines the emulated autopilots send, with the severity and wording of the
firmware they imitate, so a ground station's message pane reads as it would in the field.

Sources (PX4 main, ArduCopter 4.x):
* PX4 failsafe framework (``commander/failsafe/framework.cpp``): every failsafe action
  (offboard loss, geofence, termination) logs ``"Failsafe activated\\t"`` at CRITICAL; the
  trailing tab is PX4's marker that the same news also goes out as an event.
* PX4 commander: ``"Landing at current position\\t"`` (INFO) on NAV_LAND, a refused mode
  ``"Switching to <Mode> is currently not available\\t"`` (CRITICAL); the navigator:
  ``"RTL: start return at <a> m (<b> m above destination)\\t"`` (INFO) when RTL starts.
* ArduCopter: fences ``"Polygon fence breached"`` (NOTICE, ``AC_Fence::print_fence_message``;
  uploaded inclusion zones are the polygon fence type), GCS loss ``"GCS Failsafe"`` /
  ``"GCS Failsafe - Disarming"`` and ``"GCS Failsafe Cleared"`` (WARNING, ``events.cpp``).
* Neither autopilot sends a STATUSTEXT for a mode change that succeeds: the ground
  station announces it from the HEARTBEAT's ``custom_mode``. Only refusals and
  failsafe-driven changes are texts.
"""

from __future__ import annotations

import math

from aeroweaver_edge.vehicle.mavlink.codec import mavlink as R

Text = tuple[int, str]
"""(MAV_SEVERITY, text) as the firmware sends it."""

PX4_FAILSAFE: Text = (R.MAV_SEVERITY_CRITICAL, "Failsafe activated\t")
PX4_LAND: Text = (R.MAV_SEVERITY_INFO, "Landing at current position\t")
AP_ARMING: Text = (R.MAV_SEVERITY_INFO, "Arming motors")  # AP_Arming, recorded from SITL
AP_DISARMING: Text = (R.MAV_SEVERITY_INFO, "Disarming motors")
AP_ARM_NOT_READY: Text = (R.MAV_SEVERITY_CRITICAL, "Arm: AHRS: waiting for home")
AP_FENCE_LOADED: Text = (R.MAV_SEVERITY_DEBUG, "Fence Indexed OK")  # AC_PolyFence_loader
AP_FENCE_CLEARED: Text = (R.MAV_SEVERITY_NOTICE, "Fence breach cleared")  # Copter fence.cpp
AP_FENCE_BREACH: Text = (R.MAV_SEVERITY_NOTICE, "Polygon fence breached")
AP_GCS_FAILSAFE: Text = (R.MAV_SEVERITY_WARNING, "GCS Failsafe")
AP_GCS_FAILSAFE_DISARM: Text = (R.MAV_SEVERITY_WARNING, "GCS Failsafe - Disarming")
AP_GCS_FAILSAFE_CLEARED: Text = (R.MAV_SEVERITY_WARNING, "GCS Failsafe Cleared")
# FS_*_ENABLE value -> what ArduCopter says when the mode it asks for is unavailable (the
# emulator has no SMART_RTL mode and no mission with DO_LAND_START).
AP_FAILSAFE_FALLBACK: dict[int, Text] = {
    3: (R.MAV_SEVERITY_WARNING, "SmartRTL Unavailable, Trying RTL Mode"),
    4: (R.MAV_SEVERITY_WARNING, "SmartRTL Unavailable, Using Land Mode"),
    6: (R.MAV_SEVERITY_WARNING, "Trying RTL Mode"),
}

# PX4's nav_state_names for the modes the emulator knows (what a refusal names).
PX4_MODE_NAMES: dict[str, str] = {
    "MANUAL": "Manual",
    "ALTCTL": "Altitude",
    "POSCTL": "Position",
    "AUTO.MISSION": "Mission",
    "AUTO.LOITER": "Hold",
    "AUTO.RTL": "Return",
    "AUTO.READY": "Hold",
    "ACRO": "Acro",
    "OFFBOARD": "Offboard",
    "STABILIZED": "Stabilized",
    "AUTO.TAKEOFF": "Takeoff",
    "AUTO.LAND": "Land",
}


def px4_mode_refused(mode: str) -> Text:
    return (
        R.MAV_SEVERITY_CRITICAL,
        f"Switching to {PX4_MODE_NAMES.get(mode, mode)} is currently not available\t",
    )


def px4_rtl_start(return_alt_m: float, destination_alt_m: float = 0.0) -> Text:
    """The navigator's line when RTL starts (the emulator returns at its current height)."""
    a = math.ceil(return_alt_m)
    return (
        R.MAV_SEVERITY_INFO,
        f"RTL: start return at {a} m ({math.ceil(return_alt_m - destination_alt_m)} m "
        "above destination)\t",
    )
