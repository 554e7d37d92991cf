"""The Commander publishes context and assignments (retained via queryables), and it never
writes anywhere but its own ``cmdr`` keys: it has no flight authority (DESIGN §3, §7)."""

from __future__ import annotations

import asyncio
import threading
from dataclasses import replace
from typing import Any, TypeVar, cast

import msgspec
import zenoh

from aeroweaver_edge.contracts.wire import (
    Assignment,
    Header,
    HeaderFactory,
    Keys,
    MissionContext,
    Payload,
    ProgressReport,
)
from aeroweaver_edge.daemon.mission_state import MissionState
from aeroweaver_edge.mesh.session import Mesh
from commander.commander import Commander
from commander.harness import plan_for_task
from commander.plan import MissionPlan
from tests.helpers.zenoh_net import ZenohNet, eventually

SWARM = "cmdtest"
KEYS = Keys(SWARM)
UAVS = ["uav0", "uav1"]
PLAN = plan_for_task("coverage", UAVS, mission_id="m1")
COVERAGE_SKILLS = PLAN.assignments[UAVS[0]].skills
T = TypeVar("T", bound=msgspec.Struct)


class KeySpy:
    """Every sample put anywhere in the namespace, raw, from a passive session."""

    def __init__(self, mesh: Mesh) -> None:
        self.samples: list[tuple[str, bytes]] = []
        self._lock = threading.Lock()
        self.tokens: set[str] = set()

        def on_sample(sample: zenoh.Sample) -> None:
            with self._lock:
                self.samples.append((str(sample.key_expr), sample.payload.to_bytes()))

        mesh.session.declare_subscriber("**", zenoh.handlers.Callback(on_sample, indirect=False))
        mesh.watch_liveliness("**", on_item=lambda ev: self.tokens.add(ev[0]) if ev[1] else None)

    def decoded(self) -> list[tuple[str, Header]]:
        with self._lock:
            raw = list(self.samples)
        return [(key, msgspec.msgpack.decode(data, type=Payload).h) for key, data in raw]


async def routed(mesh: Mesh, key: str, timeout_s: float = 3.0) -> bool:
    """True once ``mesh`` knows a subscriber matching ``key``, so a put there is not lost
    to the join race of a session that has just opened."""
    pub = mesh.session.declare_publisher(key)
    try:
        # The stub says bool; zenoh 1.10 returns a MatchingStatus with ``.matching``.
        return await eventually(lambda: bool(cast(Any, pub.matching_status).matching), timeout_s)
    finally:
        await asyncio.to_thread(pub.undeclare)


async def start_commander(net: ZenohNet) -> Commander:
    cmdr = Commander(await net.open("cmdr"), SWARM)
    await cmdr.start()
    return cmdr


async def get_until(mesh: Mesh, selector: str, kind: type[T], want: int) -> list[tuple[str, T]]:
    """Query until ``want`` replies come back (routes to a new peer take a moment)."""
    replies: list[tuple[str, T]] = []

    async def probe() -> bool:
        nonlocal replies
        replies = await mesh.get(selector, kind, timeout_s=0.5)
        return len(replies) >= want

    for _ in range(10):
        if await probe():
            break
    return replies


async def test_context_and_assignments_are_published(zenoh_net: ZenohNet) -> None:
    uav = await zenoh_net.open("uav0")
    contexts = uav.subscribe(KEYS.context, MissionContext)
    assignments = uav.subscribe(KEYS.assign("*"), Assignment)
    cmdr_alive = uav.watch_liveliness(KEYS.alive_cmdr)
    cmdr = await start_commander(zenoh_net)
    assert (await cmdr_alive.get()) == (KEYS.alive_cmdr, True)
    assert await routed(cmdr.mesh, KEYS.context)
    assert await routed(cmdr.mesh, KEYS.assign("uav1"))

    cmdr.publish(PLAN)
    _key, ctx = await contexts.get()
    got = dict([await assignments.get(), await assignments.get()])

    assert (ctx.mission_id, ctx.task, ctx.participants) == ("m1", "coverage", UAVS)
    assert ctx.h.sender == "cmdr"
    assert ctx.text == PLAN.text
    assert list(ctx.constraints) == list(PLAN.constraints)
    assert set(got) == {KEYS.assign(u) for u in UAVS}
    for uav_id in UAVS:
        a = got[KEYS.assign(uav_id)]
        assert (a.uav, a.mission_id, a.role, a.revision) == (uav_id, "m1", "searcher", 1)
        assert tuple(a.skills) == COVERAGE_SKILLS
        assert a.h.sender == "cmdr"

    state = MissionState("uav0")
    state.update_context(ctx)
    state.update_assignment(got[KEYS.assign("uav0")])
    state.update_assignment(got[KEYS.assign("uav1")])  # not ours: ignored
    view = state.view()
    assert view is not None
    assert (view.mission_id, view.role, view.skills) == ("m1", "searcher", COVERAGE_SKILLS)


