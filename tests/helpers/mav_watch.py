"""An independent ground-station ear: a UDP socket on its own thread that decodes what an
autopilot sends there and keeps a timeline (mode, armed, landed state, altitude, texts).
Kill tests and the SITL recordings read the vehicle through it, never through the daemon
under test."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from dataclasses import dataclass, field

from aeroweaver_edge.vehicle.mavlink.codec import Codec, Message, mavlink
from aeroweaver_edge.vehicle.mavlink.personality import Personality, for_autopilot

ARMED = mavlink.MAV_MODE_FLAG_SAFETY_ARMED


@dataclass
class Sample:
    t: float  # time.monotonic() of receipt
    mode: str
    armed: bool


@dataclass
class Watch:
    sysid: int
    personality: Personality | None = None
    samples: list[Sample] = field(default_factory=list)  # one per HEARTBEAT
    texts: list[tuple[float, str]] = field(default_factory=list)
    alt_m: float = 0.0  # -LOCAL_POSITION_NED.z, last heard
    landed_state: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)

    @property
    def mode(self) -> str:
        with self.lock:
            return self.samples[-1].mode if self.samples else "?"

    @property
    def armed(self) -> bool:
        with self.lock:
            return bool(self.samples) and self.samples[-1].armed

    def first(self, since: float, pred: str, value: object) -> float | None:
        """Seconds from ``since`` to the first sample after it whose ``pred`` field is not
        (``mode``) or is (``armed``) ``value``; None if none yet."""
        with self.lock:
            for s in self.samples:
                if s.t < since:
                    continue
                if pred == "mode_left" and s.mode != value:
                    return s.t - since
                if pred == "armed" and s.armed == value:
                    return s.t - since
        return None


class MavWatcher:
    """Listen on ``host:port`` (0: pick one) and watch every autopilot heard there."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.sock.settimeout(0.2)
        self.port = int(self.sock.getsockname()[1])
        self.codec = Codec(250, 190)
        self.vehicles: dict[int, Watch] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="mav-watch", daemon=True)

    def __enter__(self) -> MavWatcher:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.sock.close()

    def watch(self, sysid: int) -> Watch:
        return self.vehicles.setdefault(sysid, Watch(sysid))

    def _run(self) -> None:
        answered: dict[tuple[str, int], float] = {}
        while not self._stop.is_set():
            try:
                data, addr = self.sock.recvfrom(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            for msg in self.codec.decode(data):
                self._on(msg)
            now = time.monotonic()
            if now - answered.get(addr, 0.0) > 1.0:
                answered[addr] = now
                self._answer(addr)

    def _answer(self, addr: tuple[str, int]) -> None:
        """A ground station's heartbeat and a request for every stream (4 Hz), once a second:
        ArduPilot sends texts and streams only on a channel that has heard from someone."""
        mav = self.codec.mav
        frames = [
            mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0),
            *(
                mav.request_data_stream_encode(sysid, 1, mavlink.MAV_DATA_STREAM_ALL, 4, 1)
                for sysid in list(self.vehicles)
            ),
        ]
        for frame in frames:
            with contextlib.suppress(OSError):
                self.sock.sendto(self.codec.encode(frame), addr)

    def _on(self, msg: Message) -> None:
        if msg.get_srcComponent() != 1:
            return
        w = self.watch(msg.get_srcSystem())
        kind = msg.get_type()
        now = time.monotonic()
        if kind == "HEARTBEAT":
            if msg.type == mavlink.MAV_TYPE_GCS:
                return
            if w.personality is None:
                w.personality = for_autopilot(int(msg.autopilot))
            name = (
                w.personality.mode_name(int(msg.custom_mode))
                if w.personality is not None
                else str(msg.custom_mode)
            )
            with w.lock:
                w.samples.append(Sample(now, name, bool(msg.base_mode & ARMED)))
        elif kind == "STATUSTEXT":
            with w.lock:
                w.texts.append((now, str(msg.text).rstrip("\x00")))
        elif kind == "LOCAL_POSITION_NED":
            w.alt_m = -float(msg.z)
        elif kind == "EXTENDED_SYS_STATE":
            w.landed_state = int(msg.landed_state)
