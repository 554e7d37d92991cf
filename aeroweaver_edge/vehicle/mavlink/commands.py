"""The MAVLink command protocol: COMMAND_LONG/INT out, COMMAND_ACK back.

An ACK is matched on command id, on the vehicle's autopilot as source and (when the
autopilot fills them) on our own system/component as target. A missing ACK is retried a
bounded number of times with the ``confirmation`` field incremented, so the autopilot can
tell a retry from a new command; ``MAV_RESULT_IN_PROGRESS`` extends the wait without a
resend. Before every retry the caller's ``done`` check runs: if the vehicle already shows
the effect (mode reached, armed), the command is not sent again, so a lost ACK never
duplicates an action.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from aeroweaver_edge.vehicle.mavlink.codec import AUTOPILOT_COMPID, Message, mavlink
from aeroweaver_edge.vehicle.mavlink.link import FlightLink, LinkError

log = logging.getLogger(__name__)

ACCEPTED: int = mavlink.MAV_RESULT_ACCEPTED
IN_PROGRESS: int = mavlink.MAV_RESULT_IN_PROGRESS
RESULT_NAMES = {
    v: k.removeprefix("MAV_RESULT_")
    for k, v in vars(mavlink).items()
    if k.startswith("MAV_RESULT_") and isinstance(v, int) and k != "MAV_RESULT_ENUM_END"
}
UNUSED = 0.0  # what an unused param carries: MAVLink's "reserved (default: 0)"


class CommandError(LinkError):
    """A command was refused or never acknowledged."""

    def __init__(self, command: int, result: int | None, detail: str) -> None:
        super().__init__(detail)
        self.command = command
        self.result = result


@dataclass
class CommandStats:
    sent: Counter[int] = field(default_factory=Counter)  # transmissions incl. retries
    retries: Counter[int] = field(default_factory=Counter)
    results: Counter[str] = field(default_factory=Counter)
    skipped_done: int = 0  # retries not sent because the effect was already visible
    rtt_s: list[float] = field(default_factory=list)  # first-try round trips (bounded)


def command_name(command: int) -> str:
    entry = mavlink.enums["MAV_CMD"].get(command)
    return entry.name.removeprefix("MAV_CMD_") if entry is not None else str(command)


class CommandClient:
    def __init__(
        self,
        link: FlightLink,
        *,
        timeout_s: float = 0.5,
        retries: int = 4,
        in_progress_s: float = 10.0,
    ) -> None:
        self.link = link
        self.timeout_s = timeout_s
        self.retries = retries
        self.in_progress_s = in_progress_s
        self.stats = CommandStats()
        self._locks: dict[int, asyncio.Lock] = {}

    def _matches(self, command: int) -> Callable[[Message], bool]:
        def pred(ack: Message) -> bool:
            return (
                ack.command == command
                and ack.get_srcComponent() == AUTOPILOT_COMPID
                and ack.target_system in (0, self.link.sysid)
                and ack.target_component in (0, self.link.compid)
            )

        return pred

    def _build(
        self,
        command: int,
        params: tuple[float, ...],
        confirmation: int,
        as_int: bool,
        frame: int,
    ) -> Message:
        # Unused params are 0, never NaN: ArduPilot converts some to integers, and its SITL
        # traps the invalid conversion (SIGFPE: a NaN-padded ARM killed the autopilot).
        p = (*params, *([UNUSED] * (7 - len(params))))[:7]
        sysid, compid = self.link.target
        if as_int:
            return self.link.mav.command_int_encode(
                sysid,
                compid,
                frame,
                command,
                0,
                0,
                p[0],
                p[1],
                p[2],
                p[3],
                int(p[4]) if math.isfinite(p[4]) else 0,
                int(p[5]) if math.isfinite(p[5]) else 0,
                p[6],
            )
        return self.link.mav.command_long_encode(sysid, compid, command, confirmation, *p)

    async def send(
        self,
        command: int,
        *params: float,
        done: Callable[[], bool] | None = None,
        as_int: bool = False,
        frame: int = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        check: bool = True,
    ) -> int:
        """Send ``command`` and return its final MAV_RESULT.

        ``done`` is checked before each retry; ``check`` raises ``CommandError`` for any
        result but ACCEPTED. One command id is in flight at a time.
        """
        lock = self._locks.setdefault(command, asyncio.Lock())
        async with lock:
            result = await self._send(command, params, done, as_int, frame)
        self.stats.results[RESULT_NAMES.get(result, str(result))] += 1
        if check and result != ACCEPTED:
            raise CommandError(
                command,
                result,
                f"{command_name(command)} refused by system {self.link.sysid}: "
                f"{RESULT_NAMES.get(result, result)}",
            )
        return result

    async def _send(
        self,
        command: int,
        params: tuple[float, ...],
        done: Callable[[], bool] | None,
        as_int: bool,
        frame: int,
    ) -> int:
        name = command_name(command)
        for attempt in range(self.retries + 1):
            if attempt > 0:
                if done is not None and done():
                    self.stats.skipped_done += 1
                    log.info("%s: effect already visible, not resent", name)
                    return ACCEPTED
                self.stats.retries[command] += 1
            ack_fut = self.link.expect("COMMAND_ACK", self._matches(command))
            started = time.monotonic()
            self.link.send(self._build(command, params, min(attempt, 255), as_int, frame))
            self.stats.sent[command] += 1
            deadline = self.timeout_s
            while True:
                try:
                    async with asyncio.timeout(deadline):  # a cancel is never swallowed
                        ack = await asyncio.shield(ack_fut)
                except TimeoutError:
                    ack_fut.cancel()
                    break
                if attempt == 0 and len(self.stats.rtt_s) < 10_000:
                    self.stats.rtt_s.append(time.monotonic() - started)
                if ack.result != IN_PROGRESS:
                    return int(ack.result)
                # Accepted and running: wait for the final ACK, do not resend.
                ack_fut = self.link.expect("COMMAND_ACK", self._matches(command))
                deadline = self.in_progress_s
            if self.link.lost:
                break
        raise CommandError(
            command,
            None,
            f"{name}: no COMMAND_ACK from system {self.link.sysid} after {self.retries + 1} tries",
        )
