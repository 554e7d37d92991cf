"""A daemon's simulator link believes only the world, and only about the current round.

Real zenoh sessions without signatures (an ``--insecure`` swarm, where these application
checks are all that stands in the way): a forger puts perceptions, rewards and a shutdown
on the UAV's keys under another name, for old or future rounds, or in a flood.
"""

from __future__ import annotations

import asyncio
import math

from aeroweaver_edge.contracts.wire import HeaderFactory, Keys, SimEpisode, SimPerception, SimReward
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.vehicle.sim import WORLD, SimLink
from tests.helpers.zenoh_net import ZenohNet, eventually

K = Keys("tr")


def perception(hf: HeaderFactory, rnd: int, *, uav: str = "uav0", x: float = 0.0) -> SimPerception:
    return SimPerception(
        h=hf.next(), uav=uav, episode=0, round=rnd, deadline_s=5.0,
        pos=(x, 0.0, -5.0), vel=(0.0, 0.0, 0.0),
    )  # fmt: skip


def reward(hf: HeaderFactory, rnd: int, value: float, *, uav: str = "uav0") -> SimReward:
    return SimReward(h=hf.next(), uav=uav, episode=0, round=rnd, reward=value)


async def linked(net: ZenohNet) -> tuple[SimLink, Mesh, Mesh]:
    """The UAV's link, the world's session and a forger's, all connected and matched."""
    world = await net.open("world")
    mesh = await net.open("uav0")
    forger = await net.open("uav1")
    link = SimLink(mesh, K, "uav0", HeaderFactory("uav0"))
    await link.start()
    hello = HeaderFactory(WORLD)
    # Until the link's subscriptions are known to both senders (a stale round is refused).
    for sender in (world, forger):
        ok = await eventually(
            lambda s=sender: _poke(s, hello) and link.rejected["perception_wrong_uav"] > 0, 5.0
        )
        assert ok
        link.rejected.clear()
    return link, world, forger


def _poke(mesh: Mesh, hf: HeaderFactory) -> bool:
    mesh.put(K.sim_perception("uav0"), perception(hf, -1, uav="nobody"))
    return True


def rewards_refused(link: SimLink) -> dict[str, int]:
    return {k: n for k, n in link.rejected.items() if k.startswith("reward")}


def test_the_world_identity_is_the_one_the_pki_issues() -> None:
    from aeroweaver_edge.security.identity import WORLD as PKI_WORLD

    assert WORLD == PKI_WORLD


async def test_perception_only_from_the_world_and_only_newer(zenoh_net: ZenohNet) -> None:
    link, world, forger = await linked(zenoh_net)
    try:
        fake, real = HeaderFactory("uav1"), HeaderFactory(WORLD)
        forger.put(K.sim_perception("uav0"), perception(fake, 0, x=287.0))  # not the world
        world.put(K.sim_perception("uav0"), perception(real, 0, x=1.0), block=True)
        tick = await asyncio.wait_for(link.next_round(), 5.0)
        assert tick is not None
        assert (await link.state()).pos[0] == 1.0
        await link.finish(tick, sent=[])
        world.put(K.sim_reward("uav0"), reward(real, 0, -1.0), block=True)
        world.put(K.sim_perception("uav0"), perception(real, 0, x=9.0), block=True)  # replay
        world.put(K.sim_perception("uav0"), perception(real, 1, x=2.0), block=True)
        tick = await asyncio.wait_for(link.next_round(), 5.0)
        assert tick is not None
        assert tick.round == 1
        assert (await link.state()).pos[0] == 2.0
        assert await eventually(lambda: link.rejected["perception_not_world"] == 1, 5.0)
        assert link.rejected["perception_stale"] == 1
    finally:
        await link.aclose()


async def test_a_perception_flood_keeps_only_the_newest(zenoh_net: ZenohNet) -> None:
    link, world, _forger = await linked(zenoh_net)
    try:
        real = HeaderFactory(WORLD)
        for rnd in range(1000):
            world.put(K.sim_perception("uav0"), perception(real, rnd, x=float(rnd)), block=True)
        world.put(K.sim_perception("uav0"), perception(real, 1000, x=math.nan), block=True)
        assert await eventually(lambda: link.rejected["perception_non_finite"] == 1, 10.0)
        tick = await asyncio.wait_for(link.next_round(), 5.0)
        assert tick is not None
        assert tick.round == 999  # the newest; nothing else was queued
        assert link.superseded == 999
        assert link._next is None
    finally:
        await link.aclose()


async def test_rewards_only_from_the_world_for_a_round_in_play(zenoh_net: ZenohNet) -> None:
    link, world, forger = await linked(zenoh_net)
    try:
        fake, real = HeaderFactory("uav1"), HeaderFactory(WORLD)
        world.put(K.sim_perception("uav0"), perception(real, 0), block=True)
        tick = await asyncio.wait_for(link.next_round(), 5.0)
        assert tick is not None
        await link.finish(tick, sent=[])
        forger.put(K.sim_reward("uav0"), reward(fake, 0, 1000.0))  # forged +1000
        forger.put(K.sim_reward("uav0"), reward(real, 5, 1000.0))  # "world", a future round
        forger.put(K.sim_reward("uav0"), reward(real, 0, math.inf))  # "world", not finite
        assert await eventually(lambda: len(rewards_refused(link)) == 3, 5.0)
        world.put(K.sim_reward("uav0"), reward(real, 0, -0.5), block=True)
        world.put(K.sim_reward("uav0"), reward(real, 0, 7.0), block=True)  # a second one
        assert await eventually(lambda: link.rejected["reward_duplicate"] == 1, 5.0)
        assert [(e.round, e.reward) for e in link.drain()] == [(0, -0.5)]
        assert rewards_refused(link) == {
            "reward_not_world": 1, "reward_not_current": 1, "reward_non_finite": 1,
            "reward_duplicate": 1,
        }  # fmt: skip
    finally:
        await link.aclose()


async def test_only_the_world_can_end_the_run(zenoh_net: ZenohNet) -> None:
    link, world, forger = await linked(zenoh_net)
    try:
        fake, real = HeaderFactory("uav1"), HeaderFactory(WORLD)
        forger.put(K.sim_episode, SimEpisode(h=fake.next(), episode=-1, task="t", phase="shutdown"))
        assert await eventually(lambda: link.rejected["episode_not_world"] == 1, 5.0)
        # The forged shutdown arrived first, yet the next round is the world's perception.
        world.put(K.sim_perception("uav0"), perception(real, 0), block=True)
        tick = await asyncio.wait_for(link.next_round(), 5.0)
        assert tick is not None
        assert tick.round == 0
        world.put(K.sim_episode, SimEpisode(h=real.next(), episode=-1, task="t", phase="shutdown"))
        assert await asyncio.wait_for(link.next_round(), 5.0) is None
    finally:
        await link.aclose()
