"""The MAVLink flight link: pymavlink's codec on the daemon's own asyncio loop.

No ``mavutil`` and no threads: datagrams are fed to the codec from an asyncio protocol, and
every timer (heartbeat, setpoint stream, watchdog, retries) is a task on the same loop, so a
stalled loop stops the setpoint stream and the autopilot's offboard-loss failsafe fires
(docs/notes/mavlink.md). The emulator in ``aeroweaver_edge.sim.emulator`` shares this codec.
"""
