"""The Commander's side of ``aeroweaver mission start``: find the daemons that are up, and
watch a published mission to its end (``aeroweaver_edge.orchestration.mission`` wires it,
with the kinematic world when asked; the Commander never imports the simulator).

The Commander never flies: it publishes context and assignments and reads reports. Ending
the mission (termination, horizon or Ctrl-C) publishes the ended context, so every UAV holds.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import TYPE_CHECKING, Any

from aeroweaver_edge.contracts.wire import Keys, last_chunk
from commander.commander import Commander
from commander.progress import UavProgress

if TYPE_CHECKING:
    from aeroweaver_edge.mesh.session import Mesh


async def discover_roster(mesh: Mesh, swarm: str, wait_s: float) -> list[str]:
    """UAV ids whose liveliness tokens are seen within ``wait_s``."""
    alive: set[str] = set()
    watch = mesh.watch_liveliness(Keys(swarm).alive_uav("*"))
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(wait_s):
            async for key, up in watch:
                (alive.add if up else alive.discard)(last_chunk(key))
    await watch.aclose()
    return sorted(alive)


def progress_row(p: UavProgress) -> dict[str, Any]:
    return {
        "role": p.role,
        "reports": p.reports,
        "holds": p.holds,
        "last": p.last.invocation if p.last else None,
        "prompt_tokens": p.prompt_tokens,
        "completion_tokens": p.completion_tokens,
    }


async def watch_until(commander: Commander, uavs: list[str], rounds: int) -> None:
    """Field mode: the mission runs until every participant reported ``rounds`` rounds."""
    while not all(
        (p := commander.board.uavs.get(u)) is not None and p.reports >= rounds for u in uavs
    ):
        commander.report_event.clear()
        await commander.report_event.wait()
