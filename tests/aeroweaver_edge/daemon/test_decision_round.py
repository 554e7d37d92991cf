"""One decision round without Zenoh: the in-memory peer channel, an in-process body in a
real kinematic world and task, the real skill registry and the scripted reference selector
(which records the requests it scored, so a test sees exactly what the UAV observed)."""

from __future__ import annotations

import asyncio
import math
import time
from dataclasses import dataclass, field

import numpy as np
import pytest

from aeroweaver_edge.agent.prompt import build_messages
from aeroweaver_edge.agent.scripted import ReferenceScorer
from aeroweaver_edge.config import AgentConfig, SafetyConfig
from aeroweaver_edge.contracts.observation import MissionView
from aeroweaver_edge.contracts.ports import DecisionRequest, RoundTick
from aeroweaver_edge.contracts.scores import LabelScores
from aeroweaver_edge.contracts.wire import MsgRef
from aeroweaver_edge.daemon.decision_round import RoundContext, RoundOutcome, run_round
from aeroweaver_edge.daemon.uav_daemon import routing
from aeroweaver_edge.mesh.peer_memory import MemoryPeerHub
from aeroweaver_edge.safety.gate import SafetyGate
from aeroweaver_edge.skills import SkillRegistry, load_skills
from aeroweaver_edge.tasks import create
from aeroweaver_edge.tasks.base import TaskDefinition
from aeroweaver_edge.vehicle.local import LocalBody
from aeroweaver_edge.world.kinematics import KinematicWorld

COVER = ("cover_landmark", "explore_local", "return_in_bounds", "hold_position")
CRYPTO = {
    "sender": ("encode_message", "hold_position"),
    "receiver": ("decode_message", "hold_position"),
}


@pytest.fixture(scope="module")
def registry() -> SkillRegistry:
    return load_skills()


class Recording(ReferenceScorer):
    def __init__(self) -> None:
        super().__init__()
        self.requests: list[DecisionRequest] = []

    async def score(self, request: DecisionRequest) -> LabelScores:
        self.requests.append(request)
        return await super().score(request)


class Erroring(ReferenceScorer):
    async def score(self, request: DecisionRequest) -> LabelScores:
        return LabelScores(logprobs={}, error="endpoint down")


class Stalling(ReferenceScorer):
    """Never answers: the round's deadline must hold the UAV."""

    async def score(self, request: DecisionRequest) -> LabelScores:
        await asyncio.Event().wait()
        raise AssertionError("unreachable")


@dataclass
class Rig:
    task: TaskDefinition
    world: KinematicWorld
    hub: MemoryPeerHub
    contexts: dict[str, RoundContext]
    views: dict[str, MissionView | None]
    scorers: dict[str, Recording] = field(default_factory=dict)

    async def play(
        self, rnd: int, expect: dict[str, list[MsgRef]] | None = None, deadline_s: float = 5.0
    ) -> dict[str, RoundOutcome]:
        """Every UAV decides on the frozen state, then the world advances one round."""
        outs = {}
        for uav, rc in self.contexts.items():
            tick = RoundTick(0, rnd, deadline_s, tuple((expect or {}).get(uav, ())))
            outs[uav] = await run_round(rc, tick, self.views[uav])
        self.world.step()
        return outs

    def manifest(self, outs: dict[str, RoundOutcome]) -> dict[str, list[MsgRef]]:
        """Who each message reaches (as the world computes it for ``expected_inbox``)."""
        expect: dict[str, list[MsgRef]] = {}
        for sender, out in outs.items():
            for ref in out.sent:
                for to in self.task.uav_ids:
                    if to != sender and self.task.reaches(sender, to, self.world):
                        expect.setdefault(to, []).append(ref)
        return expect


