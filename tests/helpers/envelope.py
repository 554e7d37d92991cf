"""Helpers for the envelope tests: hostile skill packages, and a gate that is not there.

``hostile_skills_root`` lays the shipped skill packages and the test-only hostile ones
(``tests/helpers/hostile_skills``: ``ram_peer``, ``dash_up_and_in``, ``leave_fence``) side by
side, so a daemon loads them through the real loader (``AEROWEAVER_SKILLS_DIR``).

``pass_through`` is what a daemon does with the safety gate wired around: the executor's raw
intent goes to the vehicle (a ``MoveTo`` flies there in one round, or at its own speed).
Monkeypatched over ``SafetyGate.gate``, it proves the world's envelope check can fail.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest

from aeroweaver_edge.contracts.actions import Hold, Motion, MoveTo, SetVelocity
from aeroweaver_edge.contracts.wire import Vec3
from aeroweaver_edge.safety.gate import GatedCommand, SafetyGate
from aeroweaver_edge.skills import default_root
from aeroweaver_edge.tasks.base import TaskDefinition
from aeroweaver_edge.world.kinematics import KinematicWorld

HOSTILE = Path(__file__).resolve().parent / "hostile_skills"
HOSTILE_SKILLS = ("ram_peer", "dash_up_and_in", "leave_fence")


def hostile_skills_root(where: Path) -> Path:
    """A skills directory under ``where``: every shipped package plus the hostile ones."""
    root = where / "skills"
    root.mkdir()
    for pkg in (*default_root().iterdir(), *HOSTILE.iterdir()):
        if pkg.is_dir() and not pkg.name.startswith(("_", ".")):
            shutil.copytree(pkg, root / pkg.name, ignore=shutil.ignore_patterns("__pycache__"))
    return root


def raw_velocity(motion: Motion, pos: Vec3, horizon_s: float) -> Vec3 | None:
    """The velocity an ungated executor intent asks for (``None``: hold)."""
    if isinstance(motion, Hold):
        return None
    if isinstance(motion, SetVelocity):
        return motion.vel
    assert isinstance(motion, MoveTo)
    delta = tuple(t - p for t, p in zip(motion.target, pos, strict=True))
    dist = math.hypot(*delta)
    if dist < 1e-9:
        return (0.0, 0.0, 0.0)
    speed = dist / horizon_s if motion.speed is None else motion.speed
    return (delta[0] / dist * speed, delta[1] / dist * speed, delta[2] / dist * speed)


def pass_through(
    self: SafetyGate,
    motion: Motion,
    pos: Vec3,
    neighbours: Sequence[Vec3] = (),
    others: Sequence[Vec3] = (),
) -> GatedCommand:
    """``SafetyGate.gate`` with every check removed (monkeypatch it over the class)."""
    vel = raw_velocity(motion, pos, self.horizon_s)
    return GatedCommand((0.0, 0.0, 0.0), True) if vel is None else GatedCommand(vel, False)


def record_worlds(monkeypatch: pytest.MonkeyPatch) -> list[KinematicWorld]:
    """Every world a task builds from now on (the runner's, per episode): a test reads the
    bodies' real positions from it after each round."""
    worlds: list[KinematicWorld] = []
    build = TaskDefinition.build_world

    def spy(self: TaskDefinition, *args: Any, **kw: Any) -> KinematicWorld:
        world = build(self, *args, **kw)
        worlds.append(world)
        return world

    monkeypatch.setattr(TaskDefinition, "build_world", spy)
    return worlds


__all__ = [
    "HOSTILE_SKILLS",
    "hostile_skills_root",
    "pass_through",
    "raw_velocity",
    "record_worlds",
]
