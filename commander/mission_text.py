"""The one check every mission text passes before anything starts (CLI ``sim --mission``,
``mission start``, the MCP ``plan_mission`` tool, and ``parse_mission`` itself).

A mission is a few sentences. It travels inside the Commander's context message (capped at
``wire.MAX_PAYLOAD_BYTES``, 64 KiB, with the constraints and ids beside it) and into every
UAV's system prompt, so it is bounded at 8 KiB of UTF-8: well above any real mission
(the shipped tasks' are 80-400 bytes), far below what the wire and a small model's context
can take. It must be UTF-8 text (a command line in another encoding reaches Python as lone
surrogates) without control characters other than tab and newline.
"""

from __future__ import annotations

import unicodedata
from typing import Final

from aeroweaver_edge.contracts.errors import UserError

MAX_MISSION_BYTES: Final = 8 * 1024
_ALLOWED_CONTROLS = frozenset("\t\n\r")


class MissionTextError(UserError):
    """The mission text cannot be used; the message says why and what to do."""


def _where(text: str, index: int) -> str:
    return f"character {index + 1} of {len(text)}"


def check_mission_text(text: str | bytes, what: str = "the mission text") -> str:
    """``text`` as a checked ``str``; raises ``MissionTextError`` (one line, exit 2)."""
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as exc:
            bad = exc.object[exc.start]
            raise MissionTextError(
                f"{what} is not UTF-8 (byte 0x{bad:02x} at offset {exc.start})",
                "write the mission as UTF-8 text",
            ) from None
    for i, ch in enumerate(text):
        if "\ud800" <= ch <= "\udfff":  # undecodable argv bytes (surrogateescape)
            byte = f"byte 0x{ord(ch) - 0xDC00:02x}" if ord(ch) >= 0xDC80 else "a lone surrogate"
            raise MissionTextError(
                f"{what} is not UTF-8 ({byte} at {_where(text, i)})",
                "write the mission as UTF-8 text (check the terminal's locale)",
            )
        if ch not in _ALLOWED_CONTROLS and unicodedata.category(ch) == "Cc":
            raise MissionTextError(
                f"{what} holds control character U+{ord(ch):04X} at {_where(text, i)}",
                "write the mission as plain text",
            )
    size = len(text.encode("utf-8"))
    if size > MAX_MISSION_BYTES:
        raise MissionTextError(
            f"{what} is {size} bytes; a mission is at most {MAX_MISSION_BYTES} bytes "
            f"({MAX_MISSION_BYTES // 1024} KiB) of UTF-8",
            "state the task, team and constraints in a few sentences",
        )
    if not text.strip():
        raise MissionTextError(f"{what} is empty", "say what the swarm should do")
    return text


__all__ = ["MAX_MISSION_BYTES", "MissionTextError", "check_mission_text"]
