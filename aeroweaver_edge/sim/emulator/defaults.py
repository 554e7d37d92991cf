"""What an emulated autopilot starts with: parameters and telemetry rates."""

from __future__ import annotations

from aeroweaver_edge.vehicle.mavlink.codec import mavlink as R
from aeroweaver_edge.vehicle.mavlink.personality import PARAM_INT32, PARAM_REAL32

# Parameter name -> (value, type), as the firmware ships them: PX4's COM_OBL_RC_ACT 0
# (Position mode: hands control to RC sticks), ArduCopter's FS_GCS_ENABLE 0 (no GCS
# failsafe), FENCE_ENABLE 0. The daemon sets its companion-loss failsafe at preflight
# (vehicle/mavlink/companion_failsafe.py). ArduPilot names as in 4.7 (MAV_SYSID,
# MAV_GCS_SYSID; SYSID_THISMAV and SYSID_MYGCS before).
PX4_PARAMS: dict[str, tuple[float, int]] = {
    "COM_OF_LOSS_T": (1.0, PARAM_REAL32),
    "COM_OBL_RC_ACT": (0, PARAM_INT32),
    "GF_ACTION": (2, PARAM_INT32),
    "GF_MAX_HOR_DIST": (0.0, PARAM_REAL32),
    "GF_MAX_VER_DIST": (0.0, PARAM_REAL32),
    "MIS_TAKEOFF_ALT": (2.5, PARAM_REAL32),
    "MPC_TKO_SPEED": (1.5, PARAM_REAL32),
    "MPC_LAND_SPEED": (0.7, PARAM_REAL32),
    "NAV_DLL_ACT": (0, PARAM_INT32),
    "RTL_RETURN_ALT": (30.0, PARAM_REAL32),
    "MAV_SYS_ID": (1, PARAM_INT32),
}
ARDUPILOT_PARAMS: dict[str, tuple[float, int]] = {
    "FENCE_ENABLE": (0, PARAM_INT32),
    "FENCE_TYPE": (7, PARAM_INT32),
    "FENCE_ACTION": (1, PARAM_INT32),
    "FENCE_MARGIN": (2.0, PARAM_REAL32),
    "AVOID_ENABLE": (3, PARAM_INT32),  # fence + proximity: GUIDED velocity stops short
    "FS_GCS_ENABLE": (0, PARAM_INT32),
    "FS_GCS_TIMEOUT": (5.0, PARAM_REAL32),
    "MAV_GCS_SYSID": (255, PARAM_INT32),
    "GUID_TIMEOUT": (3.0, PARAM_REAL32),
    "WPNAV_SPEED_UP": (250.0, PARAM_REAL32),
    "LAND_SPEED": (50.0, PARAM_REAL32),
    "RTL_ALT": (1500.0, PARAM_REAL32),
    "MAV_SYSID": (1, PARAM_INT32),
}

TELEMETRY_S: dict[int, float] = {
    R.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    R.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    R.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0,
    R.MAVLINK_MSG_ID_HOME_POSITION: 1.0,
    R.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    R.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0,
    R.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 0.1,
    R.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.1,
    R.MAVLINK_MSG_ID_ATTITUDE: 0.1,
}
