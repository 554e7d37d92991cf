"""One emulated autopilot: protocol answers, modes, failsafes and vertical motion.

Horizontal motion is the kinematic world's: the autopilot only sets its body's velocity
setpoint (offboard/guided velocity, hold = zero) and reads position back. The world is
planar, so take-off and landing are a vertical state of the autopilot alone (climb and
descent rates from the usual parameters), scaled by ``time_scale``. Timers (heartbeats,
offboard loss, retries) run on the wall clock.
"""

from __future__ import annotations

import math
import random
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from aeroweaver_edge.sim.emulator import ftp, texts
from aeroweaver_edge.sim.emulator.defaults import ARDUPILOT_PARAMS, PX4_PARAMS, TELEMETRY_S
from aeroweaver_edge.sim.emulator.telemetry import encode
from aeroweaver_edge.vehicle.mavlink.codec import AUTOPILOT_COMPID, Codec, Message, mavlink
from aeroweaver_edge.vehicle.mavlink.geo import DEFAULT_ORIGIN, GeoOrigin
from aeroweaver_edge.vehicle.mavlink.personality import (
    PARAM_INT32,
    Personality,
)
from aeroweaver_edge.world.kinematics import KinematicWorld

R = mavlink  # short alias for the enums
ACCEPTED: int = R.MAV_RESULT_ACCEPTED
DENIED: int = R.MAV_RESULT_DENIED
FAILED: int = R.MAV_RESULT_FAILED
UNSUPPORTED: int = R.MAV_RESULT_UNSUPPORTED
FENCE: int = R.MAV_MISSION_TYPE_FENCE
ON_GROUND: int = R.MAV_LANDED_STATE_ON_GROUND
IN_AIR: int = R.MAV_LANDED_STATE_IN_AIR
TAKING_OFF: int = R.MAV_LANDED_STATE_TAKEOFF
LANDING: int = R.MAV_LANDED_STATE_LANDING
OFFBOARD_STREAM_S = 0.5  # PX4 enters offboard only with a setpoint this recent
DUPLICATE_WINDOW_S = 5.0
IGNORE_POSITION = 0x7  # type_mask bits: x, y, z ignored
IGNORE_VELOCITY = 0x38  # vx, vy, vz ignored
FORCE_DISARM = 21196.0
CHANGE_MODE = R.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
GUIDED_REQUEST = 2  # MISSION_ITEM_INT.current: ArduPilot's "fly here in GUIDED"
TEXT_LEN = 50  # STATUSTEXT.text; longer texts go out in chunks sharing an id


@dataclass
class Faults:
    """Fault-injection switches (all off by default)."""

    drop_rx: float = 0.0  # fraction of incoming datagrams lost
    drop_tx: float = 0.0  # fraction of outgoing datagrams lost
    no_acks: bool = False
    no_heartbeats: bool = False
    mute: bool = False  # send nothing at all (a dead radio)
    deaf: bool = False  # hear nothing at all
    no_autopilot_version: bool = False
    no_params: bool = False
    locked_params: frozenset[str] = frozenset()  # PARAM_SET echoes the old value (refused)
    slow_commands: dict[int, float] = field(default_factory=dict)  # IN_PROGRESS, then final


@dataclass(frozen=True)
class CommandRecord:
    """One received command, as the autopilot saw it."""

    t: float
    src: tuple[int, int]
    target: tuple[int, int]
    command: int
    params: tuple[float, ...]
    confirmation: int
    result: int | None
    executed: bool  # False: a retry answered from the cache, or not for us


@dataclass
class _Upload:
    mission_type: int
    count: int
    items: list[Message]
    src: tuple[int, int]
    asked_at: float = 0.0
    tries: int = 0


