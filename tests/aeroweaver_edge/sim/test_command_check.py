"""The world refuses malformed or foreign commands and bounds the rest, and never raises.

Unit checks of ``CommandCheck`` on a real kinematic world, then the world runner over real
zenoh sessions with stand-in daemons that send hostile commands (an unsigned mesh: here the
application's own checks are all there is).
"""

from __future__ import annotations

import math

import pytest

from aeroweaver_edge.contracts.wire import (
    HeaderFactory,
    Keys,
    MsgRef,
    SimCommand,
    SimPerception,
    Vec3,
)
from aeroweaver_edge.sim.command_check import MAX_REFS, CommandCheck
from aeroweaver_edge.tasks import create
from aeroweaver_edge.world.kinematics import KinematicWorld
from tests.aeroweaver_edge.sim.test_runner import KEYS, command, holding, play
from tests.helpers.zenoh_net import ZenohNet

K = Keys("cc")
WHERE = (0, 3)


def cmd(
    uav: str = "uav0",
    *,
    sender: str | None = None,
    where: tuple[int, int] = WHERE,
    vel: Vec3 = (1.0, 0.0, 0.0),
    sent: list[MsgRef] | None = None,
) -> SimCommand:
    return SimCommand(
        h=HeaderFactory(sender or uav).next(),
        uav=uav,
        episode=where[0],
        round=where[1],
        vel=vel,
        sent=sent or [],
    )


@pytest.mark.parametrize(
    ("key", "command_", "taken", "cause"),
    [
        (K.sim_command("uav1"), cmd(), (), "key_mismatch"),
        (K.sim_command("uav0"), cmd(sender="uav1"), (), "key_mismatch"),
        (K.state("uav0"), cmd(), (), "key_mismatch"),
        (K.sim_command("evader"), cmd("evader"), (), "not_controlled"),
        (K.sim_command("uav0"), cmd(where=(0, 4)), (), "wrong_round"),
        (K.sim_command("uav0"), cmd(where=(1, 3)), (), "wrong_round"),
        (K.sim_command("uav0"), cmd(vel=(math.nan, 0.0, 0.0)), (), "non_finite"),
        (K.sim_command("uav0"), cmd(vel=(0.0, math.inf, 0.0)), (), "non_finite"),
        (K.sim_command("uav0"), cmd(vel=(0.0, 0.0, -math.inf)), (), "non_finite"),
        (K.sim_command("uav0"), cmd(), ("uav0",), "duplicate"),
    ],
)
def test_malformed_or_foreign_commands_are_refused_by_cause(
    key: str, command_: SimCommand, taken: tuple[str, ...], cause: str
) -> None:
    check = CommandCheck(K, ["uav0", "uav1"])
    assert check.admit(key, command_, WHERE, taken) is None
    assert check.refused == {cause: 1}
    assert check.admit(K.sim_command("uav0"), cmd(), WHERE, ()) is not None  # control
    assert check.refused_total == 1


def test_foreign_and_excess_message_references_leave_the_manifest() -> None:
    check = CommandCheck(K, ["uav0"])
    own = [MsgRef(sender="uav0", seq=i, to="uav1") for i in range(MAX_REFS + 5)]
    forged = [MsgRef(sender="uav1", seq=7, to="uav2")]
    ok = check.admit(K.sim_command("uav0"), cmd(sent=[*forged, *own]), WHERE, ())
    assert ok is not None
    assert ok.sent == own[:MAX_REFS]
    assert check.refused == {"foreign_ref": 1, "too_many_refs": 5}


def world_at(north: float, east: float = 0.0) -> KinematicWorld:
    w = KinematicWorld()
    w.add_uav("uav0", (north, east))
    return w


def test_speed_is_capped_along_the_commanded_direction() -> None:
    check = CommandCheck(K, ["uav0"])
    w = world_at(0.0)
    n, e, _ = check.bound(w, "uav0", (30.0, 40.0, 0.0))
    assert math.hypot(n, e) == pytest.approx(w.max_speed)
    assert n / e == pytest.approx(30.0 / 40.0)
    assert check.clamped == {"speed": 1}


def test_a_velocity_that_would_leave_the_arena_ends_at_its_edge() -> None:
    check = CommandCheck(K, ["uav0"])
    w = world_at(w_half := KinematicWorld().arena_half_m - 1.0)
    n, e, _ = check.bound(w, "uav0", (10.0, 0.0, 0.0))
    assert w_half + n * w.round_s == pytest.approx(w.arena_half_m)
    assert e == 0.0
    assert check.clamped == {"geofence": 1}


def test_a_gated_command_passes_unchanged() -> None:
    """The daemon's gate already keeps commands inside: the world's bound is then a no-op,
    so secured and insecure runs give the same returns."""
    check = CommandCheck(K, ["uav0"])
    w = world_at(10.0, -20.0)
    vel = (w.max_speed * 0.6, -w.max_speed * 0.8, 0.0)
    assert check.bound(w, "uav0", vel) == vel
    edge = world_at(w.arena_half_m - 2.0)
    exact = (2.0 / edge.round_s, 0.0, 0.0)  # what the gate gives at the edge
    assert check.bound(edge, "uav0", exact) == exact
    assert not check.clamped


async def test_world_refuses_a_nan_velocity_and_takes_the_genuine_command(
    zenoh_net: ZenohNet,
) -> None:
    """Forged NaN first, then the UAV's own command for the same round: the world does
    not crash, counts the NaN and flies the genuine one."""

    def nan_then_real(p: SimPerception, hf: HeaderFactory) -> list[tuple[str, SimCommand]]:
        bad = command(hf, p, vel=(math.nan, 1.0, 0.0))
        return [
            (KEYS.sim_command(p.uav), bad),
            (KEYS.sim_command(p.uav), command(hf, p, vel=(2.0, 0.0, 0.0))),
        ]

    runner, result, logs, ins = await play(zenoh_net, {"uav0": nan_then_real, "uav1": holding}, 3)
    assert result.rounds == 3
    assert runner.check.refused == {"non_finite": 3}
    assert [log.refused for log in logs] == [{"non_finite": 1}] * 3
    assert all(log.commands["uav0"].vel == (2.0, 0.0, 0.0) for log in logs)
    assert ins["uav0"].pos(1)[0] > ins["uav0"].pos(0)[0]  # it flew the genuine command


async def test_a_runaway_command_is_held_to_speed_and_arena(zenoh_net: ZenohNet) -> None:
    """A compromised daemon commanding its own body at 50 m/s north for 24 rounds: the
    world flies it at the vehicle's top speed and stops it at the arena's edge (past it
    by at most the braking distance, as with a gated command)."""

    def runaway(p: SimPerception, hf: HeaderFactory) -> list[tuple[str, SimCommand]]:
        return [(KEYS.sim_command(p.uav), command(hf, p, vel=(50.0, 0.0, 0.0)))]

    task = create("coverage", 2, max_rounds=24)
    runner, result, _logs, ins = await play(zenoh_net, {"uav0": runaway, "uav1": holding}, 24, task)
    w = KinematicWorld()
    braking_m = w.max_speed**2 / (2 * w.max_accel)  # momentum carries it this far at most
    seen = ins["uav0"].seen
    assert result.rounds == 24
    assert runner.check.clamped["speed"] == 24
    assert runner.check.clamped["geofence"] >= 1
    assert max(math.hypot(*p.vel[:2]) for p in seen) <= w.max_speed + 1e-9
    assert max(abs(p.pos[0]) for p in seen) <= w.arena_half_m + braking_m
    assert seen[-1].pos[0] == pytest.approx(w.arena_half_m, abs=0.05)  # parked at the fence
