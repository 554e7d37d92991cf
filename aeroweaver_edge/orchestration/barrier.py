"""The barrier between episodes: shared experience is in before the next episode starts.

At an episode's end every daemon finalises its records of that episode and publishes them
for its same-role peers (DESIGN §5), then reports a tally (``ProgressReport`` phase
``experience``: own records published, peers' records received and, of those, taken).
Before the world starts the next episode, the orchestration waits here until

- every *sharer* (a daemon that played the episode's last round) still in that life has
  reported how many records it published, and
- every such daemon has received every record the other sharers reported publishing.

Then every daemon stores exactly the same peers' records before its next decision, in one
order (``SharedIntake``), so returns do not depend on process layout or timing: a fixed
sleep could not promise that. Received, not taken, and whatever the role: a UAV reassigned
mid-episode publishes records of two roles, and its peers take only those of their own
role at arrival; every record received implies every same-role one was taken.

The wait is bounded; a daemon that died (its token went) or restarted (its reports carry a
new boot epoch) during the wait is no longer waited for, and a timeout is counted and
logged, never fatal.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from aeroweaver_edge.contracts.wire import ProgressReport

log = logging.getLogger(__name__)

DEFAULT_TIMEOUT_S = 10.0
RECHECK_S = 0.25  # liveliness is read, not pushed: look again this often while waiting


@dataclass
class BarrierStats:
    episodes: int = 0
    confirmed: int = 0
    timeouts: int = 0
    records: int = 0  # same-role peers' records confirmed taken, summed over daemons, episodes
    wait_s: list[float] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)  # what each timeout still lacked

    def as_dict(self) -> dict[str, object]:
        waits = sorted(self.wait_s)
        return {
            "episodes": self.episodes,
            "confirmed": self.confirmed,
            "timeouts": self.timeouts,
            "records": self.records,
            "wait_s_max": round(waits[-1], 4) if waits else 0.0,
            **({"missing": self.missing} if self.missing else {}),
        }


class ExperienceBarrier:
    """Fed every accepted progress report (``Commander.report_listeners``); ``wait`` blocks
    until an episode's shared experience is confirmed received, or the bound passes."""

    def __init__(self, timeout_s: float = DEFAULT_TIMEOUT_S) -> None:
        self.timeout_s = timeout_s
        self.stats = BarrierStats()
        self._epoch: dict[str, int] = {}  # uav -> boot epoch of its latest report
        self._played: dict[tuple[str, int], int] = {}  # (uav, episode) -> epoch that played
        self._tally: dict[tuple[str, int], ProgressReport] = {}  # latest per (uav, episode)
        self._changed = asyncio.Event()

    def on_report(self, rep: ProgressReport) -> None:
        h = rep.h
        if h.epoch >= self._epoch.get(rep.uav, h.epoch):
            self._epoch[rep.uav] = h.epoch
        if rep.phase == "round" and rep.episode >= 0:
            self._played[(rep.uav, rep.episode)] = h.epoch
        elif rep.phase == "experience":
            key = (rep.uav, rep.episode)
            old = self._tally.get(key)
            if old is None or (h.epoch, h.seq) > (old.h.epoch, old.h.seq):
                self._tally[key] = rep
        self._changed.set()

    def _missing(self, episode: int, sharers: Iterable[str], alive: set[str]) -> list[str]:
        """What the episode still lacks (empty: confirmed)."""
        live: dict[str, int] = {}  # sharer -> the life (epoch) that played the episode
        for u in sharers:
            epoch = self._played.get((u, episode), self._epoch.get(u))
            if u in alive and epoch is not None and self._epoch.get(u) == epoch:
                live[u] = epoch
        published: dict[str, int] = {}
        missing: list[str] = []
        for u in sorted(set(sharers)):
            rep = self._tally.get((u, episode))
            if rep is not None and rep.experience_shared >= 0:
                published[u] = rep.experience_shared  # counts even if u died since
            elif u in live:
                missing.append(f"{u} has not shared")
        for u, epoch in sorted(live.items()):
            expected = sum(n for v, n in published.items() if v != u)
            rep = self._tally.get((u, episode))
            got = rep.experience_received if rep is not None and rep.h.epoch == epoch else 0
            if got < expected:
                missing.append(f"{u} received {got} of {expected}")
        return missing

    def _confirmed_records(self, episode: int, sharers: Iterable[str]) -> int:
        return sum(
            rep.experience_taken
            for u in set(sharers)
            if (rep := self._tally.get((u, episode))) is not None
        )

    async def wait(
        self, episode: int, sharers: Iterable[str], alive: Callable[[], set[str]]
    ) -> bool:
        """Wait until ``episode``'s shared experience is confirmed (True) or the bound
        passes (False, counted). ``sharers``: the daemons that played its last round;
        ``alive``: the UAVs whose liveliness token is up now."""
        sharers = sorted(set(sharers))
        started = time.monotonic()
        self.stats.episodes += 1
        missing = self._missing(episode, sharers, alive())
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(self.timeout_s):
                while missing:
                    self._changed.clear()
                    # A report wakes us at once; a daemon's death shows only in alive().
                    with contextlib.suppress(TimeoutError):
                        async with asyncio.timeout(RECHECK_S):
                            await self._changed.wait()
                    missing = self._missing(episode, sharers, alive())
        waited = time.monotonic() - started
        self.stats.wait_s.append(waited)
        records = self._confirmed_records(episode, sharers)
        self._forget(episode)
        if missing:
            self.stats.timeouts += 1
            self.stats.missing.append(f"episode {episode}: " + "; ".join(missing[:4]))
            log.warning(
                "experience of episode %d not confirmed within %.1f s (%s); going on",
                episode, self.timeout_s, "; ".join(missing[:4]),
            )  # fmt: skip
            return False
        self.stats.confirmed += 1
        self.stats.records += records
        return True

    def _forget(self, episode: int) -> None:
        """Drop what is no longer needed (a long run must not grow this)."""
        for d in (self._played, self._tally):
            for key in [k for k in d if k[1] <= episode]:
                del d[key]


__all__ = ["BarrierStats", "ExperienceBarrier"]
