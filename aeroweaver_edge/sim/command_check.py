"""The world's check of every simulator command it receives: refuse what is malformed or
foreign, bound what is merely out of the envelope, never raise.

The daemon's safety gate already keeps its own commands in the envelope, but the world
cannot assume a command came through a gate (a compromised or buggy daemon, or a forgery in
an unsigned swarm). So the world, which owns the bodies, checks each command itself:

refused (not buffered, so a genuine command for the same round still counts; counted by
cause, in this order): ``key_mismatch`` (not on the commanding UAV's own key, or the header
names someone else), ``not_controlled`` (a body the world flies, or no body at all),
``non_finite`` (NaN or infinite velocity), ``wrong_round`` (late, early or foreign: only the
current ``(episode, round)``), ``duplicate`` (a second command for the same round: the first
valid one stands).

bounded (applied, counted as clamped): ``speed`` (faster than the body's cap: scaled down
along its direction, as the gate does) and ``geofence`` (a velocity whose one-round
prediction leaves the arena: shortened to end at the edge, as the gate does). For commands
that passed a gate both are no-ops, so a secured run's returns are unchanged.

Message references a command lists (``sent``) must be the commanding UAV's own and few:
others are dropped from the manifest (``foreign_ref``, ``too_many_refs``), so no UAV can make
its peers wait for messages it never sent in someone else's name.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Collection

import msgspec

from aeroweaver_edge.contracts.wire import Keys, SimCommand, Vec3
from aeroweaver_edge.world.kinematics import KinematicWorld

MAX_REFS = 64  # message references one command may list (a round's sends, with room)
TOLERANCE = 1e-6  # metres (and m/s): float noise in a gated command is not a violation


class CommandCheck:
    """Counts what it refused and what it bounded; one instance per world runner."""

    def __init__(self, keys: Keys, controlled: Collection[str]) -> None:
        self.keys = keys
        self.controlled = frozenset(controlled)
        self.refused: Counter[str] = Counter()
        self.clamped: Counter[str] = Counter()

    @property
    def refused_total(self) -> int:
        return sum(self.refused.values())

    def admit(
        self, key: str, cmd: SimCommand, where: tuple[int, int], taken: Collection[str]
    ) -> SimCommand | None:
        """The command to buffer for the round ``where`` (its manifest cleaned), or None
        (counted) if it must not count. ``taken``: UAVs whose command this round stands."""
        why = self._refuse(key, cmd, where, taken)
        if why is not None:
            self.refused[why] += 1
            return None
        own = [r for r in cmd.sent if r.sender == cmd.uav]
        if len(own) != len(cmd.sent):
            self.refused["foreign_ref"] += len(cmd.sent) - len(own)
        if len(own) > MAX_REFS:
            self.refused["too_many_refs"] += len(own) - MAX_REFS
            own = own[:MAX_REFS]
        if len(own) != len(cmd.sent):
            cmd = msgspec.structs.replace(cmd, sent=own)
        return cmd

    def _refuse(
        self, key: str, cmd: SimCommand, where: tuple[int, int], taken: Collection[str]
    ) -> str | None:
        if key != self.keys.sim_command(cmd.uav) or cmd.h.sender != cmd.uav:
            return "key_mismatch"
        if cmd.uav not in self.controlled:
            return "not_controlled"
        if not all(math.isfinite(x) for x in cmd.vel):
            return "non_finite"
        if (cmd.episode, cmd.round) != where:
            return "wrong_round"
        if cmd.uav in taken:
            return "duplicate"
        return None

    def bound(self, world: KinematicWorld, uav: str, vel: Vec3) -> Vec3:
        """``vel`` capped to the body's speed and kept inside the arena for one round."""
        body = world.body(uav)
        cap = world.speed_cap(body)
        n, e, d = vel
        speed = math.hypot(n, e)
        if speed > cap + TOLERANCE:
            n, e = n * cap / speed, e * cap / speed
            self.clamped["speed"] += 1
        half, dt = world.arena_half_m, world.round_s
        north, east = body.pos[0] + n * dt, body.pos[1] + e * dt
        inside = (min(max(north, -half), half), min(max(east, -half), half))
        if abs(inside[0] - north) > TOLERANCE or abs(inside[1] - east) > TOLERANCE:
            n, e = (inside[0] - body.pos[0]) / dt, (inside[1] - body.pos[1]) / dt
            self.clamped["geofence"] += 1
            speed = math.hypot(n, e)
            if speed > cap:  # from outside the arena the way back may take longer
                n, e = n * cap / speed, e * cap / speed
        return (n, e, d)


__all__ = ["MAX_REFS", "CommandCheck"]
