"""Logging for the ``aeroweaver`` process: one place decides the level and the format.

- Level: ``--log-level LEVEL`` if given, else DEBUG with ``-v``, else the command's default
  (INFO for the long-running services an operator watches -- ``daemon``, ``router`` --
  WARNING for the rest, whose results are their own output).
- Format: under systemd (``JOURNAL_STREAM`` names our stderr) no timestamp -- the journal
  stamps every line -- and a ``<N>`` syslog priority prefix, which journald turns into the
  entry's priority (``journalctl -p warning`` then works); elsewhere a timestamped line.
  Never colours.
- httpx/httpcore stay at WARNING unless ``-v``: their INFO line per request would flood a
  daemon's log (and names the endpoint URL).
"""

from __future__ import annotations

import logging
import os
import sys
from typing import TextIO

LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")
SERVICES = frozenset({"daemon", "router"})  # commands an operator watches through their log
NOISY = ("httpx", "httpcore")

_PRIORITY = {  # logging level -> syslog priority (sd-daemon.h)
    logging.CRITICAL: 2,
    logging.ERROR: 3,
    logging.WARNING: 4,
    logging.INFO: 6,
    logging.DEBUG: 7,
}


class JournalFormatter(logging.Formatter):
    """``<6>aeroweaver_edge.daemon.uav_daemon: uav0: ...``: priority prefix, no time
    (journald adds it)."""

    def format(self, record: logging.LogRecord) -> str:
        prio = next((p for lvl, p in sorted(_PRIORITY.items(), reverse=True)
                     if record.levelno >= lvl), 7)  # fmt: skip
        text = super().format(record)
        # Every line of a multi-line message (a traceback) keeps the entry's priority.
        return "\n".join(f"<{prio}>{line}" for line in text.splitlines() or [""])


def under_journal(stream: TextIO, environ: dict[str, str] | None = None) -> bool:
    """``JOURNAL_STREAM`` (``device:inode``) names ``stream``: systemd connected it to the
    journal. A child that inherited the variable but writes elsewhere does not match."""
    value = (environ if environ is not None else os.environ).get("JOURNAL_STREAM", "")
    dev, _, ino = value.partition(":")
    if not (dev.isdigit() and ino.isdigit()):
        return False
    try:
        st = os.fstat(stream.fileno())
    except (OSError, ValueError, AttributeError):
        return False
    return (st.st_dev, st.st_ino) == (int(dev), int(ino))


def level_for(command: str | None, verbose: bool, log_level: str | None) -> int:
    if log_level:
        return int(getattr(logging, log_level.upper()))
    if verbose:
        return logging.DEBUG
    return logging.INFO if command in SERVICES else logging.WARNING


def setup(
    command: str | None,
    *,
    verbose: bool = False,
    log_level: str | None = None,
    stream: TextIO | None = None,
) -> int:
    """Configure the root logger for this process; returns the level. Like
    ``logging.basicConfig``, nothing changes when the root logger has handlers already (a
    program, or a test runner, that set up logging itself)."""
    stream = stream or sys.stderr
    level = level_for(command, verbose, log_level)
    root = logging.getLogger()
    if root.handlers:
        return level
    handler = logging.StreamHandler(stream)
    if under_journal(stream):
        handler.setFormatter(JournalFormatter("%(name)s: %(message)s"))
    else:
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    root.addHandler(handler)
    root.setLevel(level)
    for name in NOISY:
        logging.getLogger(name).setLevel(level if level <= logging.DEBUG else logging.WARNING)
    return level


__all__ = ["LEVELS", "JournalFormatter", "level_for", "setup", "under_journal"]
