"""The daemon-owned setpoint stream, under a lease.

An asyncio task re-sends the current setpoint at ``rate_hz``. Every command from the agent
renews the lease; when the lease runs out the stream stops and ``on_expired`` runs (the
backend commands the autopilot's own hold). Because the stream is a task on the daemon's
loop, a stalled loop sends nothing, so the autopilot's offboard-loss failsafe fires; after a
stall longer than the lease the old setpoint is never resumed.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from typing import Any

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Setpoint:
    """Velocity (m/s) or position (m) in the local NED frame."""

    kind: str  # "velocity" | "position"
    n: float
    e: float
    d: float


ZERO_VELOCITY = Setpoint("velocity", 0.0, 0.0, 0.0)


@dataclass
class StreamStats:
    sent: int = 0
    expired: int = 0
    stalls: int = 0  # wake-ups later than two periods
    max_gap_s: float = 0.0
    gaps: list[float] = field(default_factory=list)  # recent send intervals (bounded)


class SetpointStream:
    def __init__(
        self,
        send: Callable[[Setpoint], None],
        *,
        rate_hz: float,
        lease_s: float,
        on_expired: Callable[[], Coroutine[Any, Any, None]],
    ) -> None:
        if rate_hz < 2.0:
            raise ValueError(f"setpoint rate must be >= 2 Hz for offboard control, got {rate_hz}")
        self._send = send
        self.period_s = 1.0 / rate_hz
        self.lease_s = lease_s
        self._on_expired = on_expired
        self.setpoint: Setpoint | None = None
        self._lease_until = 0.0
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._expiry: asyncio.Task[None] | None = None
        self.stats = StreamStats()
        self._last_sent = 0.0

    @property
    def active(self) -> bool:
        return self.setpoint is not None

    def start(self) -> None:
        if self._task is None:
            self._task = asyncio.create_task(self._run(), name="setpoint-stream")

    async def aclose(self) -> None:
        for t in (self._task, self._expiry):
            if t is not None:
                t.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await t
        self._task = self._expiry = None

    def set(self, sp: Setpoint, lease_s: float | None = None) -> None:
        """Stream ``sp`` from now on (sent at once) and renew the lease (``lease_s``
        overrides its length once, e.g. to cover the zero-setpoint lead-in to offboard)."""
        self.setpoint = sp
        self._lease_until = time.monotonic() + (self.lease_s if lease_s is None else lease_s)
        self._emit(time.monotonic())
        self._wake.set()

    def stop(self) -> None:
        """Send nothing more until the next :meth:`set` (link loss, mode left, shutdown)."""
        self.setpoint = None

    def _emit(self, now: float) -> None:
        if self.setpoint is None:
            return
        if self._last_sent:
            gap = now - self._last_sent
            self.stats.max_gap_s = max(self.stats.max_gap_s, gap)
            if len(self.stats.gaps) < 100_000:
                self.stats.gaps.append(gap)
        self._last_sent = now
        self._send(self.setpoint)
        self.stats.sent += 1

    async def _run(self) -> None:
        next_at = time.monotonic()
        while True:
            if self.setpoint is None:
                self._wake.clear()
                self._last_sent = 0.0
                await self._wake.wait()
                next_at = time.monotonic() + self.period_s
                continue
            delay = next_at - time.monotonic()
            if delay > 0:
                await asyncio.sleep(delay)
            now = time.monotonic()
            if now - next_at > 2 * self.period_s:
                self.stats.stalls += 1  # the loop was blocked; the autopilot saw silence
            next_at = max(next_at + self.period_s, now)
            if self.setpoint is None:
                continue
            if now > self._lease_until:
                log.warning("setpoint lease (%.1f s) ran out: stream stops, hold", self.lease_s)
                self.setpoint = None
                self.stats.expired += 1
                self._expiry = asyncio.create_task(self._on_expired(), name="lease-expired")
                continue
            self._emit(now)
