"""systemd's notify protocol, spoken directly (no dependency): READY, WATCHDOG, STOPPING.

The unit is ``Type=notify`` with ``WatchdogSec=``. systemd passes ``NOTIFY_SOCKET`` (a
path, or ``@name`` for the abstract namespace) and, with a watchdog, ``WATCHDOG_USEC``
and ``WATCHDOG_PID``. A datagram per message; every send is non-blocking and best
effort: a daemon never stops flying because systemd is not listening.

The watchdog pings come from a task *on the daemon's event loop*, every half
``WatchdogSec``, and only while the loop is healthy: a wake-up later than ``max_lag_s``
(default a quarter of ``WatchdogSec``) or a failed ``healthy()`` check skips the ping. A
stalled loop sends nothing at all, so systemd kills and restarts the daemon; the
autopilot's offboard-loss failsafe holds the aircraft meanwhile.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import time
from collections.abc import Callable, Mapping

log = logging.getLogger(__name__)


def _address(raw: str) -> str:
    """``@name`` is Linux's abstract namespace (a leading NUL byte on the wire)."""
    return "\0" + raw[1:] if raw.startswith("@") else raw


class Notifier:
    """Sends ``KEY=value`` lines to ``NOTIFY_SOCKET``; a no-op when there is none."""

    def __init__(self, address: str | None) -> None:
        self.address = address or None
        self._sock: socket.socket | None = None
        self._warned = False
        self.sent: list[str] = []  # messages sent, for status output and tests

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None) -> Notifier:
        env = os.environ if env is None else env
        return cls(env.get("NOTIFY_SOCKET"))

    @property
    def enabled(self) -> bool:
        return self.address is not None

    def notify(self, *fields: str) -> bool:
        """Send one datagram of newline-separated fields; ``False`` if it did not go."""
        if self.address is None:
            return False
        message = "\n".join(fields)
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
                self._sock.setblocking(False)
            self._sock.sendto(message.encode(), _address(self.address))
        except OSError as exc:
            if not self._warned:  # once: a missing listener must not flood the log
                self._warned = True
                log.warning("sd_notify to %s failed: %s", self.address, exc)
            return False
        self.sent.append(message)
        return True

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def watchdog_interval_s(
    env: Mapping[str, str] | None = None, pid: int | None = None
) -> float | None:
    """Half of ``WATCHDOG_USEC`` in seconds, if the watchdog is meant for this process."""
    env = os.environ if env is None else env
    try:
        usec = int(env.get("WATCHDOG_USEC", "0"))
        target = int(env.get("WATCHDOG_PID", "0") or 0)
    except ValueError:
        return None
    if usec <= 0 or (target and target != (pid if pid is not None else os.getpid())):
        return None
    return usec / 2 / 1e6


class Watchdog:
    """Pings ``WATCHDOG=1`` from the event loop while the loop keeps up (module doc)."""

    def __init__(
        self,
        notifier: Notifier,
        interval_s: float,
        *,
        max_lag_s: float | None = None,
        healthy: Callable[[], bool] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if interval_s <= 0:
            raise ValueError("watchdog interval must be positive")
        self.notifier = notifier
        self.interval_s = interval_s
        self.max_lag_s = interval_s / 2 if max_lag_s is None else max_lag_s
        self.healthy = healthy
        self._clock = clock
        self._task: asyncio.Task[None] | None = None
        self.pings = 0
        self.skipped = 0
        self.last_lag_s = 0.0

    def start(self) -> None:
        """Ping once now, then every ``interval_s`` (call from the event loop)."""
        if self._task is None:
            self._ping()
            self._task = asyncio.get_running_loop().create_task(self._run(), name="sd-watchdog")

    def _ping(self) -> None:
        if self.notifier.notify("WATCHDOG=1"):
            self.pings += 1

    async def _run(self) -> None:
        while True:
            due = self._clock() + self.interval_s
            await asyncio.sleep(self.interval_s)
            self.last_lag_s = lag = self._clock() - due
            if lag > self.max_lag_s:
                self.skipped += 1
                log.warning("event loop %.2f s late: watchdog ping withheld", lag)
                continue
            if self.healthy is not None and not self.healthy():
                self.skipped += 1
                continue
            self._ping()

    async def stop(self) -> None:
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task


class Supervision:
    """What a daemon tells systemd over its life: READY (+ watchdog), STOPPING."""

    def __init__(self, notifier: Notifier, watchdog: Watchdog | None) -> None:
        self.notifier = notifier
        self.watchdog = watchdog

    @classmethod
    def from_env(
        cls, env: Mapping[str, str] | None = None, *, healthy: Callable[[], bool] | None = None
    ) -> Supervision:
        notifier = Notifier.from_env(env)
        interval = watchdog_interval_s(env) if notifier.enabled else None
        watchdog = Watchdog(notifier, interval, healthy=healthy) if interval else None
        return cls(notifier, watchdog)

    def ready(self, status: str = "") -> None:
        """The daemon is up (mesh open, vehicle link started): READY=1, watchdog on."""
        self.notifier.notify("READY=1", *([f"STATUS={status}"] if status else []))
        if self.watchdog is not None:
            self.watchdog.start()

    def stopping(self, status: str = "") -> None:
        self.notifier.notify("STOPPING=1", *([f"STATUS={status}"] if status else []))

    async def aclose(self) -> None:
        if self.watchdog is not None:
            await self.watchdog.stop()
        self.notifier.close()
