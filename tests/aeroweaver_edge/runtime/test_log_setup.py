"""The process's logging: the level per command and flag, journald's format when
``JOURNAL_STREAM`` names our stream (a real file's device and inode), plain otherwise."""

from __future__ import annotations

import logging
import os
from pathlib import Path

from aeroweaver_edge.runtime.log_setup import JournalFormatter, level_for, under_journal


def test_levels() -> None:
    assert level_for("daemon", False, None) == logging.INFO
    assert level_for("router", False, None) == logging.INFO
    assert level_for("mission", False, None) == logging.WARNING
    assert level_for("mission", True, None) == logging.DEBUG
    assert level_for("daemon", True, "ERROR") == logging.ERROR  # --log-level wins


def test_journal_stream_must_name_this_stream(tmp_path: Path) -> None:
    mine, other = tmp_path / "a.log", tmp_path / "b.log"
    mine.touch()
    other.touch()
    st = os.stat(mine)
    with mine.open("w") as stream:
        assert under_journal(stream, {"JOURNAL_STREAM": f"{st.st_dev}:{st.st_ino}"})
        so = os.stat(other)
        assert not under_journal(stream, {"JOURNAL_STREAM": f"{so.st_dev}:{so.st_ino}"})
        assert not under_journal(stream, {"JOURNAL_STREAM": "garbage"})
        assert not under_journal(stream, {})


def test_journal_lines_carry_the_priority_and_no_time() -> None:
    fmt = JournalFormatter("%(name)s: %(message)s")
    rec = logging.LogRecord("aeroweaver_edge.daemon.uav_daemon", logging.WARNING, __file__, 1,
                            "uav0: holding\nsecond line", None, None)  # fmt: skip
    assert fmt.format(rec) == "<4>aeroweaver_edge.daemon.uav_daemon: uav0: holding\n<4>second line"
    rec.levelno = logging.INFO
    assert fmt.format(rec).startswith("<6>")
