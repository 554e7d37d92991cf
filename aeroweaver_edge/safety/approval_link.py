"""The approval gate on the mesh: approvals in, status out (one per daemon).

In: ``aw/<swarm>/operator/approval/<uav>`` (``Approval``; an operator key, so when the mesh
is secured only an operator identity can write it, and the signature is checked before the
payload reaches us). Out: ``aw/<swarm>/uav/<uav>/approval`` (``ApprovalStatus``: the level,
pending actions and records, ``ack`` naming the approval it answers), published on every
change and served by query, so ``aeroweaver approve``, the console and the MCP server see
what waits for an operator and whether their approval was taken.
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING

from aeroweaver_edge.contracts.wire import Approval, ApprovalStatus, HeaderFactory, Keys
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_edge.safety.approval import ApprovalGate

if TYPE_CHECKING:
    from aeroweaver_edge.mesh.session import Mesh, Subscription

log = logging.getLogger(__name__)


class ApprovalLink:
    def __init__(
        self, mesh: Mesh, keys: Keys, uav: str, headers: HeaderFactory, gate: ApprovalGate
    ) -> None:
        self.mesh = mesh
        self.keys = keys
        self.uav = uav
        self.headers = headers
        self.gate = gate
        self._tasks: list[asyncio.Task[None]] = []
        self._dirty = False

    def start(self) -> None:
        """Declare (before the daemon's liveliness token: an approval sent as soon as the
        token appears must find the subscriber) and start pumping."""
        sub = self.mesh.subscribe(self.keys.approval(self.uav), Approval, maxsize=32)
        self.mesh.declare_queryable(self.keys.approval_status(self.uav), self.status)
        self.gate.on_change = self._schedule
        self._tasks.append(asyncio.create_task(self._pump(sub), name=f"{self.uav}-approvals"))
        # Observers that subscribed before our queryable existed (a console or MCP server
        # started first) would otherwise learn our level only at the first change.
        self._schedule()

    async def aclose(self) -> None:
        self.gate.on_change = None
        await cancel_all(self._tasks)

    def status(self, ack: str = "") -> ApprovalStatus:
        return ApprovalStatus(
            h=self.headers.next(),
            uav=self.uav,
            level=self.gate.level,
            pending=self.gate.pending(),
            records=self.gate.records(),
            ack=ack,
        )

    async def _pump(self, sub: Subscription[Approval]) -> None:
        async for _key, msg in sub:
            # Each approval id counts once (the gate remembers them), and a stale one expired
            # in transit, so a replayed payload grants nothing new.
            rec = self.gate.receive(msg)
            self._dirty = False
            self._publish(rec.id)

    def _schedule(self) -> None:
        """Gate changed (pending action, use, expiry): publish once, from the loop."""
        if not self._dirty:
            self._dirty = True
            asyncio.get_running_loop().call_soon(self._flush)

    def _flush(self) -> None:
        if self._dirty and not self.mesh.closed:
            self._dirty = False
            self._publish("")

    def _publish(self, ack: str) -> None:
        if not self.mesh.closed:
            self.mesh.put(self.keys.approval_status(self.uav), self.status(ack), block=True)


__all__ = ["ApprovalLink"]