def rig(
    registry: SkillRegistry,
    name: str,
    n: int,
    skills: dict[str, tuple[str, ...]] | tuple[str, ...],
    *,
    seed: int = 1,
    max_labels: int = 26,
) -> Rig:
    task = create(name, n)
    world = task.build_world(np.random.default_rng(seed))
    hub = MemoryPeerHub()
    r = Rig(task, world, hub, {}, {})
    for i, uav in enumerate(task.uav_ids):
        role = task.role_of(uav)
        link = hub.channel(uav)
        link.set_routing(role, routing(name, 55.0))
        body = LocalBody(world, uav, task)
        scorer = r.scorers[uav] = Recording()
        r.contexts[uav] = RoundContext(
            uav=uav,
            uav_index=i,
            registry=registry,
            selector=scorer,
            gate=SafetyGate(SafetyConfig(), horizon_s=0.5),
            vehicle=body,
            perception=body,
            link=link,
            agent=AgentConfig(selector="scripted", beta=0.0, max_labels=max_labels),
        )
        active = skills[role] if isinstance(skills, dict) else skills
        r.views[uav] = MissionView("m", name, "test mission", role, "goal", active)
    return r


async def test_a_round_selects_gates_acts_and_talks(registry: SkillRegistry) -> None:
    r = rig(registry, "coverage", 3, COVER)
    before = {u: r.world.body(u).pos for u in r.task.uav_ids}
    outs = await r.play(0)
    for u, out in outs.items():
        assert out.chosen_by_agent, out.reason
        assert out.skill in COVER
        assert out.n_candidates >= 3  # explore_local, return_in_bounds, hold_position at least
        assert math.hypot(*out.vel) <= 11.0 + 1e-9  # the safety gate's speed cap
        moved = r.world.body(u).pos != before[u]
        assert moved == (not out.held)  # the own body acted on, and only it
    movers = [u for u, o in outs.items() if o.skill != "hold_position"]
    assert movers
    for u in movers:  # one broadcast per move, never a put per peer
        [ref] = outs[u].sent
        assert (ref.sender, ref.to) == (u, "*")
    expect = r.manifest(outs)
    await r.play(1, expect)
    for u in r.task.uav_ids:
        seen = {(m.h.sender, m.h.seq) for m in r.scorers[u].requests[-1].observation.messages}
        assert seen == {(ref.sender, ref.seq) for ref in expect.get(u, [])}
        assert r.hub.channels[u].stats.missing == 0
        assert r.scorers[u].requests[-1].task == "coverage"


async def test_a_rounds_latency_is_the_time_it_took(registry: SkillRegistry) -> None:
    """Bounded by the caller's own clock (no speed asserted): a chosen skill and a hold."""
    r = rig(registry, "coverage", 1, COVER)
    for view in (r.views["uav0"], None):
        r.views["uav0"] = view
        started = time.monotonic()
        out = (await r.play(0))["uav0"]
        took = time.monotonic() - started
        assert out.chosen_by_agent == (view is not None)
        assert 0.0 < out.latency_s <= took


async def test_messages_from_out_of_range_are_dropped_at_the_receiver(
    registry: SkillRegistry,
) -> None:
    r = rig(registry, "coverage", 2, COVER)
    far = r.world.body("uav1")
    far.north, far.east = 60.0, 60.0  # > 55 m from uav0's spawn
    outs = await r.play(0)
    assert r.manifest(outs) == {}
    await r.play(1)
    assert r.scorers["uav1"].requests[-1].observation.messages == ()
    assert r.hub.channels["uav1"].stats.rejected["out_of_range"] >= 1


async def test_without_an_assignment_the_uav_holds(registry: SkillRegistry) -> None:
    r = rig(registry, "coverage", 1, COVER)
    r.views["uav0"] = None
    out = (await r.play(0))["uav0"]
    assert (out.held, out.reason, out.chosen_by_agent) == (True, "no mission assignment yet", False)
    assert r.world.body("uav0").setpoint == (0.0, 0.0, 0.0)


async def test_more_options_than_labels_holds(registry: SkillRegistry) -> None:
    r = rig(registry, "coverage", 1, COVER, max_labels=2)
    b = r.world.body("uav0")
    b.north, b.east = 0.0, 25.0  # all three landmarks in view: 3 + explore + return + hold
    out = (await r.play(0))["uav0"]
    assert out.held
    assert out.reason.endswith("options beyond the label budget")


