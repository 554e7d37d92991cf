"""The Commander's contact with a mission's UAVs, from their liveliness tokens.

A UAV whose token goes away mid-mission is *lost* (its daemon died, its radio dropped, or
the router between us is gone: from here these look alike); it is *rejoined* when its
token comes back. ``mission start`` records both (``lost_uavs``: where each was lost;
``rejoined_uavs``: how often each came back) and stops the mission once every participant
has been out of contact for the grace: nothing is flying it any more. The daemons hold by
themselves when they lose the Commander (docs/notes/safety.md).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from aeroweaver_edge.contracts.wire import Keys, last_chunk
from aeroweaver_edge.runtime.lifecycle import cancel_all

if TYPE_CHECKING:
    from aeroweaver_edge.mesh.session import LivelinessWatch, Mesh

log = logging.getLogger(__name__)

Where = Callable[[str], tuple[int, int]]
"""(episode, round) a UAV was last seen at, for the record."""


class ContactWatch:
    """Which participants are in contact; when each was lost, and how often each came back."""

    def __init__(self, mesh: Mesh, swarm: str, participants: list[str], where: Where) -> None:
        self.participants = set(participants)
        self.alive: set[str] = set()
        self.lost: dict[str, list[int]] = {}  # uav -> [episode, round] it was lost at
        self.rejoined: dict[str, int] = {}
        self.out_since: dict[str, float] = {}  # uav -> monotonic time it went out of contact
        self.changed = asyncio.Event()
        self._mesh = mesh
        self._keys = Keys(swarm)
        self._where = where
        self._task: asyncio.Task[None] | None = None
        self._watch: LivelinessWatch | None = None

    def start(self) -> None:
        self._watch = self._mesh.watch_liveliness(self._keys.alive_uav("*"))
        self._task = asyncio.create_task(self._pump(self._watch), name="cmdr-contact")

    async def aclose(self) -> None:
        if self._task is not None:
            await cancel_all([self._task])
        if self._watch is not None:
            await self._watch.aclose()

    async def _pump(self, watch: LivelinessWatch) -> None:
        async for key, up in watch:
            self.on_token(last_chunk(key), up)

    def on_token(self, uav: str, up: bool) -> None:
        if uav not in self.participants or up == (uav in self.alive):
            return
        if up:
            self.alive.add(uav)
            self.out_since.pop(uav, None)
            if uav in self.lost:
                self.rejoined[uav] = self.rejoined.get(uav, 0) + 1
                log.info("contact with %s is back", uav)
        else:
            self.alive.discard(uav)
            self.out_since[uav] = time.monotonic()
            self.lost.setdefault(uav, list(self._where(uav)))
            log.warning("lost contact with %s", uav)
        self.changed.set()

    @property
    def out_of_contact(self) -> list[str]:
        """Participants lost and not back (sorted)."""
        return sorted(u for u in self.lost if u not in self.alive)

    async def wait_all_lost(self, grace_s: float) -> None:
        """Return once every participant has been out of contact for ``grace_s``."""
        while True:
            if self.participants and not self.alive & self.participants:
                since = max(self.out_since.get(u, time.monotonic()) for u in self.participants)
                left = grace_s - (time.monotonic() - since)
                if left <= 0:
                    return
                self.changed.clear()
                try:
                    async with asyncio.timeout(left):
                        await self.changed.wait()
                except TimeoutError:
                    pass
                continue
            self.changed.clear()
            await self.changed.wait()


__all__ = ["ContactWatch"]
