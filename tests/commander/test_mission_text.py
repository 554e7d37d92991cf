"""The one mission-text check (UTF-8, no control characters, at most 8 KiB) refuses before
anything starts: in ``parse_mission`` (the path of every front end), as an argparse type
for ``sim --mission`` and ``mission start`` (the real CLI: exit 2, one line, no process),
and as an error answer of the MCP ``plan_mission`` tool."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from commander.mission_parser import parse_mission
from commander.mission_text import MAX_MISSION_BYTES, MissionTextError, check_mission_text

ROOT = Path(__file__).resolve().parents[2]
ROSTER = ["uav0", "uav1", "uav2"]
COVER = "Cover every landmark with one drone each. "


def test_a_mission_up_to_8_kib_is_accepted_and_one_byte_more_is_not() -> None:
    exact = (COVER * 400)[:MAX_MISSION_BYTES]
    assert check_mission_text(exact) == exact
    with pytest.raises(MissionTextError, match=r"8193 bytes; a mission is at most 8192"):
        check_mission_text(exact + "x")
    wide = "é" * (MAX_MISSION_BYTES // 2)  # two bytes each: counted in UTF-8, not characters
    check_mission_text(wide)
    with pytest.raises(MissionTextError, match="8194 bytes"):
        check_mission_text(wide + "é")


@pytest.mark.parametrize(
    ("text", "says"),
    [
        (b"cover \xff the landmarks", "not UTF-8 (byte 0xff at offset 6)"),
        ("cover \udcff the landmarks", "not UTF-8 (byte 0xff at character 7"),
        ("cover \ud800 x", "not UTF-8 (a lone surrogate"),
        ("cover\x00the landmarks", "control character U+0000"),
        ("cover\x1b[31mred", "control character U+001B"),
        ("   \n\t ", "is empty"),
    ],
)
def test_what_is_not_a_mission_text_is_named(text: str | bytes, says: str) -> None:
    with pytest.raises(MissionTextError, match=re.escape(says)) as info:
        check_mission_text(text)
    assert "\n" not in str(info.value)


def test_tabs_newlines_and_any_script_are_fine() -> None:
    text = "Cover the landmarks.\n\tAvoid collisions. Покрыть ориентиры. 着陆 🚁"
    assert check_mission_text(text) == text
    assert check_mission_text(text.encode()) == text


async def test_parse_mission_checks_first_whatever_calls_it() -> None:
    with pytest.raises(MissionTextError, match="at most 8192"):
        await parse_mission(COVER * 2000, ROSTER)
    parsed = await parse_mission(COVER, ROSTER)
    assert parsed.record.task == "coverage"


def cli(*args: str | bytes) -> subprocess.CompletedProcess[bytes]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "LC_ALL": "C.UTF-8"}
    argv = [os.fsencode(sys.executable), b"-m", b"aeroweaver_edge"]
    argv += [a if isinstance(a, bytes) else a.encode() for a in args]
    return subprocess.run(argv, capture_output=True, timeout=60, env=env)


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["sim", "--selector", "scripted", "--mission", "x" * 70_000], b"70000 bytes"),
        (["sim", "--mission", b"cover \xff\xfe landmarks"], b"not UTF-8 (byte 0xff"),
        (["mission", "start", "--no-llm", "y" * 65_537], b"65537 bytes"),
        (["mission", "start", b"land \xc3\x28 now"], b"not UTF-8 (byte 0xc3"),
        (["mission", "start", "a\x01b"], b"control character U+0001"),
    ],
)
def test_the_cli_refuses_before_anything_starts(argv: list[str | bytes], says: bytes) -> None:
    proc = cli(*argv)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert says in lines[0]
    assert proc.stdout == b""  # no banner, no process, no session