async def test_no_callable_skill_holds_without_asking_the_selector(
    registry: SkillRegistry,
) -> None:
    """An active subset of skills this UAV does not have: a hold with its own cause."""
    r = rig(registry, "coverage", 1, ("no_such_skill",))
    out = (await r.play(0))["uav0"]
    assert (out.held, out.reason, out.hold_cause) == (
        True,
        "no callable skill in the active subset",
        "no_candidates",
    )
    assert (out.chosen_by_agent, out.n_candidates) == (False, 0)
    assert r.scorers["uav0"].requests == []


async def test_a_selector_error_holds_this_uav_only(registry: SkillRegistry) -> None:
    r = rig(registry, "coverage", 2, COVER)
    r.contexts["uav0"].selector = Erroring()
    outs = await r.play(0)
    assert outs["uav0"].held
    assert outs["uav0"].reason == "selector error: endpoint down"
    assert outs["uav1"].chosen_by_agent


async def test_a_missed_deadline_holds(registry: SkillRegistry) -> None:
    r = rig(registry, "coverage", 1, COVER)
    r.contexts["uav0"].selector = Stalling()
    r.world.set_velocity("uav0", (5.0, 0.0))
    out = (await r.play(0, deadline_s=0.3))["uav0"]
    assert (out.held, out.reason) == (True, "deadline")
    assert r.world.body("uav0").setpoint == (0.0, 0.0, 0.0)


async def test_a_decoded_guess_leaves_the_round_and_the_eavesdropper_is_not_a_peer(
    registry: SkillRegistry,
) -> None:
    """Private communication: the sender's ciphertext reaches the receiver regardless of
    range; the receiver's decode becomes the round's guess (what its command carries)."""
    r = rig(registry, "private_communication", 2, CRYPTO)
    sender, receiver = r.task.uav_ids
    far = r.world.body(receiver)
    far.north, far.east = 65.0, 65.0  # far beyond 55 m: routed anyway
    out0 = await r.play(0)
    assert out0[sender].skill == "encode_message"
    assert out0[receiver].skill == "hold_position"  # nothing to decode yet
    expect = r.manifest(out0)
    assert [ref.sender for ref in expect[receiver]] == [sender]
    out1 = await r.play(1, expect)
    symbol = r.task.private_facts(r.world, sender)["private_symbol"]
    assert out1[receiver].skill == "decode_message"
    assert out1[receiver].guess == symbol
    assert out1[sender].guess is None
    facts = r.scorers[receiver].requests[-1].observation.facts
    assert set(facts) == {"key"}  # never the sender's symbol


# ------------------------------------------------------------------ what reaches the vehicle


class Spy(LocalBody):
    """The in-process body, recording which Vehicle calls the round made."""

    def __init__(self, *args: object, **kw: object) -> None:
        super().__init__(*args, **kw)  # type: ignore[arg-type]
        self.calls: list[str] = []

    async def hold(self) -> None:
        self.calls.append("hold")
        await super().hold()

    async def set_velocity(self, north: float, east: float, down: float) -> None:
        self.calls.append("set_velocity")
        await super().set_velocity(north, east, down)


class Slow(ReferenceScorer):
    def __init__(self, delay_s: float) -> None:
        super().__init__()
        self.delay_s = delay_s

    async def score(self, request: DecisionRequest) -> LabelScores:
        await asyncio.sleep(self.delay_s)
        return await super().score(request)


def spied(r: Rig, uav: str = "uav0") -> Spy:
    spy = Spy(r.world, uav, r.task)
    r.contexts[uav].vehicle = spy
    r.world.set_velocity(uav, (5.0, 0.0))  # a motion a hold must end
    return spy


