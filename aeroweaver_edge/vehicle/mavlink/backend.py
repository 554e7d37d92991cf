"""The ``mavlink`` Vehicle backend: the Vehicle port over a pymavlink codec on asyncio UDP.

Start-up: discover the vehicle (system id from its heartbeat), pick the personality from
the heartbeat's autopilot field, ask for the telemetry we need, then check the failsafe
parameters and upload the mission geofence (``failsafe_policy``: warn, or refuse to arm).
Motion goes through a daemon-owned setpoint stream under a lease (see ``stream``). On link
loss the stream stops and stays stopped: the autopilot's failsafe owns the aircraft, and
only a new command from a fresh decision moves it again.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from aeroweaver_edge.contracts.endpoints import UdpUrl
from aeroweaver_edge.contracts.observation import VehicleState
from aeroweaver_edge.contracts.ports import Health
from aeroweaver_edge.contracts.wire import VehicleStatus
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_edge.vehicle.errors import VehicleError
from aeroweaver_edge.vehicle.mavlink import companion_failsafe
from aeroweaver_edge.vehicle.mavlink.codec import Message, mavlink
from aeroweaver_edge.vehicle.mavlink.commands import CommandClient, CommandError
from aeroweaver_edge.vehicle.mavlink.fence import rectangle, upload_fence
from aeroweaver_edge.vehicle.mavlink.geo import GeoOrigin
from aeroweaver_edge.vehicle.mavlink.link import FlightLink, LinkError
from aeroweaver_edge.vehicle.mavlink.params import ParamClient
from aeroweaver_edge.vehicle.mavlink.personality import (
    POSITION_ONLY,
    VELOCITY_ONLY,
    Personality,
    Role,
    for_autopilot,
    personality,
)
from aeroweaver_edge.vehicle.mavlink.signing import (
    TimestampStore,
    load_key,
    timestamp_path,
)
from aeroweaver_edge.vehicle.mavlink.stream import ZERO_VELOCITY, Setpoint, SetpointStream

if TYPE_CHECKING:
    from aeroweaver_edge.config import SafetyConfig, VehicleConfig

log = logging.getLogger(__name__)

IN_AIR_STATES = {
    mavlink.MAV_LANDED_STATE_IN_AIR,
    mavlink.MAV_LANDED_STATE_TAKEOFF,
    mavlink.MAV_LANDED_STATE_LANDING,
}
TELEMETRY = {  # message id -> interval (us) we ask for; PX4 streams these anyway, ArduPilot
    # only what a client asks for (its SRn_ rates are 0 on a fresh SITL)
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: 1_000_000,  # battery and the pre-arm bit
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 100_000,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 100_000,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1_000_000,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: 1_000_000,
}
PREARM_CHECK = mavlink.MAV_SYS_STATUS_PREARM_CHECK
REASK_S = 5.0  # telemetry intervals asked again while no position flows
PRESTREAM_S = 0.5  # zero setpoints streamed before offboard is requested (PX4 needs > 2 Hz)
MODE_CONFIRM_S = 3.0  # three 1 Hz heartbeats: a lost one must not fail the command


@dataclass
class PreflightReport:
    problems: list[str] = field(default_factory=list)
    params: dict[str, float | None] = field(default_factory=dict)
    fence_uploaded: bool = False
    companion_failsafe: companion_failsafe.FailsafeReport | None = None

    @property
    def ok(self) -> bool:
        return not self.problems


class MavlinkVehicle:
    """One UAV's autopilot over MAVLink; serves the Vehicle port."""

    def __init__(self, cfg: VehicleConfig, safety: SafetyConfig, name: str = "uav") -> None:
        if cfg.url is None:
            raise ValueError("vehicle.url is required for the mavlink backend")
        self.cfg = cfg
        self.safety = safety
        self.name = name
        self.link = FlightLink(
            UdpUrl.parse(cfg.url), sysid=cfg.sysid, link_timeout_s=cfg.link_timeout_s
        )
        self.commands = CommandClient(
            self.link, timeout_s=cfg.command_timeout_s, retries=cfg.command_retries
        )
        self.personality: Personality = (
            personality(cfg.personality) if cfg.personality != "auto" else personality("px4")
        )
        self.params = ParamClient(self.link, self.personality, timeout_s=cfg.command_timeout_s)
        self.stream = SetpointStream(
            self._send_setpoint,
            rate_hz=cfg.setpoint_hz,
            lease_s=cfg.lease_s,
            on_expired=self._lease_expired,
        )
        self.preflight = PreflightReport()
        self.refused: str | None = None
        self.origin: GeoOrigin | None = None  # the autopilot's local frame, geodetic
        self.frame = GeoOrigin(*cfg.origin) if cfg.origin is not None else None
        self.offset = (0.0, 0.0, 0.0)  # the autopilot's local origin in the swarm frame
        self._action = asyncio.Lock()  # one mode change / action at a time
        self._stamp: TimestampStore | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._t0 = time.monotonic()
        self.motion_refused = 0
        self.arm_check: str | None = None  # the autopilot's last "PreArm: ..." / "Arm: ..." text
        self.link.on("STATUSTEXT", self._on_text)

    # -- lifecycle ------------------------------------------------------------------------

    async def start(self) -> None:
        try:
            await self._start()
        except BaseException:
            await self.aclose()  # no socket or task outlives a failed start
            raise

    async def _start(self) -> None:
        cfg = self.cfg
        if cfg.signing_key:
            key = load_key(cfg.signing_key)
            self._stamp = TimestampStore(timestamp_path(cfg.signing_key))
            self.link.codec.enable_signing(key, self._stamp.load())
        await self.link.open()
        try:
            hb = await self.link.connect(cfg.connect_timeout_s)
        except LinkError as exc:
            bad = self.link.codec.stats.bad.get("signature", 0)
            hint = f" ({bad} frames failed the signature check: wrong key?)" if bad else ""
            raise VehicleError(f"{self.name}: {exc}{hint}") from None
        seen = for_autopilot(int(hb.autopilot))
        if cfg.personality == "auto":
            if seen is None:
                raise VehicleError(
                    f"{self.name}: autopilot type {hb.autopilot} is neither PX4 nor ArduPilot; "
                    "set vehicle.personality"
                )
            self.personality = seen
        elif seen is not None and seen.name != self.personality.name:
            raise VehicleError(
                f"{self.name}: vehicle.personality is {self.personality.name} but the vehicle "
                f"heartbeat says {seen.name}"
            )
        self.params.personality = self.personality
        self.link.on_link_change(self._on_link_change)
        self.stream.start()
        self._tasks.append(
            asyncio.create_task(self._ask_telemetry(), name=f"{self.name}-intervals")
        )
        if self._stamp is not None:
            self._tasks.append(
                asyncio.create_task(self._persist_stamp(), name=f"{self.name}-stamp")
            )
        await self._wait_telemetry(cfg.connect_timeout_s)
        self.preflight = await self._preflight()
        for p in self.preflight.problems:
            log.warning("%s: preflight: %s", self.name, p)
        if not self.preflight.ok and cfg.failsafe_policy == "refuse":
            self.refused = "; ".join(self.preflight.problems)
        log.info(
            "%s: connected to system %d (%s) on %s; preflight %s",
            self.name,
            self.link.sysid,
            self.personality.name,
            cfg.url,
            "ok" if self.preflight.ok else f"{len(self.preflight.problems)} problem(s)",
        )

    def _on_text(self, msg: Message) -> None:
        text = str(msg.text).rstrip("\x00").strip()
        if text.startswith(("PreArm:", "Arm:")):
            self.arm_check = text[:120]

    @property
    def prearm_ok(self) -> bool | None:
        """The autopilot's own arming checks (SYS_STATUS pre-arm bit); None: not reported."""
        sys: Message | None = self.link.last.get("SYS_STATUS")
        if sys is None or not sys.onboard_control_sensors_present & PREARM_CHECK:
            return None
        return bool(sys.onboard_control_sensors_health & PREARM_CHECK)

    async def _wait_arming_checks(self) -> None:
        """EKF, GPS and every arming check as the autopilot judges them: wait for its pre-arm
        bit (ArduPilot reports one; PX4 does not), or refuse naming the check that failed."""
        deadline = time.monotonic() + self.cfg.connect_timeout_s
        while self.prearm_ok is False:
            if time.monotonic() > deadline:
                raise VehicleError(
                    f"{self.name}: arming checks not passed within "
                    f"{self.cfg.connect_timeout_s:g} s: {self.arm_check or 'no reason given'}"
                )
            await asyncio.sleep(0.1)

    async def aclose(self) -> None:
        self.stream.stop()
        await self.stream.aclose()
        await cancel_all(self._tasks)
        if self._stamp is not None:
            with contextlib.suppress(OSError):
                await asyncio.to_thread(self._stamp.save, self.link.codec.signing_timestamp)
        await self.link.aclose()

    async def _persist_stamp(self) -> None:
        assert self._stamp is not None
        while True:
            await asyncio.sleep(10.0)
            try:
                await asyncio.to_thread(self._stamp.save, self.link.codec.signing_timestamp)
            except OSError as exc:
                log.warning("%s: cannot persist signing timestamp: %s", self.name, exc)

    async def _ask_telemetry(self) -> None:
        for msg_id, interval in TELEMETRY.items():
            with contextlib.suppress(CommandError):
                await self.commands.send(
                    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                    float(msg_id),
                    float(interval),
                    check=False,
                )

    async def _wait_telemetry(self, timeout_s: float) -> None:
        """Until LOCAL_POSITION_NED flows; the intervals are asked again every few seconds
        (a booting ArduCopter streams it only once its EKF has an origin, about 20 s in
        SITL, and one of three instances never started it after the first request)."""
        deadline = time.monotonic() + timeout_s
        ask_again = time.monotonic() + REASK_S
        while self.link.age("LOCAL_POSITION_NED") == math.inf:
            now = time.monotonic()
            if now > deadline:
                raise VehicleError(f"{self.name}: no LOCAL_POSITION_NED within {timeout_s:g} s")
            if now > ask_again:
                ask_again = now + REASK_S
                self._tasks.append(
                    asyncio.create_task(self._ask_telemetry(), name=f"{self.name}-reask")
                )
            await asyncio.sleep(0.02)

    # -- preflight: failsafe parameters and geofence -----------------------------------------

    async def _preflight(self) -> PreflightReport:
        rep = PreflightReport()
        await self._companion_failsafe(rep)
        if self.cfg.upload_fence and self.cfg.companion_failsafe != "check":
            await self._enable_fence()
        for rule in self.personality.failsafe_rules:
            value = await self.params.get(rule.name)
            rep.params[rule.name] = value
            problem = rule.check(value)
            if problem:
                rep.problems.append(problem)
        if self.frame is not None:
            local = await self._origin()
            if local is None:
                rep.problems.append(
                    "no global position: cannot place the vehicle in vehicle.origin"
                )
            else:
                self.offset = self.frame.to_local(local.lat_deg, local.lon_deg, local.alt_m)
                log.info("%s: local frame origin at N %.2f E %.2f D %.2f of vehicle.origin",
                         self.name, *self.offset)  # fmt: skip
        if self.cfg.upload_fence:
            origin = await self._origin()
            if origin is None:
                rep.problems.append("geofence not uploaded: no global position to anchor it")
            else:
                s = self.safety
                try:
                    await upload_fence(
                        self.link,
                        rectangle(self.frame or origin, s.geofence_north_m, s.geofence_east_m),
                        timeout_s=self.cfg.command_timeout_s,
                        retries=self.cfg.command_retries,
                    )
                    rep.fence_uploaded = True
                except LinkError as exc:
                    rep.problems.append(f"geofence not uploaded: {exc}")
        return rep

    async def _enable_fence(self) -> None:
        """ArduCopter ships with its fence off (FENCE_ENABLE 0): the daemon that uploads the
        fence turns it on, so the autopilot enforces the same fence as the gate. A vehicle
        that will not take it fails the FENCE_ENABLE rule below, by name."""
        if self.personality.name != "ardupilot":
            return
        found = await self.params.get("FENCE_ENABLE")
        if found is None or found == 1.0:
            return
        with contextlib.suppress(LinkError):
            now = await self.params.set("FENCE_ENABLE", 1.0)
            log.info("%s: autopilot fence: FENCE_ENABLE %g -> %g", self.name, found, now)

    async def _companion_failsafe(self, rep: PreflightReport) -> None:
        """Make the autopilot land or return on the daemon's silence; say what was set."""
        assert self.link.sysid is not None
        fs = await companion_failsafe.configure(
            self.params,
            self.personality.name,
            self.link.sysid,
            self.cfg.companion_failsafe,
            self.cfg.companion_loss_s,
        )
        rep.params.update(fs.values)
        rep.problems.extend(fs.problems)
        rep.companion_failsafe = fs
        if fs.ok:
            log.info(
                "%s: companion-loss failsafe: %s%s",
                self.name,
                fs.summary,
                f" (set {', '.join(fs.changed)})" if fs.changed else " (as found)",
            )

    async def _origin(self) -> GeoOrigin | None:
        """The local frame's geodetic origin, from one global + local position pair."""
        for _ in range(20):
            g, loc = (
                self.link.last.get("GLOBAL_POSITION_INT"),
                self.link.last.get("LOCAL_POSITION_NED"),
            )
            if g is not None and loc is not None:
                probe = GeoOrigin(g.lat / 1e7, g.lon / 1e7, g.alt / 1000.0)
                lat, lon, alt = probe.to_global(-loc.x, -loc.y, -loc.z)
                self.origin = GeoOrigin(lat, lon, alt)
                return self.origin
            await asyncio.sleep(0.05)
        return None

    # -- telemetry -------------------------------------------------------------------------

    @property
    def mode_role(self) -> Role | None:
        hb = self.link.heartbeat
        return None if hb is None else self.personality.role_of(int(hb.custom_mode))

    @property
    def mode_name(self) -> str:
        hb = self.link.heartbeat
        return "?" if hb is None else self.personality.mode_name(int(hb.custom_mode))

    @property
    def armed(self) -> bool:
        hb = self.link.heartbeat
        return hb is not None and bool(hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)

    @property
    def in_air(self) -> bool:
        ext = self.link.last.get("EXTENDED_SYS_STATE")
        if ext is not None:
            return int(ext.landed_state) in IN_AIR_STATES
        loc = self.link.last.get("LOCAL_POSITION_NED")
        return self.armed and loc is not None and -float(loc.z) > 0.5

    def _fresh(self) -> bool:
        return self.link.alive and self.link.age("LOCAL_POSITION_NED") <= self.cfg.link_timeout_s

    async def state(self) -> VehicleState:
        loc: Message | None = self.link.last.get("LOCAL_POSITION_NED")
        if loc is None:
            raise VehicleError(f"{self.name}: no position telemetry yet")
        n, e, d = self.offset
        return VehicleState(
            (float(loc.x) + n, float(loc.y) + e, float(loc.z) + d),
            (float(loc.vx), float(loc.vy), float(loc.vz)),
            armed=self.armed,
            in_air=self.in_air,
        )

    def telemetry(self) -> VehicleStatus | None:
        """Mode, armed, battery and heartbeat age as the link last heard them (observers)."""
        loc: Message | None = self.link.last.get("LOCAL_POSITION_NED")
        if loc is None:
            return None
        sys: Message | None = self.link.last.get("SYS_STATUS")
        battery = None if sys is None or sys.battery_remaining < 0 else float(sys.battery_remaining)
        hb = self.link.heartbeat
        hb_age = None if hb is None else time.monotonic() - self.link.heartbeat_at
        n, e, d = self.offset
        return VehicleStatus(
            pos=(float(loc.x) + n, float(loc.y) + e, float(loc.z) + d),
            vel=(float(loc.vx), float(loc.vy), float(loc.vz)),
            armed=self.armed, in_air=self.in_air, mode=self.mode_name[:64],
            battery_pct=battery,
            heartbeat_age_s=None if hb_age is None else round(hb_age, 3),
        )  # fmt: skip

    async def health(self) -> Health:
        if not self.link.alive:
            return Health(False, "link lost" if self.link.lost else "not connected")
        if not self._fresh():
            return Health(False, "position telemetry stale")
        if self.refused:
            return Health(False, f"refused to arm: {self.refused}")
        return Health(True, f"{self.personality.name} {self.mode_name}")

    # -- commands --------------------------------------------------------------------------

    def _require_link(self) -> None:
        if not self._fresh():
            raise VehicleError(f"{self.name}: link lost or telemetry stale; no new motion")

    async def _set_mode(self, role: Role) -> None:
        """Switch to the mode playing ``role`` and confirm it from the heartbeat."""
        mode = self.personality.roles[role]
        if self.mode_name == mode:
            return
        p1, p2, p3 = self.personality.set_mode_params(mode, self.armed)
        await self.commands.send(
            mavlink.MAV_CMD_DO_SET_MODE, p1, p2, p3, done=lambda: self.mode_name == mode
        )
        await self.wait_until(lambda: self.mode_name == mode, MODE_CONFIRM_S, f"mode {mode}")

    async def wait_until(self, cond: Callable[[], bool], timeout_s: float, what: str) -> None:
        """Poll telemetry state until ``cond()``; VehicleError after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not cond():
            if time.monotonic() > deadline:
                raise VehicleError(f"{self.name}: {what} not confirmed within {timeout_s:g} s")
            await asyncio.sleep(0.01)

    async def arm(self) -> None:
        if self.refused:
            raise VehicleError(f"{self.name}: refusing to arm: {self.refused}")
        self._require_link()
        if self.armed:
            return
        if self.in_air:
            raise VehicleError(f"{self.name}: refusing to arm a vehicle that reports in air")
        async with self._action:
            await self._wait_arming_checks()
            if self.personality.name == "ardupilot":
                await self._set_mode("takeoff")  # Copter arms and takes off in GUIDED
            self.link.beat()  # the companion-loss failsafe is armed before the vehicle is
            try:
                await self.commands.send(
                    mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0, done=lambda: self.armed
                )
            except CommandError as exc:
                why = f": {self.arm_check}" if self.arm_check else ""
                raise VehicleError(f"{self.name}: {exc}{why}") from None
            await self.wait_until(lambda: self.armed, MODE_CONFIRM_S, "arming")

    async def takeoff(self, altitude_m: float) -> None:
        self._require_link()
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise VehicleError(f"{self.name}: bad take-off altitude {altitude_m!r}")
        if self.in_air:
            raise VehicleError(f"{self.name}: refusing to take off: already in the air")
        if not self.armed:
            raise VehicleError(f"{self.name}: refusing to take off: not armed")
        async with self._action:
            if self.personality.name == "px4":
                home = self.link.last.get("HOME_POSITION")
                if home is None:
                    raise VehicleError(
                        f"{self.name}: no HOME_POSITION: cannot set take-off altitude"
                    )
                amsl = float(home.altitude) / 1000.0 + altitude_m
                await self.commands.send(
                    mavlink.MAV_CMD_NAV_TAKEOFF,
                    math.nan,
                    0,
                    0,
                    math.nan,
                    math.nan,
                    math.nan,
                    amsl,
                    done=lambda: self.in_air,
                )
            else:
                await self.commands.send(
                    mavlink.MAV_CMD_NAV_TAKEOFF,
                    0,
                    0,
                    0,
                    math.nan,
                    math.nan,
                    math.nan,
                    altitude_m,
                    done=lambda: self.in_air,
                )

    async def _engage_offboard(self) -> None:
        """Zero setpoints first, then offboard (PX4) / guided (ArduPilot), confirmed."""
        if self.mode_role == "offboard":
            return
        # The lead-in is the daemon's own doing, not the agent's: keep it under one lease.
        self.stream.set(ZERO_VELOCITY, lease_s=PRESTREAM_S + 2 * MODE_CONFIRM_S)
        await asyncio.sleep(PRESTREAM_S)
        self._require_link()
        await self._set_mode("offboard")

    async def _motion(self, sp: Setpoint) -> None:
        if self.refused:
            raise VehicleError(f"{self.name}: no motion: {self.refused}")
        self._require_link()
        if not (self.armed and self.in_air):
            raise VehicleError(f"{self.name}: no motion on the ground")
        if self.mode_role != "offboard" or not self.stream.active:
            async with self._action:
                await self._engage_offboard()
        self.stream.set(sp)

    async def set_velocity(self, north: float, east: float, down: float) -> None:
        if not all(math.isfinite(v) for v in (north, east, down)):
            raise VehicleError(f"{self.name}: non-finite velocity")
        await self._motion(Setpoint("velocity", north, east, down))

    async def goto(self, north: float, east: float, down: float) -> None:
        if not all(math.isfinite(v) for v in (north, east, down)):
            raise VehicleError(f"{self.name}: non-finite position")
        n, e, d = self.offset  # the swarm frame's target in the autopilot's own frame
        await self._motion(Setpoint("position", north - n, east - e, down - d))

    async def hold(self) -> None:
        self._require_link()
        if not self.in_air:
            self.stream.stop()
            return
        if self.mode_role == "offboard" and self.stream.active:
            self.stream.set(ZERO_VELOCITY)  # stay under our control, stopped
            return
        self.stream.stop()
        if self.mode_role in ("hold", "land", "rtl", "takeoff"):
            return  # already an autopilot-native safe mode
        async with self._action:
            await self._set_mode("hold")

    async def land(self) -> None:
        self.stream.stop()
        self._require_link()
        async with self._action:
            if self.personality.name == "px4":
                await self.commands.send(
                    mavlink.MAV_CMD_NAV_LAND,
                    math.nan,
                    0,
                    0,
                    math.nan,
                    math.nan,
                    math.nan,
                    math.nan,
                    done=lambda: self.mode_role == "land",
                )
            else:
                await self._set_mode("land")

    async def return_home(self) -> None:
        self.stream.stop()
        self._require_link()
        async with self._action:
            if self.personality.name == "px4":
                await self.commands.send(
                    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, done=lambda: self.mode_role == "rtl"
                )
            else:
                await self._set_mode("rtl")

    # -- stream plumbing -----------------------------------------------------------------------

    def _send_setpoint(self, sp: Setpoint) -> None:
        sysid, compid = self.link.target
        ms = int((time.monotonic() - self._t0) * 1000) & 0xFFFFFFFF
        if sp.kind == "velocity":
            mask, pos, vel = VELOCITY_ONLY, (0.0, 0.0, 0.0), (sp.n, sp.e, sp.d)
        else:
            mask, pos, vel = POSITION_ONLY, (sp.n, sp.e, sp.d), (0.0, 0.0, 0.0)
        self.link.send(
            self.link.mav.set_position_target_local_ned_encode(
                ms,
                sysid,
                compid,
                mavlink.MAV_FRAME_LOCAL_NED,
                mask,
                *pos,
                *vel,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            )
        )

    async def _lease_expired(self) -> None:
        """The agent fell silent past the lease: the autopilot's own hold takes over."""
        if not self._fresh() or not self.in_air:
            return
        try:
            async with self._action:
                if self.stream.active:
                    return  # a fresh command renewed the lease meanwhile: it stands
                await self._set_mode("hold")
        except (VehicleError, LinkError) as exc:
            log.warning("%s: hold after lease expiry failed: %s", self.name, exc)

    def _on_link_change(self, up: bool) -> None:
        if not up:
            # The autopilot's failsafe owns the aircraft now; never resume this setpoint.
            self.stream.stop()
