"""A MAVLink vehicle emulator whose physics is the kinematic world (``world.kinematics``).

One emulated autopilot per UAV (PX4 or ArduPilot personality) speaks real MAVLink 2 bytes
over UDP: what our ``mavlink`` backend and MAVSDK need, with an offboard-loss failsafe,
geofence actions, fault injection and a command log for assertions. No real autopilot or
SITL can be installed offline (docs/notes/mavlink.md), so this is CI's "real MAVLink" target.
"""
