"""The emulator as an independent ground station sees it: pymavlink's ``mavutil`` (not our
codec, not our backend) talks to emulated autopilots over real UDP and checks STATUSTEXT
on refused modes and failsafes, the SYS_STATUS geofence bits, FTP answered at once with a
NAK, and ArduPilot's GUIDED go-to staying GUIDED."""

from __future__ import annotations

import math
import os
import struct
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import pytest

from aeroweaver_edge.sim.emulator import ftp
from aeroweaver_edge.sim.emulator.host import EmulatorHost, EmulatorOptions
from aeroweaver_edge.vehicle.mavlink.personality import PX4
from tests.helpers.mav import ThreadedEmulator, free_udp_ports

os.environ["MAVLINK20"] = "1"  # before mavutil picks its dialect
from pymavlink import mavutil

M = mavutil.mavlink
GEOFENCE = M.MAV_SYS_STATUS_GEOFENCE
PX4_LOITER = PX4.modes["AUTO.LOITER"]
AP_GUIDED, AP_BRAKE, AP_RTL, AP_LAND = 4, 17, 6, 9


@dataclass
class Gcs:
    """A bare mavutil ground station (system 255, component 190) on a udpout link."""

    conn: Any
    texts: list[tuple[float, int, str]] = field(default_factory=list)
    last: dict[str, Any] = field(default_factory=dict)
    keepalive: bool = True  # send our 1 Hz HEARTBEAT while waiting
    tick: Callable[[], None] | None = None  # e.g. a setpoint stream, called every loop
    _hb_at: float = 0.0

    def pump(self) -> Any:
        now = time.monotonic()
        if self.keepalive and now - self._hb_at >= 0.5:
            self._hb_at = now
            self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        if self.tick is not None:
            self.tick()
        msg = self.conn.recv_match(blocking=True, timeout=0.02)
        if msg is None:
            return None
        kind = msg.get_type()
        self.last[kind] = msg
        if kind == "STATUSTEXT":
            self.texts.append((time.monotonic(), int(msg.severity), str(msg.text)))
        return msg

    def wait(self, what: str, cond: Callable[[Any], bool], timeout: float = 5.0) -> Any:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            msg = self.pump()
            if msg is not None and cond(msg):
                return msg
        raise AssertionError(f"no {what} within {timeout} s; texts seen: {self.texts}")

    def text(self, prefix: str, timeout: float = 5.0) -> tuple[int, str]:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for _t, sev, txt in self.texts:
                if txt.startswith(prefix):
                    return sev, txt
            self.pump()
        raise AssertionError(f"no STATUSTEXT {prefix!r} within {timeout} s: {self.texts}")

    def mode(self) -> int:
        return int(self.last["HEARTBEAT"].custom_mode)

    def command(self, cmd: int, *params: float) -> int:
        p = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(1, 1, cmd, 0, *p)
        ack = self.wait("COMMAND_ACK", lambda m: m.get_type() == "COMMAND_ACK" and m.command == cmd)
        return int(ack.result)

    def reposition(self, n: float, e: float, host: EmulatorHost, flags: int = 0) -> int:
        lat, lon = host.vehicles[0].origin.to_global_e7(n, e)
        self.conn.mav.command_int_send(
            1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_DO_REPOSITION, 0, 0,
            -1, flags, 0, math.nan, lat, lon, 5.0,
        )  # fmt: skip
        ack = self.wait(
            "COMMAND_ACK",
            lambda m: m.get_type() == "COMMAND_ACK" and m.command == M.MAV_CMD_DO_REPOSITION,
        )
        return int(ack.result)

    def in_air(self, timeout: float = 10.0) -> None:
        self.wait(
            "IN_AIR",
            lambda m: (
                m.get_type() == "EXTENDED_SYS_STATE" and m.landed_state == M.MAV_LANDED_STATE_IN_AIR
            ),
            timeout,
        )


@contextmanager
def ground_station(
    personality: str, params: dict[str, float] | None = None
) -> Iterator[tuple[EmulatorHost, Gcs]]:
    """One emulated vehicle on its own thread and a mavutil GCS talking to its UDP port."""
    (listen,) = free_udp_ports(1)
    opts = EmulatorOptions(
        uavs=1, personality=personality, local_base=listen, remote_ports=[9],
        time_scale=4.0, params=params or {},
    )  # fmt: skip
    with ThreadedEmulator(opts) as host:
        conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{listen}", source_system=255, source_component=190
        )
        try:
            gcs = Gcs(conn)
            gcs.wait("HEARTBEAT", lambda m: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1)
            # what MAVProxy and QGroundControl do: ArduPilot streams only what is asked for
            conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_ALL, 4, 1)
            yield host, gcs
        finally:
            conn.close()


