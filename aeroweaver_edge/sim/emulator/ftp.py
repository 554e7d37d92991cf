"""MAVLink FTP (FILE_TRANSFER_PROTOCOL) as an autopilot without files answers it.

The emulator has no file system to serve, but silence is the wrong answer: MAVProxy's
parameter download and QGroundControl's component-metadata fetch send an FTP request first
and, unanswered, retry until their timeout (seconds) before falling back. A real server
answers every request at once, so the emulator does too: ACK for the session commands that
need no file, NAK with the spec's error code for everything else.

Payload layout (https://mavlink.io/en/services/ftp.html): seq_number u16, session u8,
opcode u8, size u8, req_opcode u8, burst_complete u8, padding u8, offset u32, data[239].
"""

from __future__ import annotations

import struct

HEADER = struct.Struct("<HBBBBBBI")
PAYLOAD_LEN = 251

# Opcodes (requests) and the two reply opcodes.
TERMINATE_SESSION = 1
RESET_SESSIONS = 2
LIST_DIRECTORY = 3
OPEN_FILE_RO = 4
READ_FILE = 5
CREATE_FILE = 6
WRITE_FILE = 7
REMOVE_FILE = 8
CREATE_DIRECTORY = 9
REMOVE_DIRECTORY = 10
OPEN_FILE_WO = 11
TRUNCATE_FILE = 12
RENAME = 13
CALC_FILE_CRC32 = 14
BURST_READ_FILE = 15
ACK = 128
NAK = 129

# Error codes carried in data[0] of a NAK.
FAIL = 1
INVALID_SESSION = 4
UNKNOWN_COMMAND = 7
FILE_PROTECTED = 9
FILE_NOT_FOUND = 10

_NOT_FOUND = {LIST_DIRECTORY, OPEN_FILE_RO, REMOVE_FILE, REMOVE_DIRECTORY, CALC_FILE_CRC32}
_READ_ONLY = {CREATE_FILE, CREATE_DIRECTORY, OPEN_FILE_WO, RENAME, TRUNCATE_FILE}
_NO_SESSION = {READ_FILE, WRITE_FILE, BURST_READ_FILE}


def error_for(opcode: int) -> int | None:
    """The NAK error code for a request ``opcode``; None: the request is ACKed."""
    if opcode in (TERMINATE_SESSION, RESET_SESSIONS):
        return None  # nothing open, so nothing to close: success
    if opcode in _NOT_FOUND:
        return FILE_NOT_FOUND
    if opcode in _READ_ONLY:
        return FILE_PROTECTED
    if opcode in _NO_SESSION:
        return INVALID_SESSION  # no file was ever opened
    return UNKNOWN_COMMAND


def reply(payload: bytes | list[int]) -> list[int] | None:
    """The reply payload to request ``payload`` (None: too short to be a request, or
    itself a reply, which a server never answers)."""
    raw = bytes(payload)
    if len(raw) < HEADER.size:
        return None
    seq, session, opcode, _size, _req, _burst, _pad, _offset = HEADER.unpack_from(raw)
    if opcode in (ACK, NAK):
        return None
    error = error_for(opcode)
    out_op, size, data = (ACK, 0, b"") if error is None else (NAK, 1, bytes([error]))
    head = HEADER.pack((seq + 1) & 0xFFFF, session, out_op, size, opcode, 0, 0, 0)
    return list((head + data).ljust(PAYLOAD_LEN, b"\x00"))
