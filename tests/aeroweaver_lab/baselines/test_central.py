"""The central node on real loopback Zenoh with the fake LLM over HTTP: it gathers a
round's asks from the participants, makes one call, answers each UAV on its own key, holds
only the UAV whose letter is invalid, refuses asks a UAV sends for another, and does not
wait for a silent UAV beyond its gathering time."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from dataclasses import dataclass

import pytest

from aeroweaver_edge.contracts.wire import (
    Assignment,
    CentralAnswer,
    CentralAsk,
    HeaderFactory,
    Keys,
    MissionContext,
)
from aeroweaver_edge.llm.client import ChatClient
from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
from aeroweaver_edge.mesh.session import Mesh, Subscription
from aeroweaver_lab.baselines.central import CentralNode, CentralRound
from aeroweaver_lab.baselines.centralized import CentralizedPolicy
from aeroweaver_lab.baselines.wiring import skill_doc_renderer
from tests.helpers.zenoh_net import ZenohNet, eventually

SWARM = "t"
KEYS = Keys(SWARM)
OPTIONS = {
    "uav0": ["A. cover_landmark(target_id=L0)", "B. hold_position()"],
    "uav1": ["A. explore_local()", "B. hold_position()"],
}


@dataclass
class Uav:
    name: str
    mesh: Mesh
    headers: HeaderFactory
    answers: Subscription[CentralAnswer]

    def ask(self, rnd: int, *, claim: str | None = None) -> None:
        self.mesh.put(
            KEYS.ask(self.name),
            CentralAsk(
                h=self.headers.next(),
                uav=claim or self.name,
                episode=0,
                round=rnd,
                role="searcher",
                observation=f"{self.name} sees L0",
                options=OPTIONS[self.name],
            ),
            block=True,
        )

    async def answer(self, timeout_s: float = 10.0) -> CentralAnswer:
        async with asyncio.timeout(timeout_s):
            _key, ans = await self.answers.get()
        return ans


@dataclass
class World:
    node: CentralNode
    fake: FakeProvider
    uavs: dict[str, Uav]
    rounds: list[CentralRound]


@pytest.fixture
async def world(zenoh_net: ZenohNet, request: pytest.FixtureRequest) -> AsyncIterator[World]:
    policy_knobs = getattr(request, "param", {})
    async with FakeProvider(Policy(**policy_knobs)) as fake:
        cmdr = await zenoh_net.open("cmdr")
        central_mesh = await zenoh_net.open("central")
        rounds: list[CentralRound] = []
        node = CentralNode(
            central_mesh,
            SWARM,
            CentralizedPolicy(ChatClient(fake.base_url, "fake-model")),
            skill_doc_renderer(),
            gather_s=0.5,
            on_round=rounds.append,
        )
        await node.start()
        uavs = {}
        for name in ("uav0", "uav1"):
            mesh = await zenoh_net.open(name)
            answers = mesh.subscribe(KEYS.central_answer(name), CentralAnswer)
            mesh.declare_token(KEYS.alive_uav(name))
            uavs[name] = Uav(name, mesh, HeaderFactory(name), answers)
        ch = HeaderFactory("cmdr")
        await asyncio.sleep(0.3)  # subscriptions propagate
        cmdr.put(
            KEYS.context,
            MissionContext(
                h=ch.next(),
                mission_id="m",
                task="coverage",
                text="Cover the landmarks.",
                participants=["uav0", "uav1"],
            ),
            block=True,
        )
        for name in uavs:
            cmdr.put(
                KEYS.assign(name),
                Assignment(
                    h=ch.next(),
                    mission_id="m",
                    uav=name,
                    role="searcher",
                    local_goal="g",
                    skills=["cover_landmark", "hold_position"],
                ),
                block=True,
            )
        assert await eventually(lambda: node.participants == ["uav0", "uav1"], 5.0)
        assert await eventually(lambda: node._alive >= {"uav0", "uav1"}, 5.0)
        try:
            yield World(node, fake, uavs, rounds)
        finally:
            await node.aclose()


async def test_one_call_per_round_answers_every_uav(world: World) -> None:
    for u in world.uavs.values():
        u.ask(0)
    answers = {n: await u.answer() for n, u in world.uavs.items()}
    assert all(a.phase == "final" and a.round == 0 and a.error is None for a in answers.values())
    assert answers["uav0"].label in ("A", "B")
    assert answers["uav1"].label in ("A", "B")
    assert world.fake.chat_calls == 1
    prompt = world.fake.chat_bodies()[0]["messages"]
    assert "cover_landmark:" in prompt[0]["content"]  # the catalogue from the assignments
    assert "uav0 sees L0" in prompt[1]["content"]
    assert "uav1 sees L0" in prompt[1]["content"]
    (rec,) = world.rounds
    assert rec.asked == ["uav0", "uav1"]
    assert rec.missing == []
    assert rec.final == {"uav0": answers["uav0"].label, "uav1": answers["uav1"].label}
    totals = world.node.totals()
    assert totals["llm_calls"] == 1
    assert totals["rounds"] == 1
    assert totals["tokens"]["total"] == rec.calls[0].prompt + rec.calls[0].completion > 0


@pytest.mark.parametrize("world", [{"json_answers": "foreign_label"}], indirect=True)
async def test_an_invalid_letter_holds_that_uav_without_an_llm_failure(world: World) -> None:
    for u in world.uavs.values():
        u.ask(4)
    answers = [await u.answer() for u in world.uavs.values()]
    assert [(a.label, a.error) for a in answers] == [(None, None), (None, None)]
    assert world.node.totals()["invalid"] == 2


@pytest.mark.parametrize("world", [{"status": 503}], indirect=True)
async def test_a_failed_call_is_an_error_for_every_uav_of_the_round(world: World) -> None:
    for u in world.uavs.values():
        u.ask(1)
    answers = [await u.answer() for u in world.uavs.values()]
    assert all(a.label is None and a.error and "503" in a.error for a in answers)


async def test_a_uav_cannot_ask_for_another_and_a_silent_one_is_not_awaited(
    world: World,
) -> None:
    world.uavs["uav1"].ask(2, claim="uav0")  # on uav1's key, claiming to be uav0
    assert await eventually(lambda: world.node.rejected == 1, 5.0)
    world.uavs["uav0"].ask(2)
    ans = await world.uavs["uav0"].answer()
    assert ans.round == 2
    assert ans.label is not None
    (rec,) = world.rounds
    assert rec.asked == ["uav0"]
    assert rec.missing == ["uav1"]
    assert rec.gather_s >= 0.45  # it waited for uav1, bounded by gather_s
    assert world.uavs["uav1"].answers.drain() == []  # nothing for the silent UAV