def _same(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return len(a) == len(b) and all(
        (math.isnan(x) and math.isnan(y)) or x == y for x, y in zip(a, b, strict=True)
    )


def _pid(msg: Message) -> str:
    pid = msg.param_id
    if isinstance(pid, bytes):
        pid = pid.decode("ascii", errors="replace")
    return str(pid).rstrip("\x00")


class EmulatedAutopilot:
    def __init__(
        self,
        *,
        sysid: int,
        uav: str,
        personality: Personality,
        world: Callable[[], KinematicWorld],
        transmit: Callable[[bytes], None],
        origin: GeoOrigin = DEFAULT_ORIGIN,
        time_scale: float = 1.0,
        params: dict[str, float] | None = None,
        signing_key: bytes | None = None,
        faults: Faults | None = None,
        seed: int = 0,
        prearm_s: float = 0.0,
    ) -> None:
        self.sysid = sysid
        self.uav = uav
        self.p = personality
        self._world = world
        self._transmit = transmit
        self.origin = origin
        self.time_scale = time_scale
        self.faults = faults or Faults()
        self.codec = Codec(sysid, AUTOPILOT_COMPID)
        if signing_key is not None:
            self.codec.enable_signing(signing_key, int((time.time() - 1_420_070_400) * 1e5))
        self._rng = random.Random(seed * 7919 + sysid)
        table = PX4_PARAMS if personality.name == "px4" else ARDUPILOT_PARAMS
        self.params: dict[str, tuple[float, int]] = dict(table)
        self.params["MAV_SYS_ID" if personality.name == "px4" else "MAV_SYSID"] = (
            sysid,
            PARAM_INT32,
        )
        for name, value in (params or {}).items():
            if name not in self.params:
                raise ValueError(f"unknown {personality.name} parameter {name!r}")
            self.params[name] = (value, self.params[name][1])
        self.t0 = time.monotonic()
        self.prearm_s = prearm_s  # a warm-up (EKF, GPS) in which arming is refused
        self.armed = False
        self.mode = "AUTO.LOITER" if personality.name == "px4" else "STABILIZE"
        self._landed = ON_GROUND
        self.alt = 0.0  # metres above home
        self.vz = 0.0
        self.climb_to = 0.0
        body = world().body(uav)
        self.home = (body.north, body.east)
        self.setpoint: tuple[str, float, float, float] | None = None  # last received
        self.setpoint_at = -math.inf
        self.setpoints = 0
        self.goto_target: tuple[float, float] | None = None
        self.fence: list[Message] = []
        self.breached = False
        self.log: list[CommandRecord] = []
        self.events: list[tuple[float, str]] = []
        self.rx = Counter[str]()
        self.foreign = 0  # messages addressed to another system
        # PX4 streams its telemetry from boot; ArduPilot only its HEARTBEAT until a client
        # asks (SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM): its SRn_ rates are 0 (SITL).
        self.intervals = (
            dict(TELEMETRY_S)
            if personality.name == "px4"
            else {R.MAVLINK_MSG_ID_HEARTBEAT: TELEMETRY_S[R.MAVLINK_MSG_ID_HEARTBEAT]}
        )
        self._due: dict[int, float] = {}
        self._dup: dict[tuple[int, int, int], tuple[tuple[float, ...], float, int]] = {}
        self._upload: _Upload | None = None
        self._last_cmd: dict[tuple[int, int], int] = {}  # last command run, per sender
        self._slow: list[tuple[float, int, tuple[int, int]]] = []  # (due, command, src)
        self._last_tick = time.monotonic()
        self._guided_stopped = False
        self._text_id = 0
        self.gcs_seen_at: float | None = None  # ArduPilot: last HEARTBEAT from MAV_GCS_SYSID
        self.gcs_failsafe = False

    # -- helpers ---------------------------------------------------------------------------

    @property
    def landed(self) -> int:
        return self._landed

    @landed.setter
    def landed(self, value: int) -> None:
        if value != self._landed:
            self._landed = value
            self._send_message(R.MAVLINK_MSG_ID_EXTENDED_SYS_STATE)  # at once, like PX4

    def param(self, name: str) -> float:
        return float(self.params[name][0])

    @property
    def world(self) -> KinematicWorld:
        return self._world()

    def now(self) -> float:
        return time.monotonic()

    def boot_ms(self) -> int:
        return int((time.monotonic() - self.t0) * 1000) & 0xFFFFFFFF

    def _event(self, text: str) -> None:
        self.events.append((time.monotonic(), text))

    def _send(self, msg: Message) -> None:
        if self.faults.mute:
            return
        data = self.codec.encode(msg)
        if self.faults.drop_tx and self._rng.random() < self.faults.drop_tx:
            return
        self._transmit(data)

    @property
    def mav(self) -> Any:
        return self.codec.mav

    def _role(self) -> str | None:
        return self.p.role_of(self.p.modes[self.mode])

    def set_mode(self, mode: str, why: str = "") -> None:
        if mode == self.mode:
            return
        self._event(f"mode {self.mode} -> {mode}" + (f" ({why})" if why else ""))
        self.mode = mode
        self.goto_target = None
        self._guided_stopped = False
        role = self._role()
        if role in ("hold", "takeoff", "land") or role is None:
            self.world.hold(self.uav)
        elif role == "offboard" and self.setpoint is not None and self._stream_recent():
            self._apply_setpoint()
        elif role == "offboard":
            self.world.hold(self.uav)
        self.send_heartbeat()

    def _stream_recent(self) -> bool:
        return time.monotonic() - self.setpoint_at <= OFFBOARD_STREAM_S

    # -- receiving -------------------------------------------------------------------------

    def receive(self, data: bytes) -> bool:
        """Feed one datagram; True if it held at least one valid message."""
        if self.faults.deaf or (self.faults.drop_rx and self._rng.random() < self.faults.drop_rx):
            return False
        msgs = self.codec.decode(data)
        for m in msgs:
            self._handle(m)
        return bool(msgs)

    def _for_me(self, msg: Message) -> bool:
        target = getattr(msg, "target_system", None)
        if target is None or target in (0, self.sysid):
            return True
        self.foreign += 1
        return False

    def _handle(self, msg: Message) -> None:
        kind = msg.get_type()
        self.rx[kind] += 1
        if not self._for_me(msg):
            if kind in ("COMMAND_LONG", "COMMAND_INT"):
                self.log.append(self._record(msg, None, executed=False))
            return
        if kind == "HEARTBEAT":
            self._on_heartbeat(msg)
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            self._on_setpoint(msg)
        elif kind == "FILE_TRANSFER_PROTOCOL":
            self._on_ftp(msg)
        elif kind in ("COMMAND_LONG", "COMMAND_INT"):
            self._on_command(msg)
        elif kind == "PARAM_REQUEST_READ":
            self._on_param_read(msg)
        elif kind == "PARAM_REQUEST_LIST":
            if not self.faults.no_params:
                for i, name in enumerate(self.params):
                    self._send_param(name, i)
        elif kind == "PARAM_SET":
            self._on_param_set(msg)
        elif kind == "REQUEST_DATA_STREAM":
            self._on_data_stream(msg)
        elif kind == "MISSION_COUNT":
            self._on_mission_count(msg)
        elif kind == "MISSION_ITEM_INT":
            self._on_mission_item(msg)
        elif kind == "MISSION_REQUEST_LIST":
            n = len(self.fence) if msg.mission_type == FENCE else 0
            self._send(
                self.mav.mission_count_encode(
                    msg.get_srcSystem(), msg.get_srcComponent(), n, msg.mission_type
                )
            )
        elif kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            self._on_mission_request(msg)
        elif kind == "MISSION_CLEAR_ALL":
            if msg.mission_type == FENCE:
                self.fence = []
            self._send(
                self.mav.mission_ack_encode(
                    msg.get_srcSystem(),
                    msg.get_srcComponent(),
                    R.MAV_MISSION_ACCEPTED,
                    msg.mission_type,
                )
            )

    def _on_data_stream(self, msg: Message) -> None:
        """REQUEST_DATA_STREAM (what MAVProxy and QGroundControl send ArduPilot): start
        streams every telemetry message at its usual rate; stop leaves the HEARTBEAT."""
        if msg.start_stop and msg.req_message_rate > 0:
            for msg_id, period in TELEMETRY_S.items():
                self.intervals.setdefault(msg_id, period)
        elif not msg.start_stop:
            self.intervals = {R.MAVLINK_MSG_ID_HEARTBEAT: TELEMETRY_S[R.MAVLINK_MSG_ID_HEARTBEAT]}

    def _on_heartbeat(self, msg: Message) -> None:
        # Any component of the GCS system counts (GCS_MAVLINK::handle_heartbeat): a daemon
        # that set MAV_GCS_SYSID to the vehicle's own id is its GCS of record.
        if self.p.name == "ardupilot" and msg.get_srcSystem() == int(self.param("MAV_GCS_SYSID")):
            self.gcs_seen_at = time.monotonic()

    def _on_ftp(self, msg: Message) -> None:
        """Answer at once (NAK: no files here) so a GCS falls back without a timeout."""
        if int(msg.target_component) not in (0, AUTOPILOT_COMPID):
            return
        payload = ftp.reply(msg.payload)
        if payload is None:
            return
        self._event(f"ftp opcode {msg.payload[3]} answered")
        self._send(
            self.mav.file_transfer_protocol_encode(
                0, msg.get_srcSystem(), msg.get_srcComponent(), payload
            )
        )

    # -- offboard setpoints ------------------------------------------------------------------

    def _on_setpoint(self, msg: Message) -> None:
        if msg.coordinate_frame != R.MAV_FRAME_LOCAL_NED:
            return
        mask = int(msg.type_mask)
        if mask & IGNORE_POSITION == IGNORE_POSITION:
            kind = "velocity"
            sp = (float(msg.vx), float(msg.vy), float(msg.vz))
        elif mask & IGNORE_VELOCITY == IGNORE_VELOCITY:
            kind = "position"
            sp = (float(msg.x), float(msg.y), float(msg.z))
        else:
            return  # position + velocity feed-forward: not modelled
        if not all(math.isfinite(v) for v in sp):
            return
        self.setpoint = (kind, *sp)
        self.setpoint_at = time.monotonic()
        self.setpoints += 1
        self._guided_stopped = False
        if self._role() == "offboard" and self.armed and self.landed == IN_AIR:
            self._apply_setpoint()

    def _apply_setpoint(self) -> None:
        assert self.setpoint is not None
        kind, a, b, _c = self.setpoint
        if kind == "velocity":
            self.goto_target = None
            self.world.set_velocity(self.uav, (a, b))
            self._avoid_fence()  # not even one tick toward the fence
        elif self._fenced_out(a, b):
            self._event(f"guided target N {a:.1f} E {b:.1f} outside the fence: ignored")
        else:
            self.goto_target = (a, b)

    def _fenced_out(self, n: float, e: float) -> bool:
        """ArduCopter's GUIDED refuses a destination outside its enabled fence
        (``ModeGuided::set_destination``: ``check_destination_within_fence``)."""
        return (
            self.p.name == "ardupilot"
            and self.param("FENCE_ENABLE") >= 1
            and bool(self.fence)
            and not self._inside_fence(n, e)
        )

    def _avoid_fence(self) -> None:
        """ArduCopter's simple avoidance (AVOID_ENABLE fence bit) in GUIDED velocity
        control: a velocity toward the fence stops FENCE_MARGIN short of it (recorded from
        SITL: 3 m/s north at a fence 8 m north stopped at 6.2 m)."""
        if (
            self.p.name != "ardupilot"
            or self.landed != IN_AIR
            or self._role() != "offboard"
            or self.goto_target is not None
            or self.param("FENCE_ENABLE") < 1
            or not self.fence
            or not int(self.param("AVOID_ENABLE")) & 2
        ):
            return
        b = self.world.body(self.uav)
        vn, ve = (b.vn, b.ve) if b.speed >= 0.05 else (b.sp_n, b.sp_e)
        speed = math.hypot(vn, ve)
        if speed < 0.05:
            return
        # the margin plus the distance it takes to brake at the world's acceleration limit
        reach = self.param("FENCE_MARGIN") + b.speed**2 / (2 * self.world.max_accel)
        ahead = (b.north + vn / speed * reach, b.east + ve / speed * reach)
        if self._inside_fence(b.north, b.east) and not self._inside_fence(*ahead):
            self.world.hold(self.uav)

    # -- commands ----------------------------------------------------------------------------

    def _record(self, msg: Message, result: int | None, executed: bool) -> CommandRecord:
        if msg.get_type() == "COMMAND_LONG":
            params = (
                msg.param1,
                msg.param2,
                msg.param3,
                msg.param4,
                msg.param5,
                msg.param6,
                msg.param7,
            )
            confirmation = int(msg.confirmation)
        else:
            params = (
                msg.param1,
                msg.param2,
                msg.param3,
                msg.param4,
                float(msg.x),
                float(msg.y),
                msg.z,
            )
            confirmation = 0
        return CommandRecord(
            time.monotonic(),
            (msg.get_srcSystem(), msg.get_srcComponent()),
            (int(msg.target_system), int(msg.target_component)),
            int(msg.command),
            tuple(float(p) for p in params),
            confirmation,
            result,
            executed,
        )

    def _ack(self, command: int, result: int, src: tuple[int, int], progress: int = 0) -> None:
        if self.faults.no_acks:
            return
        self._send(self.mav.command_ack_encode(command, result, progress, 0, src[0], src[1]))

    def _on_command(self, msg: Message) -> None:
        rec = self._record(msg, None, executed=True)
        key = (rec.src[0], rec.src[1], rec.command)
        cached = self._dup.get(key)
        if (
            rec.confirmation > 0
            and cached is not None
            and self._last_cmd.get(rec.src) == rec.command  # nothing else ran since
            and _same(cached[0], rec.params)
            and rec.t - cached[1] <= DUPLICATE_WINDOW_S
        ):
            # A retry of a command we already ran (its ACK was lost): answer, don't re-run.
            self.log.append(
                CommandRecord(**{**rec.__dict__, "result": cached[2], "executed": False})
            )
            self._ack(rec.command, cached[2], rec.src)
            return
        delay = self.faults.slow_commands.get(rec.command)
        result = self._execute(rec, msg)
        self._dup[key] = (rec.params, rec.t, result)
        self._last_cmd[rec.src] = rec.command
        self.log.append(CommandRecord(**{**rec.__dict__, "result": result}))
        if delay is not None and result == ACCEPTED:
            self._ack(rec.command, R.MAV_RESULT_IN_PROGRESS, rec.src, progress=0)
            self._slow.append((time.monotonic() + delay, rec.command, rec.src))
        else:
            self._ack(rec.command, result, rec.src)

    def _execute(self, rec: CommandRecord, msg: Message) -> int:
        c, p = rec.command, rec.params
        if c == R.MAV_CMD_COMPONENT_ARM_DISARM:
            return self._arm(p[0] >= 0.5, p[1] == FORCE_DISARM)
        if c == R.MAV_CMD_NAV_TAKEOFF:
            return self._takeoff(p[6])
        if c == R.MAV_CMD_NAV_LAND:
            result = self._land()
            if result == ACCEPTED and self.p.name == "px4":
                self._statustext(*texts.PX4_LAND)  # the commander says so for NAV_LAND only
            return result
        if c == R.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self._rtl()
        if c == R.MAV_CMD_DO_SET_MODE:
            return self._do_set_mode(p[0], p[1], p[2])
        if c == R.MAV_CMD_DO_REPOSITION and msg.get_type() == "COMMAND_INT":
            return self._reposition(int(msg.x), int(msg.y), int(p[1]))
        if c == R.MAV_CMD_SET_MESSAGE_INTERVAL:
            msg_id, interval = int(p[0]), p[1]
            if interval < 0:
                self.intervals.pop(msg_id, None)
            elif interval == 0:
                if msg_id in TELEMETRY_S:
                    self.intervals[msg_id] = TELEMETRY_S[msg_id]
            else:
                self.intervals[msg_id] = interval / 1e6
            return ACCEPTED
        if c == R.MAV_CMD_REQUEST_MESSAGE:
            return ACCEPTED if self._send_message(int(p[0])) else DENIED
        if c == R.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return (
                ACCEPTED if self._send_message(R.MAVLINK_MSG_ID_AUTOPILOT_VERSION) else UNSUPPORTED
            )
        if c == R.MAV_CMD_GET_HOME_POSITION:
            self._send_message(R.MAVLINK_MSG_ID_HOME_POSITION)
            return ACCEPTED
        return UNSUPPORTED

    @property
    def prearm_ready(self) -> bool:
        """The autopilot's arming checks pass (the SYS_STATUS pre-arm bit)."""
        return time.monotonic() - self.t0 >= self.prearm_s

    def _arm(self, arm: bool, force: bool) -> int:
        if arm:
            if not self.armed and not self.prearm_ready and not force:
                if self.p.name == "ardupilot":  # ArduCopter: FAILED, and why (AP_Arming)
                    self._statustext(*texts.AP_ARM_NOT_READY)
                self._event("arming refused: checks not passed")
                return FAILED
            if not self.armed:
                self.armed = True
                self._event("armed")
                if self.p.name == "ardupilot":
                    self._statustext(*texts.AP_ARMING)
                self.send_heartbeat()
            return ACCEPTED
        if self.landed != ON_GROUND and not force:
            return DENIED
        self._disarm("disarm command")
        return ACCEPTED

    def _disarm(self, why: str) -> None:
        if self.armed:
            self.armed = False
            self._event(f"disarmed ({why})")
            if self.p.name == "ardupilot":
                self._statustext(*texts.AP_DISARMING)
            self.send_heartbeat()

    def _takeoff(self, param7: float) -> int:
        if not self.armed or self.landed != ON_GROUND:
            return DENIED
        if self.p.name == "px4":
            target = (
                (param7 - self.origin.alt_m)
                if math.isfinite(param7)
                else self.param("MIS_TAKEOFF_ALT")
            )
        else:
            if self.mode != "GUIDED":
                return DENIED
            target = param7
        if not (math.isfinite(target) and 0.5 <= target <= 500):
            return DENIED
        self.climb_to = target
        self.landed = TAKING_OFF
        if self.p.name == "px4":
            self.set_mode("AUTO.TAKEOFF", "takeoff")
        self._event(f"takeoff to {target:.1f} m")
        return ACCEPTED

    def _land(self) -> int:
        if self.landed == ON_GROUND:
            return DENIED
        self.set_mode(self.p.roles["land"], "land")
        self.landed = LANDING
        return ACCEPTED

    def _rtl(self) -> int:
        if self.landed == ON_GROUND:
            return DENIED
        if self.p.name == "px4" and self.mode != self.p.roles["rtl"]:
            self._statustext(*texts.px4_rtl_start(self.alt))
        self.set_mode(self.p.roles["rtl"], "return")
        return ACCEPTED

    def _do_set_mode(self, p1: float, p2: float, p3: float) -> int:
        mode = self.p.mode_from_set_mode(p1, p2, p3)
        if mode is None:
            return UNSUPPORTED
        role = self.p.role_of(self.p.modes[mode])
        if self.p.name == "px4" and role == "offboard" and not self._stream_recent():
            self._statustext(*texts.px4_mode_refused(mode))
            return DENIED  # PX4 refuses offboard without a live setpoint stream
        if role == "land":
            return self._land()
        if role == "rtl":
            return self._rtl()
        if role == "takeoff" and self.p.name == "px4":
            return self._takeoff(math.nan)
        self.set_mode(mode, "commanded")
        return ACCEPTED

    def _reposition(self, lat_e7: int, lon_e7: int, flags: int) -> int:
        """DO_REPOSITION: PX4 flies there in Hold (AUTO.LOITER); ArduCopter flies there in
        GUIDED and stays GUIDED, and refuses outside GUIDED unless asked to change mode
        (``MAV_DO_REPOSITION_FLAGS_CHANGE_MODE``), as ``handle_command_int_do_reposition``."""
        if self.landed != IN_AIR:
            return DENIED
        n, e, _ = self.origin.to_local(lat_e7 / 1e7, lon_e7 / 1e7, self.origin.alt_m)
        if self.p.name == "ardupilot":
            return self._guided_goto(n, e, change_mode=bool(flags & CHANGE_MODE))
        self.set_mode(self.p.roles["hold"], "reposition")
        self.goto_target = (n, e)
        return ACCEPTED

    def _guided_goto(self, n: float, e: float, *, change_mode: bool) -> int:
        """ArduCopter's GUIDED position target: the vehicle flies there and stays GUIDED."""
        if self._fenced_out(n, e):
            return FAILED  # handle_command_int_do_reposition: set_destination refused
        if self.mode != "GUIDED":
            if not change_mode:
                return DENIED
            self.set_mode("GUIDED", "guided goto")
        self.setpoint = None  # a position target replaces any velocity target
        self._guided_stopped = False
        self.goto_target = (n, e)
        self._event(f"guided goto N {n:.1f} E {e:.1f}")
        return ACCEPTED

    # -- parameters --------------------------------------------------------------------------

    def _send_param(self, name: str, index: int) -> None:
        value, ptype = self.params[name]
        self._send(
            self.mav.param_value_encode(
                name.encode(), self.p.encode_param(value, ptype), ptype, len(self.params), index
            )
        )

    def _on_param_read(self, msg: Message) -> None:
        if self.faults.no_params:
            return
        names = list(self.params)
        name = _pid(msg)
        if msg.param_index >= 0 and msg.param_index < len(names):
            name = names[msg.param_index]
        if name in self.params:
            self._send_param(name, names.index(name))

    def _on_param_set(self, msg: Message) -> None:
        if self.faults.no_params:
            return
        name = _pid(msg)
        if name not in self.params:
            return
        ptype = self.params[name][1]
        value = self.p.decode_param(float(msg.param_value), ptype)
        if name not in self.faults.locked_params:
            self.params[name] = (value, ptype)
            self._event(f"param {name} = {value:g}")
        self._send_param(name, list(self.params).index(name))

    # -- mission protocol (fence) -----------------------------------------------------------

    def _on_mission_count(self, msg: Message) -> None:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if msg.mission_type != FENCE:
            self._send(
                self.mav.mission_ack_encode(
                    src[0], src[1], R.MAV_MISSION_UNSUPPORTED, msg.mission_type
                )
            )
            return
        self._upload = _Upload(FENCE, int(msg.count), [], src)
        if msg.count == 0:
            self.fence = []
            self._upload = None
            self._send(self.mav.mission_ack_encode(src[0], src[1], R.MAV_MISSION_ACCEPTED, FENCE))
            return
        self._request_next()

    def _request_next(self) -> None:
        up = self._upload
        assert up is not None
        up.asked_at = time.monotonic()
        up.tries += 1
        self._send(self.mav.mission_request_int_encode(up.src[0], up.src[1], len(up.items), FENCE))

    def _on_mission_item(self, msg: Message) -> None:
        if (
            self.p.name == "ardupilot"
            and msg.mission_type == R.MAV_MISSION_TYPE_MISSION
            and msg.current == GUIDED_REQUEST
        ):
            self._on_guided_request(msg)
            return
        up = self._upload
        if up is None or msg.mission_type != FENCE:
            return
        if msg.seq != len(up.items):
            return  # a duplicate or out of order: the pending request is re-sent on timeout
        up.items.append(msg)
        up.tries = 0
        if len(up.items) < up.count:
            self._request_next()
            return
        self.fence = up.items
        self._upload = None
        self.breached = False
        self._event(f"fence uploaded: {len(self.fence)} items")
        if self.p.name == "ardupilot":
            self._statustext(*texts.AP_FENCE_LOADED)
        self._send(self.mav.mission_ack_encode(up.src[0], up.src[1], R.MAV_MISSION_ACCEPTED, FENCE))

    def _on_guided_request(self, msg: Message) -> None:
        """MAVProxy's ``guided LAT LON ALT``: a MISSION_ITEM_INT with current=2, accepted
        in GUIDED only (ArduCopter ``do_guided``), answered with a MISSION_ACK."""
        ok = False
        if self.mode == "GUIDED" and self.landed == IN_AIR and msg.frame != R.MAV_FRAME_MISSION:
            lat, lon = int(msg.x) / 1e7, int(msg.y) / 1e7
            if -90 <= lat <= 90 and -180 <= lon <= 180:
                n, e, _ = self.origin.to_local(lat, lon, self.origin.alt_m)
                ok = self._guided_goto(n, e, change_mode=False) == ACCEPTED
        result = R.MAV_MISSION_ACCEPTED if ok else R.MAV_MISSION_ERROR
        self._send(
            self.mav.mission_ack_encode(
                msg.get_srcSystem(), msg.get_srcComponent(), result, R.MAV_MISSION_TYPE_MISSION
            )
        )

    def _on_mission_request(self, msg: Message) -> None:
        if msg.mission_type != FENCE or not 0 <= msg.seq < len(self.fence):
            return
        it = self.fence[msg.seq]
        self._send(
            self.mav.mission_item_int_encode(
                msg.get_srcSystem(),
                msg.get_srcComponent(),
                msg.seq,
                it.frame,
                it.command,
                0,
                1,
                it.param1,
                it.param2,
                it.param3,
                it.param4,
                it.x,
                it.y,
                it.z,
                FENCE,
            )
        )

    # -- geofence ------------------------------------------------------------------------------

    def _inside_fence(self, n: float, e: float) -> bool:
        lat, lon, _ = self.origin.to_global(n, e)
        x, y = lat * 1e7, lon * 1e7
        polygon: list[tuple[float, float]] = []
        inside = True
        for it in self.fence:
            if it.command == R.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION:
                polygon.append((float(it.x), float(it.y)))
                if len(polygon) == int(it.param1):
                    inside &= _point_in_polygon(x, y, polygon)
                    polygon = []
            elif it.command == R.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION:
                cn, ce, _ = self.origin.to_local(it.x / 1e7, it.y / 1e7, self.origin.alt_m)
                inside &= math.hypot(n - cn, e - ce) <= it.param1
        if self.p.name == "px4":
            hor = self.param("GF_MAX_HOR_DIST")
            if hor > 0 and math.hypot(n - self.home[0], e - self.home[1]) > hor:
                inside = False
            ver = self.param("GF_MAX_VER_DIST")
            if ver > 0 and self.alt > ver:
                inside = False
        return inside

    def _check_fence(self) -> None:
        if self.landed != IN_AIR:
            return
        if self.p.name == "ardupilot" and self.param("FENCE_ENABLE") < 1:
            return
        body = self.world.body(self.uav)
        inside = self._inside_fence(body.north, body.east)
        if inside:
            if self.breached and self.p.name == "ardupilot":
                self._statustext(*texts.AP_FENCE_CLEARED)
            self.breached = False
            return
        if self.breached:
            return
        self.breached = True
        action = int(self.param(self.p.fence_action_param))
        self._event(f"geofence breach (action {action})")
        self._statustext(*(texts.PX4_FAILSAFE if self.p.name == "px4" else texts.AP_FENCE_BREACH))
        if self.p.name == "px4":
            target = {2: "hold", 3: "rtl", 5: "land"}.get(action)
            if action == 4:
                self._terminate("geofence")
        else:
            target = {1: "rtl", 2: "land", 4: "hold"}.get(action)
        if target == "land":
            self._land()
        elif target == "rtl":
            self._rtl()
        elif target == "hold":
            self.set_mode(self.p.roles["hold"], "geofence")

    def _terminate(self, why: str) -> None:
        self.alt = 0.0
        self.landed = ON_GROUND
        self.world.hold(self.uav)
        self._disarm(f"flight termination: {why}")

    def _statustext(self, severity: int, text: str) -> None:
        """One STATUSTEXT, or chunks sharing a non-zero id when longer than 50 bytes
        (MAVLink 2 convention; the last chunk is shorter than 50 or NUL-terminated)."""
        self._event(f"statustext {severity}: {text.rstrip()}")
        raw = text.encode()
        if len(raw) <= TEXT_LEN:
            self._send(self.mav.statustext_encode(severity, raw))
            return
        self._text_id = self._text_id % 0xFFFF + 1
        chunks = [raw[i : i + TEXT_LEN] for i in range(0, len(raw), TEXT_LEN)]
        if len(chunks[-1]) == TEXT_LEN:
            chunks.append(b"")
        for seq, chunk in enumerate(chunks):
            self._send(self.mav.statustext_encode(severity, chunk, self._text_id, seq))

    # -- time ------------------------------------------------------------------------------

    def tick(self, now: float) -> None:
        dt = max(0.0, now - self._last_tick) * self.time_scale
        self._last_tick = now
        self._failsafes(now)
        self._gcs_failsafe(now)
        self._vertical(dt)
        self._guidance()
        self._avoid_fence()
        self._check_fence()
        for due, command, src in [s for s in self._slow if s[0] <= now]:
            self._slow.remove((due, command, src))
            self._ack(command, ACCEPTED, src, progress=100)
        up = self._upload
        if up is not None and now - up.asked_at > 0.25:
            if up.tries >= 10:
                self._upload = None
                self._send(
                    self.mav.mission_ack_encode(
                        up.src[0], up.src[1], R.MAV_MISSION_OPERATION_CANCELLED, FENCE
                    )
                )
            else:
                self._request_next()
        self._telemetry(now)

    def _failsafes(self, now: float) -> None:
        if self.landed != IN_AIR:
            return
        role = self._role()
        silent = now - self.setpoint_at
        if self.p.name == "px4" and role == "offboard" and silent > self.param("COM_OF_LOSS_T"):
            action = int(self.param("COM_OBL_RC_ACT"))
            self._event(f"offboard loss after {silent:.2f} s (COM_OBL_RC_ACT={action})")
            self._statustext(*texts.PX4_FAILSAFE)
            if action == 3:
                self._rtl()
            elif action == 4:
                self._land()
            elif action in (6, 7):
                self._terminate("offboard loss")
            else:  # 5 Hold; 0-2 hand over to RC sticks, which nobody holds here: hold
                self.set_mode("AUTO.LOITER", "offboard loss")
        elif (
            self.p.name == "ardupilot"
            and role == "offboard"
            and self.setpoint is not None
            and self.setpoint[0] == "velocity"
            and not self._guided_stopped
            and silent > self.param("GUID_TIMEOUT")
        ):
            self._guided_stopped = True  # Copter stops when a velocity target expires
            self._event(f"guided velocity target expired after {silent:.2f} s")
            self.world.hold(self.uav)

    def _gcs_failsafe(self, now: float) -> None:
        """ArduCopter's GCS failsafe: armed only once MAV_GCS_SYSID was heard; after
        FS_GCS_TIMEOUT of silence FS_GCS_ENABLE decides (1, 2: RTL; 3 SmartRTL and 6 Auto
        RTL, unavailable here: RTL; 4 SmartRTL, unavailable: land; 5: land; 7: brake).
        The daemon heartbeats with the vehicle's own system id, so it never counts."""
        if self.p.name != "ardupilot" or self.gcs_seen_at is None:
            return
        enable = int(self.param("FS_GCS_ENABLE"))
        silent = now - self.gcs_seen_at > self.param("FS_GCS_TIMEOUT")
        if enable == 0 or silent == self.gcs_failsafe:
            return
        self.gcs_failsafe = silent
        if not silent:
            self._event("GCS failsafe cleared")
            self._statustext(*texts.AP_GCS_FAILSAFE_CLEARED)
            return
        self._event(f"GCS failsafe (FS_GCS_ENABLE={enable})")
        if self.armed and self.landed == ON_GROUND:
            self._statustext(*texts.AP_GCS_FAILSAFE_DISARM)
            self._disarm("GCS failsafe")
            return
        self._statustext(*texts.AP_GCS_FAILSAFE)
        if not self.armed or self.landed != IN_AIR:
            return
        # No SMART_RTL mode and no mission here: ArduCopter's fallbacks, with their texts.
        fallback = texts.AP_FAILSAFE_FALLBACK.get(enable)
        if fallback is not None:
            self._statustext(*fallback)
        if enable in (4, 5):
            self._land()
        elif enable == 7:
            self.set_mode("BRAKE", "GCS failsafe")
        else:
            self._rtl()

    def _vertical(self, dt: float) -> None:
        if self.landed == TAKING_OFF:
            up = (
                self.param("MPC_TKO_SPEED")
                if self.p.name == "px4"
                else self.param("WPNAV_SPEED_UP") / 100.0
            )
            self.vz = -up
            self.alt = min(self.climb_to, self.alt + up * dt)
            if self.alt >= self.climb_to - 1e-6:
                self.landed = IN_AIR
                self.vz = 0.0
                self._event(f"reached {self.alt:.1f} m")
                if self.p.name == "px4":
                    self.set_mode("AUTO.LOITER", "takeoff complete")
                else:
                    self.send_heartbeat()
        elif self.landed == LANDING or (
            self.landed == IN_AIR and self._role() == "rtl" and self._at_home()
        ):
            if self.landed != LANDING:
                self.landed = LANDING
                self.world.hold(self.uav)  # over home: straight down, no drift
            down = (
                self.param("MPC_LAND_SPEED")
                if self.p.name == "px4"
                else self.param("LAND_SPEED") / 100.0
            )
            self.vz = down
            self.alt = max(0.0, self.alt - down * dt)
            if self.alt <= 0.0:
                self.landed = ON_GROUND
                self.vz = 0.0
                self.world.hold(self.uav)
                self._event("landed")
                self._disarm("landed")

    def _at_home(self) -> bool:
        b = self.world.body(self.uav)
        return math.hypot(b.north - self.home[0], b.east - self.home[1]) < 1.0 and b.speed < 0.5

    def _guidance(self) -> None:
        """Steer the body toward a position target (goto, reposition, return home)."""
        if self.landed != IN_AIR:
            return
        target = self.home if self._role() == "rtl" else self.goto_target
        if target is None:
            return
        b = self.world.body(self.uav)
        dn, de = target[0] - b.north, target[1] - b.east
        dist = math.hypot(dn, de)
        if dist < 0.05:
            self.world.hold(self.uav)
            return
        speed = min(self.world.max_speed, dist / 0.5)
        self.world.set_velocity(self.uav, (dn / dist * speed, de / dist * speed))

    # -- telemetry ---------------------------------------------------------------------------

    def _telemetry(self, now: float) -> None:
        for msg_id, period in self.intervals.items():
            due = self._due.get(msg_id, 0.0)
            if now >= due:
                self._due[msg_id] = now + period
                if msg_id == R.MAVLINK_MSG_ID_HEARTBEAT and self.faults.no_heartbeats:
                    continue
                self._send_message(msg_id)

    def send_heartbeat(self) -> None:
        if self.faults.no_heartbeats:
            return
        base = R.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (
            R.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0
        )
        status = R.MAV_STATE_ACTIVE if self.armed else R.MAV_STATE_STANDBY
        self._send(
            self.mav.heartbeat_encode(
                R.MAV_TYPE_QUADROTOR, self.p.autopilot, base, self.p.modes[self.mode], status
            )
        )

    def _send_message(self, msg_id: int) -> bool:
        if msg_id == R.MAVLINK_MSG_ID_HEARTBEAT:
            self.send_heartbeat()
            return True
        msg = encode(self, msg_id)
        if msg is None:
            return False
        self._send(msg)
        return True


def _point_in_polygon(x: float, y: float, poly: list[tuple[float, float]]) -> bool:
    inside = False
    j = len(poly) - 1
    for i in range(len(poly)):
        xi, yi = poly[i]
        xj, yj = poly[j]
        if (yi > y) != (yj > y) and x < (xj - xi) * (y - yi) / (yj - yi) + xi:
            inside = not inside
        j = i
    return inside
