"""Frames for a swarm that flies real (or emulated) vehicles with no simulated world.

Nobody publishes a ``WorldSnapshot`` then, so the console builds its frames from what each
UAV daemon already publishes every round: its ``ProgressReport`` (skill, hold and cause,
and ``vehicle``: the link's position, flight mode, armed, battery, heartbeat age, the
daemon's flight phase and the points of interest it knows). The daemons' rounds run on
their own wall clocks, so a field frame is a *sample*: every ``period_s`` in which at least
one report came (or a UAV went quiet), one frame with each UAV's latest state.

A field frame has the shape of a world frame (``frames.py``) plus ``vehicles``
(per UAV: mode, armed, in_air, alt_m, battery_pct, heartbeat_age_s, phase, heard_s = age of
its last report, round = its own round) and ``source: "field"``; a UAV not heard for
``stale_s`` is listed in ``absent``. World frames also get ``vehicles`` when the daemons
report a link (``sim --link``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from aeroweaver_edge.console.frames import report_decision
from aeroweaver_edge.contracts.wire import ProgressReport, VehicleStatus
from aeroweaver_edge.orchestration.trace import entity_dict

PERIOD_S = 0.5
STALE_S = 3.0
MAX_UAVS_SHOWN = 256  # a flood of invented UAV names must not grow the view without bound


def _num(x: float | None, nd: int = 2) -> float | None:
    return None if x is None or not math.isfinite(x) else round(x, nd)


def _vec(v: tuple[float, ...]) -> list[float] | None:
    if not all(math.isfinite(c) and abs(c) < 1e7 for c in v[:2]):
        return None  # no place to draw it: the row still shows the rest
    return [round(v[0], 2), round(v[1], 2)]


@dataclass
class _Uav:
    report: ProgressReport
    heard: float  # local monotonic receipt time
    status: VehicleStatus | None


class FieldView:
    """Each UAV's latest report; ``frame()`` samples them into one frame."""

    def __init__(
        self,
        *,
        stale_s: float = STALE_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.stale_s = stale_s
        self._clock = clock
        self.uavs: dict[str, _Uav] = {}
        self.points: dict[str, dict[str, Any]] = {}
        self.mission_id = ""
        self.episode = 0  # one per mission seen (trails restart with a mission)
        self.round = -1
        self._fresh = False  # a report came since the last frame
        self._absent: list[str] = []

    def on_report(self, rep: ProgressReport) -> None:
        if rep.uav not in self.uavs and len(self.uavs) >= MAX_UAVS_SHOWN:
            return
        if rep.mission_id and rep.mission_id != self.mission_id:
            if self.mission_id:
                self.episode += 1
                self.round = -1
            self.mission_id = rep.mission_id
        self.uavs[rep.uav] = _Uav(rep, self._clock(), rep.vehicle)
        if rep.vehicle is not None:
            for p in rep.vehicle.points:
                room = len(self.points) < 4 * MAX_UAVS_SHOWN
                if p.id not in self.points and room and _vec(p.pos) is not None:
                    self.points[p.id] = entity_dict(p)
        self._fresh = True

    @property
    def flying(self) -> bool:
        """Some UAV reports a vehicle link (a field swarm, or ``sim --link``)."""
        return any(u.status is not None for u in self.uavs.values())

    def vehicles(self) -> dict[str, dict[str, Any]]:
        """Per UAV with a vehicle link: what it last reported, and how long ago."""
        now = self._clock()
        out: dict[str, dict[str, Any]] = {}
        for uav, u in sorted(self.uavs.items()):
            st = u.status
            if st is None:
                continue
            alt = -st.pos[2] if math.isfinite(st.pos[2]) else None
            out[uav] = {
                "mode": st.mode,
                "armed": st.armed,
                "in_air": st.in_air,
                "alt_m": _num(alt, 1),
                "battery_pct": _num(st.battery_pct, 0),
                "heartbeat_age_s": _num(st.heartbeat_age_s),
                "phase": st.phase,
                "heard_s": round(now - u.heard, 2),
                "round": u.report.round,
            }
        return out

    def frame(self, task: str = "") -> dict[str, Any] | None:
        """The next field frame, or None when nothing changed since the last one."""
        now = self._clock()
        absent = sorted(u for u, x in self.uavs.items() if now - x.heard > self.stale_s)
        if not self._fresh and absent == self._absent:
            return None
        self._fresh, self._absent = False, absent
        flying = {u: x for u, x in sorted(self.uavs.items()) if x.status is not None}
        if not flying:
            return None
        self.round += 1
        bodies = []
        for uav, x in flying.items():
            assert x.status is not None
            pos = _vec(x.status.pos)
            if pos is None:
                continue
            body: dict[str, Any] = {"id": uav, "kind": "uav", "pos": pos}
            vel = _vec(x.status.vel)
            if vel is not None and any(vel):
                body["vel"] = vel
            if x.report.role:
                body["role"] = x.report.role
            bodies.append(body)
        return {
            "episode": self.episode,
            "round": self.round,
            "stamp": time.time(),
            "task": task,
            "source": "field",
            "uavs": list(flying),
            "bodies": bodies,
            "entities": [self.points[k] for k in sorted(self.points)],
            "held": [u for u, x in flying.items() if x.report.held],
            "messages": [],
            "guesses": {},
            "missed": [],
            "absent": [u for u in absent if u in flying],
            "rewards": {},
            "team_reward": None,
            "complete": False,
            "done": False,
            "reason": "",
            "decisions": {u: report_decision(x.report) for u, x in flying.items()},
            "vehicles": self.vehicles(),
        }


__all__ = ["PERIOD_S", "STALE_S", "FieldView"]
