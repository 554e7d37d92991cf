"""The kinematic world: point-mass UAVs at a fixed altitude in a local NED frame.

This is physics and nothing else (no tasks, rewards or networking). It lives at the top of
the package, below both the simulator and the task definitions, so the task platform
(``aeroweaver_edge.tasks``, which the Commander reads too), the simulator, the benchmark and
a future MAVLink emulator share one definition of motion without importing each other.
It reproduces the authors' substrate (docs/notes/mpe-tasks.md): a 140 x 140 m arena centred on
(0, 0), 0.5 s rounds integrated as 10 ticks of 0.05 s, motion commands that persist until
changed.

Model, per tick of ``dt`` (semi-implicit Euler):

1. the velocity moves toward the commanded setpoint by at most ``max_accel * dt``;
2. the speed is capped at ``max_speed``;
3. the position advances by ``velocity * dt``.

Motion is horizontal only: every body flies at ``down = -altitude_m`` and the down component
of a command is ignored, because every benchmark task is planar (MPE is 2-D) and the authors
fly at a fixed altitude. Positions are *not* clamped to the arena: leaving it is a task-level
matter (boundary penalties, the safety gate's geofence), not physics.

Plain Python floats are used instead of numpy: with a handful of bodies the per-call overhead
of tiny arrays costs more than the arithmetic. ``step`` draws no random numbers, so equal
inputs give bit-identical trajectories.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Final

from aeroweaver_edge.config import SimConfig
from aeroweaver_edge.contracts.defaults import (
    ALTITUDE_M,
    ARENA_HALF_M,
    MAX_ACCEL_MPS2,
    MAX_SPEED_MPS,
    ROUND_S,
    SENSING_RADIUS_M,
)
from aeroweaver_edge.contracts.wire import Entity, Vec3

__all__ = ["ARENA_HALF_M", "SUBSTEP_S", "Body", "KinematicWorld", "steer"]

SUBSTEP_S: Final = 0.05
"""Physics tick used by the authors (10 ticks per 0.5 s round)."""


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


@dataclass(slots=True)
class Body:
    """One UAV's kinematic state. Mutated only by :class:`KinematicWorld`."""

    id: str
    north: float
    east: float
    down: float
    vn: float = 0.0
    ve: float = 0.0
    sp_n: float = 0.0  # commanded velocity setpoint, kept until changed
    sp_e: float = 0.0
    role: str = ""
    absent: bool = False  # daemon died or missed its deadline: holds, ignores commands
    max_speed: float | None = None  # per-body cap (e.g. the faster evader); None: the world's

    @property
    def pos(self) -> Vec3:
        return (self.north, self.east, self.down)

    @property
    def vel(self) -> Vec3:
        return (self.vn, self.ve, 0.0)

    @property
    def setpoint(self) -> Vec3:
        return (self.sp_n, self.sp_e, 0.0)

    @property
    def speed(self) -> float:
        return math.hypot(self.vn, self.ve)

    def as_entity(self) -> Entity:
        """The body as a peer would sense it (kind ``"uav"``)."""
        return Entity(id=self.id, kind="uav", pos=self.pos, vel=self.vel, role=self.role)


