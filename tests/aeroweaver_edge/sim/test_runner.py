"""WorldRunner over real zenoh sessions, with hand-driven stand-in daemons.

Each stand-in is a real session that holds a liveliness token and answers the world's
perceptions by publishing SimCommands itself, so a test can play a silent, slow or
spoofing UAV exactly.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import pytest

from aeroweaver_edge.config import SafetyConfig, SimConfig
from aeroweaver_edge.contracts.wire import HeaderFactory, Keys, SimCommand, SimPerception, Vec3
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.sim.episode import EpisodeResult
from aeroweaver_edge.sim.runner import RoundLog, WorldRunner
from aeroweaver_edge.tasks import create
from aeroweaver_edge.tasks.base import TaskDefinition
from tests.helpers.zenoh_net import ZenohNet

SWARM = "rt"
KEYS = Keys(SWARM)
DEADLINE_S = 1.0  # generous: a loaded CI machine must not turn answers into misses

Policy = Callable[[SimPerception, HeaderFactory], list[tuple[str, SimCommand]]]
"""Given a perception, the (key, command) pairs the stand-in publishes in reply."""


@dataclass
class StandIn:
    uav: str
    mesh: Mesh
    seen: list[SimPerception] = field(default_factory=list)

    def pos(self, round_: int) -> Vec3:
        return next(p.pos for p in self.seen if p.round == round_)

    def vel(self, round_: int) -> Vec3:
        return next(p.vel for p in self.seen if p.round == round_)


def command(
    hf: HeaderFactory,
    p: SimPerception,
    *,
    uav: str | None = None,
    vel: Vec3 = (0.0, 0.0, 0.0),
    held: bool = False,
    guess: str | None = None,
) -> SimCommand:
    return SimCommand(
        h=hf.next(),
        uav=uav or p.uav,
        episode=p.episode,
        round=p.round,
        vel=vel,
        held=held,
        guess=guess,
    )


def silent(p: SimPerception, hf: HeaderFactory) -> list[tuple[str, SimCommand]]:
    return []


def holding(p: SimPerception, hf: HeaderFactory) -> list[tuple[str, SimCommand]]:
    return [(KEYS.sim_command(p.uav), command(hf, p, held=True))]


async def stand_in(net: ZenohNet, uav: str, policy: Policy) -> StandIn:
    mesh = await net.open(uav)
    hf = HeaderFactory(uav)
    me = StandIn(uav, mesh)

    def on_perception(item: tuple[str, SimPerception]) -> None:
        _key, p = item
        me.seen.append(p)
        for key, cmd in policy(p, hf):
            mesh.put(key, cmd, block=True)

    mesh.subscribe(KEYS.sim_perception(uav), SimPerception, on_item=on_perception)
    mesh.declare_token(KEYS.alive_uav(uav))
    return me


async def play(
    net: ZenohNet,
    policies: dict[str, Policy],
    rounds: int,
    task: TaskDefinition | None = None,
    safety: SafetyConfig | None = None,
) -> tuple[WorldRunner, EpisodeResult, list[RoundLog], dict[str, StandIn]]:
    world_mesh = await net.open("world")
    cfg = SimConfig(uavs=len(policies), max_rounds=rounds, deadline_s=DEADLINE_S)
    logs: list[RoundLog] = []

    async def on_round(log: RoundLog) -> None:
        logs.append(log)

    runner = WorldRunner(
        world_mesh,
        SWARM,
        task or create("coverage", len(policies), max_rounds=rounds),
        cfg,
        on_round=on_round,
        safety=safety,
    )
    await runner.start()
    try:
        stand_ins = {u: await stand_in(net, u, pol) for u, pol in policies.items()}
        assert await runner.wait_alive(list(policies), 5.0) == set()
        result = await runner.run_episode(0)
    finally:
        await runner.aclose()
    return runner, result, logs, stand_ins


async def test_spoofed_commands_are_rejected_and_counted(zenoh_net: ZenohNet) -> None:
    def spoofer(p: SimPerception, hf: HeaderFactory) -> list[tuple[str, SimCommand]]:
        push: Vec3 = (10.0, 0.0, 0.0)
        return [
            # on uav0's key, naming uav0, but the header says who really sent it
            (KEYS.sim_command("uav0"), command(hf, p, uav="uav0", vel=push)),
            # on its own key, but claiming to command uav0's body
            (KEYS.sim_command("uav1"), command(hf, p, uav="uav0", vel=push)),
            # on uav0's key, commanding itself
            (KEYS.sim_command("uav0"), command(hf, p, vel=push)),
            # and finally its own, legitimate hold
            (KEYS.sim_command("uav1"), command(hf, p, held=True)),
        ]

    runner, result, logs, ins = await play(zenoh_net, {"uav0": silent, "uav1": spoofer}, 2)

    assert result.rounds == 2
    assert runner.stats.rejected_commands == 3 * 2
    assert runner.stats.commands == 2  # uav1's own holds only
    for log in logs:
        assert set(log.commands) == {"uav1"}
        assert log.commands["uav1"].held
        assert log.missed == ("uav0",)  # a spoofed command does not stand in for uav0's
    # Neither body was pushed: both held in place.
    assert len(ins["uav0"].seen) == len(ins["uav1"].seen) == 2
    assert ins["uav0"].pos(1) == ins["uav0"].pos(0)
    assert ins["uav1"].pos(1) == ins["uav1"].pos(0)


async def test_silent_uav_holds_and_counts_as_a_deadline_miss(zenoh_net: ZenohNet) -> None:
    def once_then_silent(p: SimPerception, hf: HeaderFactory) -> list[tuple[str, SimCommand]]:
        if p.round > 0:
            return []
        return [(KEYS.sim_command(p.uav), command(hf, p, vel=(4.0, 0.0, 0.0)))]

    runner, result, logs, ins = await play(
        zenoh_net, {"uav0": once_then_silent, "uav1": holding}, 4
    )
    u0 = ins["uav0"]

    assert result.rounds == 4
    assert [log.missed for log in logs] == [(), ("uav0",), ("uav0",), ("uav0",)]
    assert runner.stats.deadline_misses == 3
    for log in logs[1:]:
        assert log.wait_s >= DEADLINE_S - 0.05  # the world waited out the deadline
        assert "uav1" in log.commands
    assert logs[0].wait_s < DEADLINE_S  # everyone answered: no waiting for the deadline

    # Round 0 moved it; the missed round 1 brought it to a stop; after that it stays put.
    assert u0.pos(1)[0] > u0.pos(0)[0]
    assert u0.vel(2) == pytest.approx((0.0, 0.0, 0.0))
    assert u0.pos(3) == u0.pos(2)
    assert ins["uav1"].pos(3) == ins["uav1"].pos(0)


async def test_commands_for_another_round_do_not_count(zenoh_net: ZenohNet) -> None:
    def late(p: SimPerception, hf: HeaderFactory) -> list[tuple[str, SimCommand]]:
        stale = SimCommand(
            h=hf.next(), uav=p.uav, episode=p.episode, round=p.round - 1, vel=(5.0, 0.0, 0.0)
        )
        return [(KEYS.sim_command(p.uav), stale)]

    runner, _result, logs, ins = await play(zenoh_net, {"uav0": late}, 2)
    assert [log.missed for log in logs] == [("uav0",), ("uav0",)]
    assert runner.stats.deadline_misses == 2
    assert ins["uav0"].pos(1) == ins["uav0"].pos(0)


async def test_private_facts_reach_only_their_role_and_guesses_are_scored(
    zenoh_net: ZenohNet,
) -> None:
    """Private communication over the real mesh: the sender's perception carries symbol and
    key, the receiver's only the key; the receiver's guess travels in its command and the
    world scores it (the scripted eavesdropper heard nothing: no ciphertext was sent)."""
    task = create("private_communication", 2, max_rounds=5)

    def receiver(p: SimPerception, hf: HeaderFactory) -> list[tuple[str, SimCommand]]:
        key = int(p.facts["key"])
        return [(KEYS.sim_command(p.uav), command(hf, p, held=True, guess=str(3 ^ key)))]

    _runner, result, _logs, ins = await play(
        zenoh_net, {"uav0": holding, "uav1": receiver}, 5, task=task
    )
    sender_facts = {tuple(sorted(p.facts)) for p in ins["uav0"].seen}
    receiver_facts = {tuple(sorted(p.facts)) for p in ins["uav1"].seen}
    assert sender_facts == {("key", "private_symbol")}
    assert receiver_facts == {("key",)}
    assert ins["uav0"].seen[0].facts["key"] == ins["uav1"].seen[0].facts["key"]
    symbol = int(ins["uav0"].seen[0].facts["private_symbol"])
    key = int(ins["uav1"].seen[0].facts["key"])
    assert (result.rounds, result.reason) == (3, "complete")  # ends after round 3
    right = 3 ^ key == symbol
    assert result.metrics["receiver_correct"] == float(right)
    assert result.metrics["eavesdropper_correct"] == 0.0
    # Bob right: 0 per round; wrong: -2 per round (3 rounds); Eve never spoke.
    assert result.returns["uav1"] == (0.0 if right else -6.0)
    assert result.returns["eavesdropper0"] == 0.0


async def test_every_applied_command_is_judged_against_the_configured_envelope(
    zenoh_net: ZenohNet,
) -> None:
    """A stand-in with no gate at all: the world counts what it is told to fly; a hold, a
    missed round and a command inside the envelope count nothing."""
    tight = SafetyConfig(max_speed_mps=5.0)

    def raw(p: SimPerception, hf: HeaderFactory) -> list[tuple[str, SimCommand]]:
        vel = {0: (0.0, -155.0, 0.0), 1: (0.0, 6.0, 0.0), 2: (0.0, 4.0, 0.0)}.get(p.round)
        if vel is None:
            return []  # round 3: silent (the world holds it)
        return [(KEYS.sim_command(p.uav), command(hf, p, vel=vel))]

    runner, _result, logs, _ins = await play(
        zenoh_net, {"uav0": raw, "uav1": holding}, 4, safety=tight
    )
    per_round = [sorted((v.uav, v.kind) for v in log.violations) for log in logs]
    assert per_round == [
        [("uav0", "geofence"), ("uav0", "speed")],  # 155 m/s west: 77 m on, out of the fence
        [("uav0", "speed")],  # 6 m/s against a 5 m/s envelope (the world's physics: 11)
        [],
        [],
    ]
    summary = runner.envelope.summary()
    assert summary["total"] == 3
    assert summary["by_uav"] == {"uav0": {"geofence": 1, "speed": 2}}
    assert (summary["checked"], summary["moving"]) == (8, 3)
    assert summary["envelope"]["max_speed_mps"] == 5.0
