"""pymavlink's generated MAVLink 2 codec used purely as an encoder/decoder.

``MAVLINK20=1`` must be set before pymavlink is imported, or it starts in MAVLink 1; this
module is the only place that imports the dialect, so importing it first is enough.
"""

from __future__ import annotations

import hashlib
import os
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
os.environ["MAVLINK20"] = "1"

from pymavlink.dialects.v20 import common as mavlink

Message = Any
"""A decoded pymavlink message (the generated classes are untyped)."""

COMPANION_COMPID = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER  # 191
AUTOPILOT_COMPID = mavlink.MAV_COMP_ID_AUTOPILOT1  # 1


class _SafeMAVLink(mavlink.MAVLink):  # type: ignore[misc]
    """pymavlink's codec with the signature checked *before* the replay window moves.

    Upstream records a stream's timestamp before verifying the hash, so one forged frame
    with a far-future timestamp would make every genuine frame look like a replay.
    """

    def check_signature(self, msgbuf: bytearray, srcSystem: int, srcComponent: int) -> bool:
        key = self.signing.secret_key
        if key is None:  # pragma: no cover - pymavlink calls this only with a key
            return False
        h = hashlib.sha256()
        h.update(key)
        h.update(msgbuf[:-6])
        if h.digest()[:6] != bytes(msgbuf[-6:]):
            return False
        tlow, thigh = self.mav_sign_unpacker.unpack(msgbuf[-12:-6])
        timestamp = int(tlow) + (int(thigh) << 32)
        stream_key = (msgbuf[-13], srcSystem, srcComponent)
        last = self.signing.stream_timestamps.get(stream_key)
        if last is not None and timestamp <= last:
            return False  # replayed or reordered
        if last is None and timestamp + 6000 * 1000 < self.signing.timestamp:
            return False  # a "new" stream more than a minute in the past: a replay
        self.signing.stream_timestamps[stream_key] = timestamp
        self.signing.timestamp = max(self.signing.timestamp, timestamp)
        return True


@dataclass
class CodecStats:
    rx: Counter[str] = field(default_factory=Counter)  # decoded messages by type
    tx: Counter[str] = field(default_factory=Counter)
    bad: Counter[str] = field(default_factory=Counter)  # undecodable frames by reason


class Codec:
    """Encode messages to bytes and decode datagrams to messages, MAVLink 2 only."""

    def __init__(self, src_system: int, src_component: int) -> None:
        self._out: list[bytes] = []
        self.mav = _SafeMAVLink(self, srcSystem=src_system, srcComponent=src_component)
        self.mav.robust_parsing = True  # bad frames come back as BAD_DATA, never raise
        self.stats = CodecStats()

    # pymavlink calls file.write(buf) from *_send; we collect instead of sending.
    def write(self, buf: bytes) -> None:
        self._out.append(bytes(buf))

    @property
    def src_system(self) -> int:
        return int(self.mav.srcSystem)

    @src_system.setter
    def src_system(self, value: int) -> None:
        self.mav.srcSystem = value

    def encode(self, msg: Message) -> bytes:
        """Frame ``msg`` (signed when signing is on) and return the bytes."""
        self.stats.tx[msg.get_type()] += 1
        return bytes(msg.pack(self.mav))

    def decode(self, data: bytes) -> list[Message]:
        """Every message in ``data``; frames that fail CRC or signature are counted only."""
        out: list[Message] = []
        try:
            msgs = self.mav.parse_buffer(data) or []
        except Exception as exc:  # robust_parsing should prevent this; never let it escape
            self.stats.bad[type(exc).__name__] += 1
            self.mav.buf = bytearray()
            self.mav.buf_index = 0
            return out
        for m in msgs:
            kind = m.get_type()
            if kind in ("BAD_DATA", "UNKNOWN"):
                reason = str(getattr(m, "reason", kind))
                self.stats.bad["signature" if "signature" in reason else kind.lower()] += 1
                continue
            self.stats.rx[kind] += 1
            out.append(m)
        return out

    def enable_signing(
        self,
        key: bytes,
        timestamp: int,
        link_id: int = 0,
        allow_unsigned: Callable[[int], bool] | None = None,
    ) -> None:
        """Sign everything we send and refuse unsigned or badly signed input
        (except message ids ``allow_unsigned`` accepts)."""
        if len(key) != 32:
            raise ValueError(f"a MAVLink signing key is 32 bytes, got {len(key)}")
        s = self.mav.signing
        s.secret_key = key
        s.sign_outgoing = True
        s.link_id = link_id
        s.timestamp = timestamp
        if allow_unsigned is not None:
            s.allow_unsigned_callback = lambda _mav, msg_id: allow_unsigned(msg_id)

    @property
    def signing_timestamp(self) -> int:
        return int(self.mav.signing.timestamp)


__all__ = ["AUTOPILOT_COMPID", "COMPANION_COMPID", "Codec", "CodecStats", "Message", "mavlink"]
