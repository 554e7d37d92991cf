"""Building blocks of the opponents the world flies (evader, foragers, concealment adversary).

They reuse the skills' own geometry (``evade_peer``'s escape point, ``explore_local``'s
waypoint), so a scripted opponent moves exactly as a UAV choosing that skill would; the
skill modules are imported on first use, never by a daemon that does not run the world.
A target point becomes a velocity with ``kinematics.steer`` at the body's own speed cap: the
world's agents are the environment and do not pass a safety gate.
"""

from __future__ import annotations

from aeroweaver_edge.contracts.defaults import ALTITUDE_M
from aeroweaver_edge.contracts.skill_api import SkillContext
from aeroweaver_edge.tasks.base import NE, Action
from aeroweaver_edge.tasks.policy import BOUNDARY_M
from aeroweaver_edge.world.kinematics import Body, KinematicWorld, steer


def context(body: Body, index: int, task: str, altitude_m: float = ALTITUDE_M) -> SkillContext:
    """The skill context a world-flown body acts under."""
    return SkillContext(
        uav=body.id, uav_index=index, role=body.role, task=task, altitude_m=altitude_m
    )


def explore_point(round: int, ctx: SkillContext) -> NE:
    """``explore_local``'s waypoint for this round: the 35 m circle, angle round/18 + 1.7 i."""
    from skills.explore_local.skill import waypoint

    return waypoint(round, ctx.uav_index, ctx)


def escape_from(body: Body, threat: Body, ctx: SkillContext) -> NE:
    """``evade_peer``'s escape point: the threat mirrored through the body, >= 20 m away,
    clamped inside ±60 m."""
    from skills.evade_peer.skill import escape_point

    return escape_point((body.north, body.east), (threat.north, threat.east), ctx)


def fly_to(world: KinematicWorld, body: Body, point: NE) -> Action:
    """Head for ``point`` this round (at most the body's cap, no overshoot)."""
    return Action(steer(body.pos, point, world.speed_cap(body), world.round_s))


def out_of_bounds(body: Body) -> bool:
    return max(abs(body.north), abs(body.east)) > BOUNDARY_M


__all__ = ["context", "escape_from", "explore_point", "fly_to", "out_of_bounds"]