class KinematicWorld:
    """Point-mass UAVs plus static entities (landmarks, food, ...) in one arena.

    Deterministic: the only inputs are the spawn state and the setpoints given through
    :meth:`set_velocity` / :meth:`hold`.
    """

    def __init__(
        self,
        *,
        altitude_m: float = ALTITUDE_M,
        max_speed_mps: float = MAX_SPEED_MPS,
        max_accel_mps2: float = MAX_ACCEL_MPS2,
        round_s: float = ROUND_S,
        substep_s: float = SUBSTEP_S,
        sensing_radius_m: float = SENSING_RADIUS_M,
        arena_half_m: float = ARENA_HALF_M,
    ) -> None:
        for name, value in (
            ("altitude_m", altitude_m),
            ("max_speed_mps", max_speed_mps),
            ("max_accel_mps2", max_accel_mps2),
            ("round_s", round_s),
            ("substep_s", substep_s),
            ("sensing_radius_m", sensing_radius_m),
            ("arena_half_m", arena_half_m),
        ):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        self.altitude_m = altitude_m
        self.max_speed = max_speed_mps
        self.max_accel = max_accel_mps2
        self.round_s = round_s
        self.substep_s = substep_s
        self.sensing_radius_m = sensing_radius_m
        self.arena_half_m = arena_half_m
        self.time_s = 0.0
        self.ticks = 0
        self._bodies: dict[str, Body] = {}
        self._entities: dict[str, Entity] = {}

    @classmethod
    def from_config(cls, config: SimConfig) -> KinematicWorld:
        return cls(
            altitude_m=config.altitude_m,
            max_speed_mps=config.max_speed_mps,
            max_accel_mps2=config.max_accel_mps2,
            round_s=config.round_s,
            sensing_radius_m=config.sensing_radius_m,
        )

    # ----------------------------------------------------------------- population

    @property
    def down_m(self) -> float:
        """The NED down coordinate of the flight level (negative: above ground)."""
        return -self.altitude_m

    def add_uav(
        self,
        uav: str,
        pos: Vec3 | tuple[float, float],
        role: str = "",
        *,
        max_speed: float | None = None,
    ) -> Body:
        """Place a UAV at rest at ``pos`` (north, east[, down]); down is set to the flight level.

        ``max_speed`` overrides the world's speed cap for this body only."""
        if uav in self._bodies or uav in self._entities:
            raise ValueError(f"duplicate id {uav!r}")
        north, east = float(pos[0]), float(pos[1])
        if not _finite(north, east):
            raise ValueError(f"non-finite position for {uav!r}: {pos!r}")
        if max_speed is not None and not (math.isfinite(max_speed) and max_speed > 0):
            raise ValueError(f"max_speed must be a positive finite number, got {max_speed!r}")
        body = Body(
            id=uav, north=north, east=east, down=self.down_m, role=role, max_speed=max_speed
        )
        self._bodies[uav] = body
        return body

    def add_entity(self, entity: Entity) -> None:
        """Add or replace a static entity (tasks may swap one, e.g. a picked-up treasure)."""
        if entity.id in self._bodies:
            raise ValueError(f"id {entity.id!r} is already a UAV")
        self._entities[entity.id] = entity

    def remove_entity(self, entity_id: str) -> None:
        del self._entities[entity_id]

    def body(self, uav: str) -> Body:
        try:
            return self._bodies[uav]
        except KeyError:
            raise KeyError(f"unknown UAV {uav!r}") from None

    @property
    def uav_ids(self) -> list[str]:
        return list(self._bodies)

    def bodies(self) -> Iterator[Body]:
        return iter(self._bodies.values())

    def entities(self) -> Iterator[Entity]:
        return iter(self._entities.values())

    def has_entity(self, entity_id: str) -> bool:
        return entity_id in self._entities

    def entity(self, entity_id: str) -> Entity:
        try:
            return self._entities[entity_id]
        except KeyError:
            raise KeyError(f"unknown entity {entity_id!r}") from None

    # ------------------------------------------------------------------- commands

    def set_velocity(self, uav: str, vel: Vec3 | tuple[float, float]) -> bool:
        """Command a horizontal velocity; it is kept until changed.

        The down component (if any) is ignored: flight is at a fixed altitude. A setpoint
        faster than ``max_speed`` is scaled down along its direction. Returns ``False`` (and
        changes nothing) when the UAV is marked absent: a dead daemon cannot fly it.
        """
        body = self.body(uav)
        n, e = float(vel[0]), float(vel[1])
        if not _finite(n, e):
            raise ValueError(f"non-finite velocity for {uav!r}: {vel!r}")
        if body.absent:
            return False
        cap = self.speed_cap(body)
        speed = math.hypot(n, e)
        if speed > cap:
            n, e = n * cap / speed, e * cap / speed
        body.sp_n, body.sp_e = n, e
        return True

    def speed_cap(self, body: Body) -> float:
        return self.max_speed if body.max_speed is None else body.max_speed

    def hold(self, uav: str) -> None:
        """Zero the setpoint; the UAV decelerates at the acceleration limit and stops."""
        body = self.body(uav)
        body.sp_n = body.sp_e = 0.0

    def mark_absent(self, uav: str) -> None:
        """The UAV's daemon is gone: it holds and ignores commands until marked present."""
        body = self.body(uav)
        body.absent = True
        body.sp_n = body.sp_e = 0.0

    def mark_present(self, uav: str) -> None:
        self.body(uav).absent = False

    # -------------------------------------------------------------------- physics

    def step(self, dt_total: float | None = None) -> None:
        """Advance by ``dt_total`` (default: one round) in ticks of at most ``substep_s``."""
        total = self.round_s if dt_total is None else dt_total
        if not (math.isfinite(total) and total > 0):
            raise ValueError(f"dt_total must be positive and finite, got {total!r}")
        n_ticks = max(1, round(total / self.substep_s))
        dt = total / n_ticks
        dv_max = self.max_accel * dt
        bodies = [(b, self.speed_cap(b)) for b in self._bodies.values()]
        for _ in range(n_ticks):
            for b, v_max in bodies:
                dvn, dve = b.sp_n - b.vn, b.sp_e - b.ve
                dv = math.hypot(dvn, dve)
                if dv > dv_max:
                    dvn, dve = dvn * dv_max / dv, dve * dv_max / dv
                vn, ve = b.vn + dvn, b.ve + dve
                speed = math.hypot(vn, ve)
                if speed > v_max:
                    vn, ve = vn * v_max / speed, ve * v_max / speed
                b.vn, b.ve = vn, ve
                b.north += vn * dt
                b.east += ve * dt
        self.ticks += n_ticks
        self.time_s += total

    # -------------------------------------------------------------------- sensing

    def horizontal_distance(self, a: Vec3, b: Vec3) -> float:
        return math.hypot(a[0] - b[0], a[1] - b[1])

    def sense(self, uav: str, radius_m: float | None = None) -> list[Entity]:
        """Static entities and peer UAVs within ``radius_m`` (horizontal, inclusive) of ``uav``.

        Peers come as kind ``"uav"``; the sensing UAV itself is excluded. Order: static
        entities in insertion order, then peers in spawn order (stable, so prompts built from
        it are reproducible).
        """
        me = self.body(uav)
        radius = self.sensing_radius_m if radius_m is None else radius_m
        out = [
            e
            for e in self._entities.values()
            if math.hypot(e.pos[0] - me.north, e.pos[1] - me.east) <= radius
        ]
        out.extend(
            b.as_entity()
            for b in self._bodies.values()
            if b is not me and math.hypot(b.north - me.north, b.east - me.east) <= radius
        )
        return out

    def in_arena(self, pos: Vec3 | tuple[float, float]) -> bool:
        return abs(pos[0]) <= self.arena_half_m and abs(pos[1]) <= self.arena_half_m

    def near_collisions(self, threshold_m: float = 2.0, ids: Iterable[str] | None = None) -> int:
        """Number of UAV pairs closer than ``threshold_m`` (horizontal)."""
        pool = list(self._bodies.values()) if ids is None else [self.body(i) for i in ids]
        count = 0
        for i, a in enumerate(pool):
            for b in pool[i + 1 :]:
                if math.hypot(a.north - b.north, a.east - b.east) < threshold_m:
                    count += 1
        return count


def steer(
    pos: Vec3, target: Vec3 | tuple[float, float], max_speed: float, horizon_s: float
) -> Vec3:
    """The horizontal velocity that flies from ``pos`` toward ``target`` within one horizon:
    along the line, at ``max_speed`` or slower so the body does not overshoot in
    ``horizon_s``. The same conversion the safety gate applies to a ``MoveTo`` (without its
    envelope checks), used for the agents the world itself flies."""
    dn, de = target[0] - pos[0], target[1] - pos[1]
    dist = math.hypot(dn, de)
    if dist < 1e-9:
        return (0.0, 0.0, 0.0)
    speed = min(max_speed, dist / horizon_s)
    return (dn / dist * speed, de / dist * speed, 0.0)
