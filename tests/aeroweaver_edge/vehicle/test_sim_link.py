"""The sim backend (SimLink) over real zenoh sessions: a hand-driven world on one session,
the UAV's link on another. Perception is the round trigger and carries the private facts;
the command carries the velocity, the messages sent and the guess; rewards arrive before the
next round; a shutdown ends the clock."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from dataclasses import dataclass

import pytest

from aeroweaver_edge.contracts.ports import RewardEvent
from aeroweaver_edge.contracts.wire import (
    Entity,
    HeaderFactory,
    Keys,
    MsgRef,
    SimCommand,
    SimEpisode,
    SimPerception,
    SimReward,
)
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.vehicle.sim import SimLink
from tests.helpers.zenoh_net import ZenohNet, eventually

KEYS = Keys("vs")
L0 = Entity(id="L0", kind="landmark", pos=(1.0, 2.0, -5.0))


@dataclass
class World:
    mesh: Mesh
    headers: HeaderFactory
    commands: list[SimCommand]

    def perceive(self, rnd: int, uav: str = "uav0", **kw: object) -> None:
        self.mesh.put(
            KEYS.sim_perception(uav),
            SimPerception(
                h=self.headers.next(), uav=uav, episode=0, round=rnd, deadline_s=5.0,
                pos=(float(rnd), 0.0, -5.0), vel=(0.0, 0.0, 0.0), **kw,  # type: ignore[arg-type]
            ),
            block=True,
        )  # fmt: skip

    def reward(self, rnd: int, value: float, done: bool = False) -> None:
        self.mesh.put(
            KEYS.sim_reward("uav0"),
            SimReward(h=self.headers.next(), uav="uav0", episode=0, round=rnd, reward=value,
                      done=done),
            block=True,
        )  # fmt: skip


@pytest.fixture
async def pair(zenoh_net: ZenohNet) -> AsyncIterator[tuple[World, SimLink]]:
    world_mesh = await zenoh_net.open("world")
    commands: list[SimCommand] = []
    world_mesh.subscribe(
        KEYS.sim_command("*"), SimCommand, on_item=lambda item: commands.append(item[1])
    )
    uav_mesh = await zenoh_net.open("uav0")
    link = SimLink(uav_mesh, KEYS, "uav0", HeaderFactory("uav0"), reward_wait_s=2.0)
    await link.start()
    await asyncio.sleep(0.2)  # let both subscriptions propagate
    try:
        yield World(world_mesh, HeaderFactory("world"), commands), link
    finally:
        await link.aclose()


async def test_perception_triggers_a_round_with_facts_and_expectations(
    pair: tuple[World, SimLink],
) -> None:
    world, link = pair
    ref = MsgRef(sender="uav1", seq=7, to="*")
    world.perceive(0, "uav9")  # another UAV's perception never triggers this one
    world.perceive(0, entities=[L0], expected_inbox=[ref], facts={"key": "2"})
    tick = await asyncio.wait_for(link.next_round(), 3.0)
    assert tick is not None
    assert (tick.episode, tick.round, tick.deadline_s, tick.expect) == (0, 0, 5.0, (ref,))
    percept = await link.sense(tick)
    assert percept.own.pos == (0.0, 0.0, -5.0)
    assert list(percept.entities) == [L0]
    assert dict(percept.facts) == {"key": "2"}
    assert (await link.state()).pos == (0.0, 0.0, -5.0)


async def test_the_command_carries_velocity_messages_and_guess(
    pair: tuple[World, SimLink],
) -> None:
    world, link = pair
    world.perceive(0)
    tick = await asyncio.wait_for(link.next_round(), 3.0)
    assert tick is not None
    sent = [MsgRef(sender="uav0", seq=3, to="*")]
    await link.arm()  # the simulated airframe flies only once it took off (flight phases)
    await link.takeoff(5.0)
    await link.set_velocity(3.0, -4.0, 0.0)
    await link.finish(tick, sent=sent, guess="2")
    assert await eventually(lambda: len(world.commands) == 1)
    [cmd] = world.commands
    assert (cmd.uav, cmd.round, cmd.vel, cmd.held, cmd.sent, cmd.guess) == (
        "uav0", 0, (3.0, -4.0, 0.0), False, sent, "2",
    )  # fmt: skip
    assert cmd.h.sender == "uav0"

    world.reward(0, -1.5)
    world.perceive(1)
    tick = await asyncio.wait_for(link.next_round(), 3.0)  # a new round starts held
    assert tick is not None
    await link.finish(tick, sent=[])
    assert await eventually(lambda: len(world.commands) == 2)
    assert (world.commands[1].held, world.commands[1].vel, world.commands[1].guess) == (
        True, (0.0, 0.0, 0.0), None,
    )  # fmt: skip


async def test_the_reward_of_a_round_arrives_before_the_next_round(
    pair: tuple[World, SimLink],
) -> None:
    world, link = pair
    world.perceive(0)
    tick = await asyncio.wait_for(link.next_round(), 3.0)
    assert tick is not None
    await link.finish(tick, sent=[])
    nxt = asyncio.create_task(link.next_round())
    await asyncio.sleep(0)  # it waits for a perception now
    world.perceive(1)  # the next perception overtakes the reward...
    # Taken by the waiting round (nothing pending any more), which now waits for round 0's
    # reward. (No second perception here: a newer one would supersede round 1's if it came
    # before the round took it.)
    assert await eventually(lambda: link._taken == (0, 1) and link._next is None)
    await asyncio.sleep(0)
    assert not nxt.done()  # ...but the round waits for round 0's reward
    world.reward(0, 2.5, done=False)
    tick = await asyncio.wait_for(nxt, 3.0)
    assert tick is not None
    assert tick.round == 1
    [event] = link.drain()
    assert (event.episode, event.round, event.reward, event.done, event.source) == (
        0, 0, 2.5, False, "sim",
    )  # fmt: skip
    world.reward(0, 2.5)  # a duplicate is ignored...
    world.reward(1, -1.0)  # ...as the next reward, sent after it on the same key, shows
    got: list[RewardEvent] = []

    def drained() -> bool:
        got.extend(link.drain())
        return got != []

    assert await eventually(drained)
    assert [(e.round, e.reward) for e in got] == [(1, -1.0)]


async def test_shutdown_ends_the_clock(pair: tuple[World, SimLink]) -> None:
    world, link = pair
    world.mesh.put(
        KEYS.sim_episode,
        SimEpisode(h=world.headers.next(), episode=-1, task="coverage", phase="shutdown"),
        block=True,
    )
    assert await asyncio.wait_for(link.next_round(), 3.0) is None
    with pytest.raises(RuntimeError, match="no perception"):
        await link.state()


async def test_settle_waits_for_the_reward_up_to_the_round_deadline(
    zenoh_net: ZenohNet,
) -> None:
    """A UAV that decided early waits in settle until the world rewards the round (after
    the slowest UAV), not only reward_wait_s: the episode's last reward must be absorbed
    before the barrier between episodes, or the barrier waits its whole bound."""
    world_mesh = await zenoh_net.open("world")
    uav_mesh = await zenoh_net.open("uav0")
    link = SimLink(uav_mesh, KEYS, "uav0", HeaderFactory("uav0"), reward_wait_s=0.05)
    await link.start()
    try:
        await asyncio.sleep(0.2)  # let both subscriptions propagate
        world = World(world_mesh, HeaderFactory("world"), [])
        world.perceive(0)  # deadline_s 5.0
        tick = await asyncio.wait_for(link.next_round(), 3.0)
        assert tick is not None
        await link.finish(tick, sent=[])
        settling = asyncio.create_task(link.settle(tick))
        await asyncio.sleep(0.3)  # six times reward_wait_s, far inside the 5 s deadline
        assert not settling.done()
        world.reward(0, -1.25, done=True)
        await asyncio.wait_for(settling, 3.0)
        [event] = link.drain()
        assert (event.round, event.reward, event.done) == (0, -1.25, True)
    finally:
        await link.aclose()


async def test_settle_stops_at_a_later_perception_when_the_reward_was_lost(
    zenoh_net: ZenohNet,
) -> None:
    """A UAV cut off by a partition never gets the reward the world sent across it. Once
    healed, the world's next perception ends the settle at once (before: the whole deadline
    + reward_wait_s bound, 7 s here, so the UAV missed the first round it was sent); the
    round then takes that perception without the lost reward."""
    world_mesh = await zenoh_net.open("world")
    uav_mesh = await zenoh_net.open("uav0")
    link = SimLink(uav_mesh, KEYS, "uav0", HeaderFactory("uav0"), reward_wait_s=2.0)
    await link.start()
    try:
        await asyncio.sleep(0.2)  # let both subscriptions propagate
        world = World(world_mesh, HeaderFactory("world"), [])
        world.perceive(0)  # deadline_s 5.0
        tick = await asyncio.wait_for(link.next_round(), 3.0)
        assert tick is not None
        await link.finish(tick, sent=[])
        settling = asyncio.create_task(link.settle(tick))
        await asyncio.sleep(0)
        assert not settling.done()  # waiting for round 0's reward...
        world.perceive(4)  # ...which was lost: the world is at round 4 now
        await asyncio.wait_for(settling, 1.5)  # well inside the 7 s bound
        tick = await asyncio.wait_for(link.next_round(), 3.0)  # <= reward_wait_s for it
        assert tick is not None
        assert tick.round == 4
        assert link.drain() == []
    finally:
        await link.aclose()


async def test_a_new_world_starts_afresh_and_an_older_one_is_refused(
    pair: tuple[World, SimLink],
) -> None:
    """A service daemon flies world after world: a perception with a newer header epoch is
    a new world (its rounds start at 0 again, nothing of the old one is kept); a late one
    of the older world is refused; ``next_world`` forgets the world after its shutdown."""
    world, link = pair
    assert link.waiting_for() == "waiting for a simulated world (sim backend)"
    world.perceive(1)  # one perception only: two could be read one at a time (a race)
    tick = await asyncio.wait_for(link.next_round(), 5)
    assert tick is not None
    assert (tick.episode, tick.round) == (0, 1)
    assert link.waiting_for() is None
    await link.finish(tick, sent=[])
    old = world.headers
    world.headers = HeaderFactory("world", epoch=old.epoch + 1)  # the next world's session
    world.perceive(0)
    tick = await asyncio.wait_for(link.next_round(), 5)  # no reward wait for the old round
    assert tick is not None
    assert (tick.episode, tick.round) == (0, 0)
    assert link.worlds == 2
    world.headers = old
    world.perceive(5)  # the first world, late
    assert await eventually(lambda: link.rejected["perception_old_world"] == 1)
    world.headers = HeaderFactory("world", epoch=old.epoch + 1)
    world.headers._seq = 100
    world.mesh.put(
        KEYS.sim_episode,
        SimEpisode(h=world.headers.next(), episode=-1, task="coverage", phase="shutdown"),
        block=True,
    )
    assert await asyncio.wait_for(link.next_round(), 5) is None
    assert link.world_over
    link.next_world()
    link.end_world()  # nothing flies it: a no-op
    assert link.waiting_for() is not None
    world.perceive(0)  # the same epoch again is fine after next_world: a fresh start
    tick = await asyncio.wait_for(link.next_round(), 5)
    assert tick is not None
    assert (tick.episode, tick.round) == (0, 0)