def _ftp_request(opcode: int, seq: int, path: bytes = b"") -> list[int]:
    head = struct.pack("<HBBBBBBI", seq, 0, opcode, len(path), 0, 0, 0, 0)
    return list((head + path).ljust(251, b"\x00"))


@pytest.mark.parametrize("personality", ["px4", "ardupilot"])
def test_ftp_is_answered_at_once_with_a_nak(personality: str) -> None:
    with ground_station(personality) as (_host, gcs):
        cases = [
            (ftp.OPEN_FILE_RO, b"@PARAM/param.pck", ftp.NAK, ftp.FILE_NOT_FOUND),
            (ftp.LIST_DIRECTORY, b"/", ftp.NAK, ftp.FILE_NOT_FOUND),
            (ftp.READ_FILE, b"", ftp.NAK, ftp.INVALID_SESSION),
            (ftp.CREATE_FILE, b"/x", ftp.NAK, ftp.FILE_PROTECTED),
            (99, b"", ftp.NAK, ftp.UNKNOWN_COMMAND),
            (ftp.RESET_SESSIONS, b"", ftp.ACK, None),
        ]
        for seq, (opcode, path, answer, error) in enumerate(cases, start=10):
            sent = time.monotonic()
            gcs.conn.mav.file_transfer_protocol_send(0, 1, 1, _ftp_request(opcode, seq, path))
            got = gcs.wait(
                "FTP reply",
                lambda m: m.get_type() == "FILE_TRANSFER_PROTOCOL",
                timeout=1.0,
            )
            took = time.monotonic() - sent
            raw = bytes(got.payload)
            rseq, _session, op, size, req = struct.unpack_from("<HBBBB", raw)
            assert (got.target_system, got.target_component) == (255, 190)
            assert (rseq, op, req) == (seq + 1, answer, opcode)
            assert took < 0.5, f"FTP opcode {opcode} answered after {took:.3f} s"
            if error is not None:
                assert (size, raw[12]) == (1, error)


def test_px4_says_what_px4_says_on_a_refused_mode_a_landing_and_an_offboard_loss() -> None:
    params = {"COM_OF_LOSS_T": 0.3}
    with ground_station("px4", params) as (host, gcs):
        assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
        assert gcs.command(M.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7) == M.MAV_RESULT_ACCEPTED
        gcs.in_air()
        offboard = PX4().set_mode_params("OFFBOARD", armed=True)
        assert gcs.command(M.MAV_CMD_DO_SET_MODE, *offboard) == M.MAV_RESULT_DENIED
        assert gcs.text("Switching to Offboard") == (
            M.MAV_SEVERITY_CRITICAL,
            "Switching to Offboard is currently not available\t",
        )

        def stream() -> None:  # zero-velocity setpoints, as a companion streams them
            gcs.conn.mav.set_position_target_local_ned_send(
                0, 1, 1, M.MAV_FRAME_LOCAL_NED, 0x0DC7, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
            )

        gcs.tick = stream
        end = time.monotonic() + 0.3
        while time.monotonic() < end:
            gcs.pump()
        assert gcs.command(M.MAV_CMD_DO_SET_MODE, *offboard) == M.MAV_RESULT_ACCEPTED
        gcs.wait("OFFBOARD", lambda m: m.get_type() == "HEARTBEAT" and gcs.mode() == 6 << 16)

        host.vehicles[0].faults.deaf = True  # fault injection: the vehicle hears nothing
        cut = time.monotonic()
        assert gcs.text("Failsafe activated", timeout=3.0) == (
            M.MAV_SEVERITY_CRITICAL,
            "Failsafe activated\t",
        )
        said = next(t for t, _s, txt in gcs.texts if txt.startswith("Failsafe activated"))
        assert said - cut < 0.3 + 0.5  # COM_OF_LOSS_T plus a tick and the loopback
        gcs.wait("Hold", lambda m: m.get_type() == "HEARTBEAT" and gcs.mode() == PX4_LOITER)

        host.vehicles[0].faults.deaf = False
        gcs.tick = None
        assert gcs.command(M.MAV_CMD_NAV_LAND, 0, 0, 0, math.nan) == M.MAV_RESULT_ACCEPTED
        assert gcs.text("Landing at") == (M.MAV_SEVERITY_INFO, "Landing at current position\t")
        # PX4 reports no geofence in SYS_STATUS
        status = gcs.wait("SYS_STATUS", lambda m: m.get_type() == "SYS_STATUS")
        assert status.onboard_control_sensors_present & GEOFENCE == 0