@pytest.mark.parametrize("why", ["chosen", "unassigned", "selector error"])
async def test_every_hold_reaches_the_vehicle_as_a_hold(registry: SkillRegistry, why: str) -> None:
    """A hold is the vehicle's hold (an autopilot's Hold mode), never a zero velocity."""
    r = rig(registry, "coverage", 1, ("hold_position",) if why == "chosen" else COVER)
    spy = spied(r)
    if why == "unassigned":
        r.views["uav0"] = None
    if why == "selector error":
        r.contexts["uav0"].selector = Erroring()
    out = (await r.play(0))["uav0"]
    assert out.held
    assert spy.calls == ["hold"]
    assert r.world.body("uav0").setpoint == (0.0, 0.0, 0.0)
    assert (out.dropped, out.sent) == (0, ())


async def test_a_move_is_one_velocity_setpoint_and_the_round_accounts_for_itself(
    registry: SkillRegistry,
) -> None:
    r = rig(registry, "coverage", 1, ("explore_local", "hold_position"))
    spy = spied(r)
    out = (await r.play(0))["uav0"]
    assert (out.skill, out.held, spy.calls) == ("explore_local", False, ["set_velocity"])
    assert out.dropped == 0
    assert 0.0 <= out.cpu_s <= out.latency_s + 0.05  # this thread's CPU time within the round


async def test_the_deadline_keeps_a_margin_for_the_command_to_travel(
    registry: SkillRegistry,
) -> None:
    """Budget = deadline - 0.25 s (at least 0.05 s): a 0.2 s decision fits a 1 s deadline,
    and does not fit a 0.2 s one."""
    r = rig(registry, "coverage", 1, COVER)
    r.contexts["uav0"].selector = Slow(0.2)
    assert (await r.play(0, deadline_s=1.0))["uav0"].chosen_by_agent
    late = (await r.play(1, deadline_s=0.2))["uav0"]
    assert (late.held, late.reason, late.hold_cause) == (True, "deadline", "deadline")


class NoMemory:
    """Experience memory that must not be asked: beta = 0 means no correction."""

    async def advantages(self, *args: object) -> dict[str, float]:
        raise AssertionError("advantages asked for with beta = 0")


async def test_experience_is_asked_only_when_it_can_change_the_pick(
    registry: SkillRegistry,
) -> None:
    r = rig(registry, "coverage", 1, COVER)
    r.contexts["uav0"].memory = NoMemory()  # type: ignore[assignment]
    assert (await r.play(0))["uav0"].chosen_by_agent  # beta = 0: never asked
    rc = r.contexts["uav0"]
    r.contexts["uav0"] = RoundContext(**{**rc.__dict__, "memory": None, "agent": AgentConfig(
        selector="scripted", beta=0.8)})  # fmt: skip
    out = (await r.play(1))["uav0"]  # beta > 0 without a memory: no correction, no error
    assert out.chosen_by_agent
    assert not out.corrected


@pytest.mark.parametrize("far", [1.7e308, -1.7e308, 1e12, 2**62])
async def test_an_absurd_position_in_a_peer_message_is_data_not_a_crash(
    registry: SkillRegistry, far: float
) -> None:
    """A peer's ``north``/``east`` is summarised as distance and bearing from the reader; a
    finite but absurd one (the distance overflows to inf) once ended the receiver's daemon."""
    r = rig(registry, "coverage", 2, COVER)
    await r.play(0)
    body: dict[str, str | int | float | bool] = {
        "skill": "cover_landmark", "target_id": "L0", "north": far, "east": far
    }  # fmt: skip
    ref = await r.contexts["uav1"].link.send("*", "intent", body, round=1)
    assert ref is not None
    await r.play(1)
    outs = await r.play(2, expect={"uav0": [ref]})
    request = r.scorers["uav0"].requests[-1]
    assert body in [m.body for m in request.observation.messages]
    assert outs["uav0"].chosen_by_agent  # the round went through selection as usual
    assert "huge" in outs["uav0"].state_text
    user = build_messages(request)[-1]["content"]
    line = next(ln for ln in user.splitlines() if ln.startswith("uav1 intent"))
    assert " m " not in line  # not a place ...
    assert len(line) < 120  # ... and no 300-digit number
