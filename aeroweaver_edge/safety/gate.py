"""The safety gate: every motion passes here before it reaches the UAV's own vehicle.

It knows nothing about LLMs or skills. It turns an intent into one velocity setpoint that
fits the envelope (geofence, altitude band, speed cap, minimum separation from neighbours'
last known positions), clamping where a clamp is safe and holding where it is not.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from aeroweaver_edge.config import SafetyConfig
from aeroweaver_edge.contracts.actions import Hold, Motion, MoveTo, SetVelocity
from aeroweaver_edge.contracts.wire import Vec3

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

    def _closing(self, vel: Vec3, u: Vec3) -> float:
        """Metres this velocity closes in along ``u`` within one horizon."""
        return (vel[0] * u[0] + vel[1] * u[1] + vel[2] * u[2]) * self.horizon_s

    def _separation_limits(
        self, pos: Vec3, neighbours: Sequence[Vec3], others: Sequence[Vec3]
    ) -> list[tuple[Vec3, float, float]]:
        """(unit vector toward the body, metres we may close in on it, gap) per body."""
        sep = self.cfg.min_separation_m
        out: list[tuple[Vec3, float, float]] = []
        if sep <= 0:
            return out
        for bodies, share in ((neighbours, 2.0), (others, 1.0)):
            for other in bodies:
                if not _finite(other):
                    continue
                gap = math.dist(pos, other)
                if gap < 1e-9:
                    continue  # on top of it: every direction opens the gap
                u = (
                    (other[0] - pos[0]) / gap,
                    (other[1] - pos[1]) / gap,
                    (other[2] - pos[2]) / gap,
                )
                out.append((u, max(0.0, (gap - sep) / share), gap))
        return out

    def _fits(self, pos: Vec3, vel: Vec3, limits: list[tuple[Vec3, float, float]]) -> bool:
        """Inside the cap, the envelope one horizon ahead and every separation limit."""
        h = self.horizon_s
        ahead = (pos[0] + vel[0] * h, pos[1] + vel[1] * h, pos[2] + vel[2] * h)
        inside = self._inside(ahead)
        return (
            math.hypot(*vel) <= self.cfg.max_speed_mps * (1 + 1e-12)
            and math.dist(inside, ahead) <= 1e-9
            and all(self._closing(vel, u) <= a + 1e-9 for u, a, _gap in limits)
        )

    def gate(
        self,
        motion: Motion,
        pos: Vec3,
        neighbours: Sequence[Vec3] = (),
        others: Sequence[Vec3] = (),
    ) -> GatedCommand:
        """``neighbours``: last known positions of UAVs that run this gate too (they share
        every gap); ``others``: of bodies that do not (world-flown opponents)."""
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
        # A UAV may close on a gated neighbour by at most half the gap beyond the minimum
        # within one horizon (a reciprocal half-plane: two gated UAVs that fly at each other
        # in the same round still end it at least the minimum apart); on a body that runs no
        # gate of ours, by the whole spare gap. Only the excess approach is taken away (the
        # UAV slides past); where sliding would break another limit it is slowed along its
        # own direction instead (which keeps the fence and the cap); nothing left: hold.
        limits = self._separation_limits(pos, neighbours, others)
        over = [lim for lim in limits if self._closing(vel, lim[0]) > lim[1]]
        if over:
            tightest = min(gap for _u, _a, gap in over)
            why = f"{tightest:.1f} m, minimum {self.cfg.min_separation_m} m"
            slid = vel
            for u, allowed, _gap in limits:
                excess = self._closing(slid, u) - allowed
                if excess > 0:
                    k = excess / self.horizon_s
                    slid = (slid[0] - k * u[0], slid[1] - k * u[1], slid[2] - k * u[2])
            if self._fits(pos, slid, limits):
                vel = slid
                notes.append(f"slid past for separation ({why})")
            else:
                scale = min(allowed / self._closing(vel, u) for u, allowed, _gap in over)
                vel = (vel[0] * scale, vel[1] * scale, vel[2] * scale)
                notes.append(f"slowed for separation ({why})")
            if math.hypot(*vel) < 1e-9:
                return GatedCommand(ZERO, True, (*notes[:-1], f"separation: {why}"))
        return GatedCommand(vel, held=False, violations=tuple(notes))