@pytest.mark.parametrize(
    ("enable", "mode", "fallback"),
    [(1, AP_RTL, None), (4, AP_LAND, "SmartRTL Unavailable, Using Land Mode")],
)
def test_ardupilot_gcs_failsafe_says_so_and_acts(enable: int, mode: int, fallback: str) -> None:
    params = {"FS_GCS_TIMEOUT": 1.0, "FS_GCS_ENABLE": enable}
    with ground_station("ardupilot", params) as (host, gcs):
        assert gcs.command(M.MAV_CMD_DO_SET_MODE, 1, AP_GUIDED) == M.MAV_RESULT_ACCEPTED
        assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
        assert gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5) == M.MAV_RESULT_ACCEPTED
        gcs.in_air()
        # ArduCopter says it arms (recorded from SITL); a mode change that succeeds is no text
        assert [t for _at, _sev, t in gcs.texts] == ["Arming motors"]

        host.vehicles[0].faults.deaf = True  # our heartbeats stop reaching the vehicle
        sev, txt = gcs.text("GCS Failsafe", timeout=4.0)
        assert (sev, txt) == (M.MAV_SEVERITY_WARNING, "GCS Failsafe")
        if fallback is not None:  # no SMART_RTL mode here: ArduCopter's fallback and its text
            assert gcs.text(fallback) == (M.MAV_SEVERITY_WARNING, fallback)
        gcs.wait(f"mode {mode}", lambda m: m.get_type() == "HEARTBEAT" and gcs.mode() == mode)

        host.vehicles[0].faults.deaf = False
        assert gcs.text("GCS Failsafe Cleared", timeout=3.0)[0] == M.MAV_SEVERITY_WARNING


def test_ardupilot_guided_goto_stays_guided() -> None:
    with ground_station("ardupilot") as (host, gcs):
        _airborne_guided(gcs)

        assert gcs.reposition(8.0, 0.0, host) == M.MAV_RESULT_ACCEPTED
        origin = host.vehicles[0].origin

        def at(n: float, e: float) -> Callable[[Any], bool]:
            def ok(m: Any) -> bool:
                if m.get_type() != "GLOBAL_POSITION_INT":
                    return False
                pn, pe, _ = origin.to_local(m.lat / 1e7, m.lon / 1e7, origin.alt_m)
                return math.hypot(pn - n, pe - e) < 0.3

            return ok

        gcs.wait("arrival at (8, 0)", at(8.0, 0.0), timeout=8.0)
        for _ in range(3):  # it stays GUIDED on the way and after arrival
            gcs.wait("HEARTBEAT", lambda m: m.get_type() == "HEARTBEAT")
            assert gcs.mode() == AP_GUIDED

        # MAVProxy's `guided LAT LON ALT`: MISSION_ITEM_INT current=2, answered by MISSION_ACK
        lat, lon = origin.to_global_e7(0.0, 6.0)
        gcs.conn.mav.mission_item_int_send(
            1, 1, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_WAYPOINT, 2, 0,
            0, 0, 0, 0, lat, lon, 5.0, M.MAV_MISSION_TYPE_MISSION,
        )  # fmt: skip
        ack = gcs.wait("MISSION_ACK", lambda m: m.get_type() == "MISSION_ACK")
        assert ack.type == M.MAV_MISSION_ACCEPTED
        gcs.wait("arrival at (0, 6)", at(0.0, 6.0), timeout=8.0)
        assert gcs.mode() == AP_GUIDED

        # Outside GUIDED ArduCopter refuses a reposition unless told to change mode.
        assert gcs.command(M.MAV_CMD_DO_SET_MODE, 1, AP_BRAKE) == M.MAV_RESULT_ACCEPTED
        assert gcs.reposition(3.0, 3.0, host) == M.MAV_RESULT_DENIED
        change = M.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
        assert gcs.reposition(3.0, 3.0, host, flags=change) == M.MAV_RESULT_ACCEPTED
        gcs.wait("GUIDED", lambda m: m.get_type() == "HEARTBEAT" and gcs.mode() == AP_GUIDED)
        gcs.wait("arrival at (3, 3)", at(3.0, 3.0), timeout=8.0)
        assert gcs.mode() == AP_GUIDED


