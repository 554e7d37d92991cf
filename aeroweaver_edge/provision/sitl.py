"""ArduCopter SITL as a vehicle ``keys init --vehicle sitl`` provisions for: where instance
*i* starts, what it needs to pass every arming check, and the command line that runs the
user's own build (``arducopter`` from ArduPilot's ``./waf configure --board sitl && ./waf
copter``). Nothing here builds or ships ArduPilot.

Instance *i* is system *i+1*, starts 5 m east of instance *i-1* (the emulator's row), and
sends MAVLink from its SERIAL0 to the daemon's UDP port. Every daemon gets the same
``[vehicle] origin`` (instance 0's home), so the vehicles share one local frame.
"""

from __future__ import annotations

import math

EARTH_RADIUS_M = 6_378_137.0
# The emulator's default origin (vehicle.mavlink.geo.DEFAULT_ORIGIN; provision may not import
# vehicle, a test holds the two equal): lat, lon, alt_m.
ORIGIN = (47.397742, 8.545594, 488.0)

SPACING_M = 5.0
PARAMS_FILE = "aeroweaver-sitl.parm"

# A bare SITL copter fails its arming checks on an uncalibrated simulated IMU and RC, and
# has no RC transmitter for its throttle failsafe: our own list of what it needs (from the
# PreArm texts of a bare instance). Every other parameter keeps the firmware's default; the
# daemon itself sets the companion-loss failsafe and the fence at preflight.
PARAMS: dict[str, float] = {
    "FRAME_CLASS": 1,  # quad
    "FRAME_TYPE": 1,  # X
    **{f"INS_ACC{s}OFFS_{a}": 0.001 for s in ("", "2") for a in "XYZ"},
    **{f"INS_ACC{s}SCAL_{a}": 1.001 for s in ("", "2") for a in "XYZ"},
    **{f"RC{c}_{k}": v for c in range(1, 9) for k, v in (("MIN", 1000), ("MAX", 2000))},
    **{f"RC{c}_TRIM": 1500 for c in range(1, 9)},
    "FS_THR_ENABLE": 0,  # no RC transmitter in the loop
    "SIM_BARO_RND": 0,
}


def params_text() -> str:
    """The defaults file (``--defaults``): one ``NAME VALUE`` a line."""
    return "".join(f"{k} {v:g}\n" for k, v in PARAMS.items())


def home(i: int) -> tuple[float, float, float]:
    """Instance ``i``'s home (lat, lon, alt_m): ``SPACING_M * i`` east of ``ORIGIN``."""
    lat, lon, alt = ORIGIN
    east = SPACING_M * i
    return lat, lon + math.degrees(east / (EARTH_RADIUS_M * math.cos(math.radians(lat)))), alt


def command(
    i: int,
    send_to: str,
    *,
    binary: str = "arducopter",
    defaults: str = PARAMS_FILE,
    speedup: float = 1.0,
    serial1: str | None = None,
    instance: int | None = None,
) -> list[str]:
    """The argv of SITL instance ``i`` whose SERIAL0 sends to ``send_to`` (``HOST:PORT``).
    ``instance`` (``-I``) offsets SITL's own TCP ports; default ``i``, so several instances
    can share a machine; in a network namespace of its own every instance can be 0."""
    lat, lon, alt = home(i)
    offset = i if instance is None else instance
    argv = [
        binary, "--model", "quad", "--speedup", f"{speedup:g}",
        "--home", f"{lat:.7f},{lon:.7f},{alt:.1f},0",
        "--defaults", defaults, "--sysid", str(i + 1), "-I", str(offset),
        "--serial0", f"udpclient:{send_to}",
    ]  # fmt: skip
    if serial1 is not None:
        argv += ["--serial1", f"udpclient:{serial1}"]
    return argv
