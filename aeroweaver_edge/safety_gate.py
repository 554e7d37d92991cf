"""The safety gate: every motion passes here before it reaches the UAV's own vehicle.

It knows nothing about LLMs or skills. It turns an intent into one velocity setpoint that
fits the envelope (geofence, altitude band, speed cap, minimum separation from neighbours'
last known positions), clamping where a clamp is safe and holding where it is not.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from aeroweaver_edge.actions import Hold, Motion, MoveTo, SetVelocity
from aeroweaver_edge.config import SafetyConfig
from aeroweaver_edge.wire import Vec3

ZERO: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class GatedCommand:
    vel: Vec3
    held: bool
    violations: tuple[str, ...] = ()


def _finite(v: Sequence[float]) -> bool:
    return all(math.isfinite(x) for x in v)


def _clip(x: float, lo: float, hi: float) -> float:
    return min(max(x, lo), hi)


class SafetyGate:
    def __init__(self, cfg: SafetyConfig, horizon_s: float) -> None:
        """``horizon_s`` is how far ahead a setpoint is checked: one decision round."""
        self.cfg = cfg
        self.horizon_s = horizon_s

    def _inside(self, p: Vec3) -> Vec3:
        c = self.cfg
        alt_lo, alt_hi = c.altitude_band_m
        return (
            _clip(p[0], *c.geofence_north_m),
            _clip(p[1], *c.geofence_east_m),
            _clip(p[2], -alt_hi, -alt_lo),
        )

    def _cap(self, vel: Vec3, notes: list[str]) -> Vec3:
        speed = math.hypot(*vel)  # hypot: squares of huge components would overflow to inf
        if speed > self.cfg.max_speed_mps:
            k = self.cfg.max_speed_mps / speed
            vel = (vel[0] * k, vel[1] * k, vel[2] * k)
            if "speed capped" not in notes:
                notes.append("speed capped")
        return vel

    def gate(self, motion: Motion, pos: Vec3, neighbours: Sequence[Vec3] = ()) -> GatedCommand:
        if isinstance(motion, Hold):
            return GatedCommand(ZERO, held=True)
        if not _finite(pos):
            return GatedCommand(ZERO, True, ("own position not finite",))
        notes: list[str] = []
        if isinstance(motion, MoveTo):
            if not _finite(motion.target) or (
                motion.speed is not None and not math.isfinite(motion.speed)
            ):
                return GatedCommand(ZERO, True, ("non-finite target",))
            if motion.speed is not None and motion.speed < 0:
                return GatedCommand(ZERO, True, (f"negative speed {motion.speed}",))
            target = self._inside(motion.target)
            if target != motion.target:
                notes.append("target clamped into envelope")
            delta = tuple(t - p for t, p in zip(target, pos, strict=True))
            dist = math.hypot(*delta)
            cap = (
                self.cfg.max_speed_mps
                if motion.speed is None
                else min(motion.speed, self.cfg.max_speed_mps)
            )
            speed = min(cap, dist / self.horizon_s)
            vel: Vec3 = (
                ZERO
                if dist < 1e-9
                else (
                    delta[0] / dist * speed,
                    delta[1] / dist * speed,
                    delta[2] / dist * speed,
                )
            )
        elif isinstance(motion, SetVelocity):
            if not _finite(motion.vel):
                return GatedCommand(ZERO, True, ("non-finite velocity",))
            vel = motion.vel
        else:  # pragma: no cover - exhaustive over Motion
            return GatedCommand(ZERO, True, (f"unknown motion {type(motion).__name__}",))

        vel = self._cap(vel, notes)

        # Keep the predicted position inside the envelope (a velocity can carry us out).
        ahead = tuple(p + v * self.horizon_s for p, v in zip(pos, vel, strict=True))
        inside = self._inside((ahead[0], ahead[1], ahead[2]))
        if inside != ahead:
            vel = (
                (inside[0] - pos[0]) / self.horizon_s,
                (inside[1] - pos[1]) / self.horizon_s,
                (inside[2] - pos[2]) / self.horizon_s,
            )
            notes.append("velocity clamped at envelope edge")
            # From outside the envelope the way back can be longer than one horizon allows.
            vel = self._cap(vel, notes)

        # Never close in below the minimum separation, even when the neighbour closes in too.
        # Each UAV may close on a neighbour by at most half the gap beyond the minimum within
        # one horizon (a reciprocal half-plane): two gated UAVs that fly at each other in the
        # same round still end it at least the minimum apart, and a neighbour that does not
        # move is kept at (gap + minimum) / 2. A faster approach is slowed along its own
        # direction (which keeps the fence and the cap); with no gap left to close: hold.
        sep = self.cfg.min_separation_m
        if sep > 0:
            scale, tightest = 1.0, math.inf
            for other in neighbours:
                if not _finite(other):
                    continue
                gap = math.dist(pos, other)
                if gap < 1e-9:
                    continue  # on top of it: every direction opens the gap
                closing = (
                    sum(v * (o - p) for v, o, p in zip(vel, other, pos, strict=True))
                    / gap
                    * self.horizon_s
                )
                allowed = max(0.0, (gap - sep) / 2)
                if closing > allowed and allowed / closing < scale:
                    scale, tightest = allowed / closing, gap
            if scale <= 0.0:
                return GatedCommand(
                    ZERO, True, (*notes, f"separation: {tightest:.1f} m, minimum {sep} m")
                )
            if scale < 1.0:
                vel = (vel[0] * scale, vel[1] * scale, vel[2] * scale)
                notes.append(f"slowed for separation ({tightest:.1f} m, minimum {sep} m)")
        return GatedCommand(vel, held=False, violations=tuple(notes))