def _upload_square_fence(gcs: Gcs, host: EmulatorHost, half_m: float) -> None:
    origin = host.vehicles[0].origin
    corners = [(-half_m, -half_m), (-half_m, half_m), (half_m, half_m), (half_m, -half_m)]
    gcs.conn.mav.mission_count_send(1, 1, len(corners), M.MAV_MISSION_TYPE_FENCE)
    while True:
        msg = gcs.wait(
            "fence request or ack",
            lambda m: m.get_type() in ("MISSION_REQUEST_INT", "MISSION_ACK"),
        )
        if msg.get_type() == "MISSION_ACK":
            assert msg.type == M.MAV_MISSION_ACCEPTED
            return
        lat, lon = origin.to_global_e7(*corners[msg.seq])
        gcs.conn.mav.mission_item_int_send(
            1, 1, msg.seq, M.MAV_FRAME_GLOBAL, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
            0, 1, len(corners), 0, 0, 0, lat, lon, 0, M.MAV_MISSION_TYPE_FENCE,
        )  # fmt: skip


def _breach_by_moving_the_fence(gcs: Gcs, host: EmulatorHost) -> None:
    """In GUIDED ArduCopter never flies out of its fence (a target outside it is refused:
    recorded from SITL), so the fence moves: 4 m north inside a 6 m fence, then a 2 m one."""
    _upload_square_fence(gcs, host, half_m=6.0)
    _airborne_guided(gcs)
    assert gcs.reposition(15.0, 0.0, host) == M.MAV_RESULT_FAILED  # outside: refused
    assert gcs.reposition(4.0, 0.0, host) == M.MAV_RESULT_ACCEPTED
    body = host.vehicles[0].world.body("uav0")
    deadline = time.monotonic() + 10
    while body.north < 3.8:
        assert time.monotonic() < deadline, "did not reach 4 m north"
        time.sleep(0.05)
    _upload_square_fence(gcs, host, half_m=2.0)  # now the vehicle is outside


def _bits(m: Any) -> tuple[bool, bool, bool]:
    """MAV_SYS_STATUS_GEOFENCE in (present, enabled, health)."""
    return (
        bool(m.onboard_control_sensors_present & GEOFENCE),
        bool(m.onboard_control_sensors_enabled & GEOFENCE),
        bool(m.onboard_control_sensors_health & GEOFENCE),
    )


def _status(gcs: Gcs, want: tuple[bool, bool, bool], timeout: float = 5.0) -> None:
    gcs.wait(
        f"SYS_STATUS geofence bits {want}",
        lambda m: m.get_type() == "SYS_STATUS" and _bits(m) == want,
        timeout,
    )


def _airborne_guided(gcs: Gcs) -> None:
    assert gcs.command(M.MAV_CMD_DO_SET_MODE, 1, AP_GUIDED) == M.MAV_RESULT_ACCEPTED
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5) == M.MAV_RESULT_ACCEPTED
    gcs.in_air()


def test_ardupilot_fence_health_bit_follows_the_breach() -> None:
    # FENCE_ACTION 0 (report only): present, not enabled; health clears while outside.
    with ground_station("ardupilot", {"FENCE_ACTION": 0, "FENCE_ENABLE": 1}) as (host, gcs):
        first = gcs.wait("SYS_STATUS", lambda m: m.get_type() == "SYS_STATUS")
        assert _bits(first) == (True, False, True)
        _breach_by_moving_the_fence(gcs, host)
        assert gcs.text("Polygon fence breached", timeout=8.0) == (
            M.MAV_SEVERITY_NOTICE,
            "Polygon fence breached",
        )
        _status(gcs, (True, False, False))
        assert gcs.mode() == AP_GUIDED  # report only: no action
        assert gcs.reposition(0.0, 0.0, host) == M.MAV_RESULT_ACCEPTED
        _status(gcs, (True, False, True), timeout=8.0)


def test_ardupilot_fence_breach_returns_home_and_fence_enable_clears_the_enabled_bit() -> None:
    # ArduCopter ships with FENCE_ENABLE 0 (the daemon turns it on at preflight)
    with ground_station("ardupilot", {"FENCE_ENABLE": 1}) as (host, gcs):
        first = gcs.wait("SYS_STATUS", lambda m: m.get_type() == "SYS_STATUS")
        assert _bits(first) == (True, True, True)  # FENCE_TYPE 7, FENCE_ENABLE 1, ACTION 1
        _breach_by_moving_the_fence(gcs, host)
        assert gcs.text("Polygon fence breached", timeout=8.0)[0] == M.MAV_SEVERITY_NOTICE
        gcs.wait("RTL", lambda m: m.get_type() == "HEARTBEAT" and gcs.mode() == AP_RTL)

    with ground_station("ardupilot", {"FENCE_ENABLE": 0}) as (_host, gcs):
        status = gcs.wait("SYS_STATUS", lambda m: m.get_type() == "SYS_STATUS")
        assert _bits(status) == (True, False, True)
