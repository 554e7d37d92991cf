"""The envelope invariant where commands land: the world checks every velocity it applies.

The safety gate sits in each daemon; nothing in the daemon can prove that what reaches a
vehicle went through it. This checker sits on the other side, in the world, and judges
every command a controlled UAV's body is about to fly against the configured envelope (the
daemons' ``SafetyConfig``): a gate that is bypassed, mis-wired or wrong shows up here as a
counted violation, by kind and by UAV, in the run summary. Swarm tests assert zero.

It is deliberately an independent oracle: it does not import or reuse ``safety/gate.py``,
only the envelope's numbers, and states each rule once from the envelope's definition:

* ``speed``: the commanded speed (3-D, as a real autopilot would fly it) is at most
  ``max_speed_mps``.
* ``geofence``: the position predicted by flying the command in a straight line for one
  horizon (one round: the gate's horizon) is inside the north/east fence.
* ``altitude``: the predicted altitude (``-down``) is inside ``altitude_band_m``.
* ``separation``: a UAV that closes in on a neighbour it was told about this round (a UAV
  entity of its perception) does not come nearer than ``min_separation_m`` to it at any
  time of the round, both flying straight lines: a controlled neighbour its own applied
  command (the world knows every command of the round at once), a world-flown one staying
  where it was. Two UAVs that swap places in one round meet halfway: a violation.

A UAV already outside the fence or band may fly a command that brings it nearer (that is
the gate's way back); it must not stay out or go further. A hold (zero velocity) is always
inside. The only slack is float rounding of a clamp at an edge (``TOL_M``, ``TOL_SPEED``).
World-flown agents (evaders, foragers) are not checked: no gate commands them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, Literal

from aeroweaver_edge.config import SafetyConfig
from aeroweaver_edge.contracts.wire import Vec3

Kind = Literal["speed", "geofence", "altitude", "separation"]
KINDS: Final[tuple[Kind, ...]] = ("speed", "geofence", "altitude", "separation")
TOL_M: Final = 1e-6
"""Metres of float rounding allowed at a clamped edge (a gate clamps *to* the edge)."""
TOL_SPEED: Final = 1e-9
"""Relative speed rounding allowed at the cap (a scaled vector's norm is not exact)."""
KEEP: Final = 20
"""Violations kept verbatim for the summary (all are counted)."""


@dataclass(frozen=True)
class Violation:
    uav: str
    episode: int
    round: int
    kind: Kind
    detail: str

    def as_dict(self) -> dict[str, Any]:
        return {
            "uav": self.uav,
            "episode": self.episode,
            "round": self.round,
            "kind": self.kind,
            "detail": self.detail,
        }


def _excess(x: float, lo: float, hi: float) -> float:
    """How far ``x`` lies outside ``[lo, hi]`` (0 inside)."""
    return max(lo - x, x - hi, 0.0)


def _sub(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _closest(r0: Vec3, d: Vec3) -> float:
    """Smallest ``|r0 + s * d|`` for ``s`` in [0, 1]: the nearest two straight-line
    motions come (``r0`` the gap now, ``d`` how the gap changes over the round)."""
    dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    s = 0.0 if dd == 0.0 else min(1.0, max(0.0, -(r0[0] * d[0] + r0[1] * d[1] + r0[2] * d[2]) / dd))
    return math.hypot(r0[0] + s * d[0], r0[1] + s * d[1], r0[2] + s * d[2])


def _left_or_stayed_out(now: float, ahead: float) -> bool:
    """Out of bounds after the round, and not on the way back in."""
    return ahead > TOL_M and ahead > now - TOL_M


@dataclass
class EnvelopeCheck:
    """Judges applied commands against ``safety`` over a horizon of ``horizon_s`` seconds."""

    safety: SafetyConfig
    horizon_s: float
    checked: int = 0  # commands judged (holds included)
    moving: int = 0  # of which non-zero velocities
    by_uav: dict[str, dict[Kind, int]] = field(default_factory=dict)
    first: list[Violation] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.horizon_s) and self.horizon_s > 0):
            raise ValueError(f"horizon_s must be positive and finite, got {self.horizon_s!r}")

    def ahead(self, pos: Vec3, vel: Vec3 | None) -> Vec3:
        """Where ``vel`` (``None``: hold) takes ``pos`` in one horizon, in a straight line."""
        if vel is None:
            return pos
        h = self.horizon_s
        return (pos[0] + vel[0] * h, pos[1] + vel[1] * h, pos[2] + vel[2] * h)

    def judge(
        self, pos: Vec3, vel: Vec3 | None, neighbours: Iterable[tuple[Vec3, Vec3]] = ()
    ) -> list[tuple[Kind, str]]:
        """Every rule ``vel`` (``None``: hold) breaks from ``pos``; pure. ``neighbours`` are
        (where it is, where it will be after the round) of each neighbour."""
        if vel is None or vel == (0.0, 0.0, 0.0):
            return []
        s = self.safety
        out: list[tuple[Kind, str]] = []
        if not all(math.isfinite(v) for v in (*pos, *vel)):
            return [("speed", f"non-finite command {vel!r} at {pos!r}")]
        speed = math.sqrt(vel[0] ** 2 + vel[1] ** 2 + vel[2] ** 2)
        if speed > s.max_speed_mps * (1.0 + TOL_SPEED):
            out.append(("speed", f"{speed:.3f} m/s > cap {s.max_speed_mps:g} m/s"))
        ahead = self.ahead(pos, vel)
        fence_now = max(_excess(pos[0], *s.geofence_north_m), _excess(pos[1], *s.geofence_east_m))
        fence_ahead = max(
            _excess(ahead[0], *s.geofence_north_m), _excess(ahead[1], *s.geofence_east_m)
        )
        if _left_or_stayed_out(fence_now, fence_ahead):
            out.append(
                (
                    "geofence",
                    f"predicted ({ahead[0]:.2f}, {ahead[1]:.2f}) is {fence_ahead:.3f} m "
                    "outside the fence",
                )
            )
        lo, hi = s.altitude_band_m
        alt_now, alt_ahead = -pos[2], -ahead[2]
        if _left_or_stayed_out(_excess(alt_now, lo, hi), _excess(alt_ahead, lo, hi)):
            out.append(("altitude", f"predicted altitude {alt_ahead:.2f} m outside [{lo}, {hi}]"))
        sep = s.min_separation_m
        if sep > 0:
            own = _sub(ahead, pos)
            for now, then in neighbours:
                if not all(math.isfinite(c) for c in (*now, *then)):
                    continue
                gap = _sub(now, pos)
                d_now = math.hypot(*gap)
                # Closest approach during the round (both fly straight lines), and whether
                # this UAV's own motion brings it nearer at all (its part of the approach).
                nearest = _closest(gap, _sub(_sub(then, now), own))
                mine = _closest(gap, (-own[0], -own[1], -own[2]))
                if nearest < sep - TOL_M and nearest < d_now - TOL_M and mine < d_now - TOL_M:
                    out.append(("separation", f"closing to {nearest:.2f} m < {sep:g} m of {now!r}"))
                    break
        return out

    def check_round(
        self,
        episode: int,
        round: int,
        positions: Mapping[str, Vec3],
        orders: Mapping[str, Vec3 | None],
        told: Mapping[str, Sequence[str]],
    ) -> list[Violation]:
        """Judge every applied command of one round: ``positions`` of every body now,
        ``orders`` the controlled UAVs' commands (``None``: hold), ``told`` the UAV ids each
        one perceived this round."""
        found: list[Violation] = []
        for uav, vel in orders.items():
            neighbours = [
                (positions[b], self.ahead(positions[b], orders.get(b)))
                for b in told.get(uav, ())
                if b in positions and b != uav
            ]
            found += self.check(uav, episode, round, positions[uav], vel, neighbours)
        return found

    def check(
        self,
        uav: str,
        episode: int,
        round: int,
        pos: Vec3,
        vel: Vec3 | None,
        neighbours: Iterable[tuple[Vec3, Vec3]] = (),
    ) -> list[Violation]:
        """Judge one applied command and count what it breaks."""
        self.checked += 1
        if vel is not None and vel != (0.0, 0.0, 0.0):
            self.moving += 1
        found = [
            Violation(uav, episode, round, kind, detail)
            for kind, detail in self.judge(pos, vel, neighbours)
        ]
        counts = self.by_uav.setdefault(uav, {})
        for v in found:
            counts[v.kind] = counts.get(v.kind, 0) + 1
            if len(self.first) < KEEP:
                self.first.append(v)
        return found

    @property
    def by_kind(self) -> dict[Kind, int]:
        return {k: sum(c.get(k, 0) for c in self.by_uav.values()) for k in KINDS}

    @property
    def total(self) -> int:
        return sum(self.by_kind.values())

    def summary(self) -> dict[str, Any]:
        """JSON-ready: totals, by kind, by UAV (only UAVs with violations), the first few,
        and the envelope and horizon they were judged against."""
        return {
            "total": self.total,
            "by_kind": dict(self.by_kind),
            "by_uav": {u: dict(c) for u, c in sorted(self.by_uav.items()) if c},
            "checked": self.checked,
            "moving": self.moving,
            "first": [v.as_dict() for v in self.first],
            "envelope": self.safety.model_dump(mode="json"),
            "horizon_s": self.horizon_s,
        }


__all__ = ["KINDS", "TOL_M", "TOL_SPEED", "EnvelopeCheck", "Kind", "Violation"]