async def test_a_late_joiner_catches_up_from_the_queryables(zenoh_net: ZenohNet) -> None:
    cmdr = await start_commander(zenoh_net)
    cmdr.publish(PLAN)
    changed = replace(PLAN, text="Cover every landmark; L2 first.")
    cmdr.publish(changed)  # a republish: the late joiner must see the latest revision

    late = await zenoh_net.open("uav1")  # starts after publication
    [(key, ctx)] = await get_until(late, KEYS.context, MissionContext, 1)
    [(akey, mine)] = await get_until(late, KEYS.assign("uav1"), Assignment, 1)
    both = await get_until(late, KEYS.assign("*"), Assignment, 2)

    assert key == KEYS.context
    assert isinstance(ctx, MissionContext)
    assert (ctx.mission_id, ctx.text) == ("m1", changed.text)
    assert akey == KEYS.assign("uav1")
    assert isinstance(mine, Assignment)
    assert (mine.uav, mine.revision) == ("uav1", 2)
    assert sorted(k for k, _ in both) == [KEYS.assign(u) for u in UAVS]
    assert await late.get(KEYS.assign("uav9"), Assignment, timeout_s=0.3) == []

    state = MissionState("uav1")
    state.update_context(ctx)
    state.update_assignment(mine)
    view = state.view()
    assert view is not None
    assert view.text == changed.text


async def test_a_uav_dropped_from_the_plan_is_told_to_hold(zenoh_net: ZenohNet) -> None:
    """After a republish without uav1, uav1 (live or restarted) must not keep flying, or
    catch up on, its old role: it is served a hold-only release instead."""
    cmdr = await start_commander(zenoh_net)
    cmdr.publish(PLAN)
    cmdr.publish(plan_for_task("coverage", ["uav0"], mission_id="m1"))

    late = await zenoh_net.open("uav1")
    assert len(await get_until(late, KEYS.assign("uav0"), Assignment, 1)) == 1  # routes up
    [(_k, released)] = await get_until(late, KEYS.assign("uav1"), Assignment, 1)
    assert isinstance(released, Assignment)
    assert released.role == "unassigned"
    assert (released.skills, released.revision) == (["hold_position"], 2)
    [(_key, ctx)] = await get_until(late, KEYS.context, MissionContext, 1)
    assert ctx.participants == ["uav0"]


async def test_nothing_is_served_before_a_plan_exists(zenoh_net: ZenohNet) -> None:
    await start_commander(zenoh_net)
    late = await zenoh_net.open("uav0")
    assert await late.get(KEYS.context, MissionContext, timeout_s=0.3) == []


async def test_commander_writes_only_under_its_own_keys(zenoh_net: ZenohNet) -> None:
    spy = KeySpy(await zenoh_net.open("spy"))
    cmdr = await start_commander(zenoh_net)
    assert await eventually(lambda: KEYS.alive_cmdr in spy.tokens, 3.0)
    assert await routed(cmdr.mesh, KEYS.context)

    # Phase 1: only the Commander is writing. Publish, republish with another plan.
    cmdr.publish(PLAN)
    three = plan_for_task("coverage", [*UAVS, "uav2"], mission_id="m2")
    cmdr.publish(three)
    assert await eventually(lambda: len(spy.samples) >= 3 + 4, 3.0)
    phase1 = spy.decoded()
    assert {h.sender for _, h in phase1} == {"cmdr"}
    for key, _h in phase1:
        assert key.startswith(f"aw/{SWARM}/cmdr/"), key
    assert spy.tokens == {KEYS.alive_cmdr}

    # Phase 2: a UAV reports (one honest ready ack, one forged in another UAV's name);
    # the Commander reads them but still writes nothing outside cmdr/.
    uav = await zenoh_net.open("uav1")
    hf = HeaderFactory("uav1")

    def ready(claimed: str) -> ProgressReport:
        return ProgressReport(
            h=hf.next(),
            phase="ready",
            uav=claimed,
            mission_id="m2",
            episode=-1,
            round=-1,
            role="searcher",
            skill="",
            invocation="",
            label=None,
            held=True,
        )

    # The honest ack is repeated until it lands (a just-opened session may not know the
    # Commander's subscription yet); after that the route exists and one put suffices.
    for _ in range(30):
        uav.put(KEYS.report("uav1"), ready("uav1"), block=True)
        if await cmdr.wait_ready(["uav1"], 0.1) == set():
            break
    assert "uav1" in cmdr.board.ready
    uav.put(KEYS.report("uav2"), ready("uav2"), block=True)
    assert await eventually(lambda: cmdr.board.foreign == 1, 2.0)
    assert "uav2" not in cmdr.board.ready

    everything = spy.decoded()
    mine = [(k, h) for k, h in everything if h.sender == "cmdr"]
    assert len(mine) == len(phase1)  # reading reports made the Commander write nothing
    for key, _h in mine:
        assert key.startswith(f"aw/{SWARM}/cmdr/"), key
        assert not key.startswith((f"aw/{SWARM}/uav/", f"aw/{SWARM}/sim/"))
    assert {k for k, h in everything if h.sender != "cmdr"} == {
        KEYS.report("uav1"),
        KEYS.report("uav2"),
    }


def test_task_plan_is_what_the_swarm_flies() -> None:
    plan: MissionPlan = plan_for_task("coverage", UAVS, mission_id="m9")
    assert plan.participants == UAVS
    assert plan.text.startswith("Cover every landmark")
    assert all(a.skills[-1] == "hold_position" for a in plan.assignments.values())
