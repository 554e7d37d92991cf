"""Shared swarm memory inside an episode: in-flight records extend the sender's returns on
the receiver exactly as on the sender, the intake's per-sender bound and the memory's
per-sender caps hold for them, and a late joiner fetches its role's recent records from
its peers' queryables over real Zenoh (loopback)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any, cast

import msgspec

from aeroweaver_edge.agent.estimators import Estimator
from aeroweaver_edge.agent.memory.async_memory import AsyncExperienceMemory
from aeroweaver_edge.agent.memory.experience import (
    ExperienceMemory,
    StoredRecord,
)
from aeroweaver_edge.agent.memory.round_sharing import BATCH_BYTES, RoundSharing
from aeroweaver_edge.agent.memory.shared_intake import SharedIntake
from aeroweaver_edge.contracts.wire import (
    MAX_BATCH_RECORDS,
    MAX_TEXT,
    ExperienceRecord,
    HeaderFactory,
    Keys,
)
from tests.helpers.zenoh_net import ZenohNet

RUN = "run-r"
KEYS = Keys("rs")


def own_memory(path: Path | None = None, max_records_per_sender: int = 4096) -> ExperienceMemory:
    return ExperienceMemory(path, gamma=0.9, run=RUN, max_records_per_sender=max_records_per_sender)


def stored(path: Path) -> list[StoredRecord]:
    """What the receiver's file holds (read on a connection of this thread)."""
    mem = ExperienceMemory(path, run=RUN)
    try:
        return mem.records("coverage", "searcher")
    finally:
        mem.close()


def play(
    mem: ExperienceMemory,
    uav: str,
    rounds: int,
    role: str = "searcher",
    sharing: RoundSharing | None = None,
) -> None:
    """``rounds`` decisions of ``uav``, each rewarded (and published to ``sharing``)."""
    headers = HeaderFactory(uav)
    for t in range(rounds):
        mem.append(
            task="coverage", role=role, uav=uav, episode=0, round=t,
            state_text=f"task coverage role {role} landmark L{t % 3} near", skill="explore_local",
            invocation="explore_local()",
        )  # fmt: skip
        mem.add_reward(uav, 0, t, 0.25 * t - 1.0, "sim")
        if sharing is not None:
            sharing.published(published(mem, uav, t, headers))


def published(mem: ExperienceMemory, uav: str, t: int, headers: HeaderFactory) -> ExperienceRecord:
    rec = mem.get(uav, 0, t)
    assert rec is not None
    return rec.to_wire(headers.next())


async def test_in_flight_records_extend_the_senders_returns_exactly_as_it_does(
    tmp_path: Path,
) -> None:
    """Rounds 2, 3 and 5 held (no record): their rewards ride on the next record."""
    held = {2, 3, 5}
    sender = own_memory()
    mesh: Any = None  # the sender's bookkeeping only
    books = RoundSharing(mesh, KEYS, "uav0", HeaderFactory("uav0"), SharedIntake("uav0"), 0.9)
    receiver = await AsyncExperienceMemory.open(tmp_path / "uav1.db", gamma=0.9, run=RUN)
    intake = SharedIntake("uav1")
    headers = HeaderFactory("uav0")
    mine: list[tuple[int, float | None]] = []
    for t in range(8):  # round t: the sender decides (or holds), is rewarded, publishes
        play_one(sender, t, decide=t not in held)
        books.note_reward(0, t, reward(t))
        if t in held:
            continue
        wire = published(sender, "uav0", t, headers)
        wire = msgspec.structs.replace(wire, held_rewards=books.held_rewards(0, t))
        assert intake.offer(KEYS.experience("uav0"), wire, "searcher")
        assert intake.arrived(RUN, "uav0", 0, t)
        await intake.store(receiver)  # the receiver's round t+1 start
        mine = [(r.round, r.ret) for r in sender.records("coverage", "searcher")]
        theirs = [(r.round, r.ret) for r in stored(tmp_path / "uav1.db") if r.origin == "uav0"]
        assert theirs == mine  # bit for bit, while in flight
    assert [r for r, _ in mine] == [0, 1, 4, 6, 7]
    assert all(not r.final for r in stored(tmp_path / "uav1.db"))
    # the finalised versions replace them and credit nothing more
    sender.finalise("uav0", 0)
    for rec in sender.export_final("uav0", 0):
        intake.offer(KEYS.experience("uav0"), rec.to_wire(headers.next()), "searcher")
    assert intake.taken(RUN, 0) == 5  # only finalised records count for the barrier
    await intake.store(receiver)
    final = [(r.round, r.ret, r.final) for r in stored(tmp_path / "uav1.db")]
    assert final == [(t, ret, True) for t, ret in mine]
    await receiver.aclose()


def reward(t: int) -> float:
    return 0.25 * t - 1.0


def play_one(mem: ExperienceMemory, t: int, *, decide: bool = True) -> None:
    if decide:
        mem.append(
            task="coverage", role="searcher", uav="uav0", episode=0, round=t,
            state_text=f"task coverage role searcher landmark L{t % 3} near",
            skill="explore_local", invocation="explore_local()",
        )  # fmt: skip
    mem.add_reward("uav0", 0, t, reward(t), "sim")


async def test_a_flooding_sender_is_bounded_in_the_intake_and_in_memory(tmp_path: Path) -> None:
    intake = SharedIntake("uav1", max_per_sender=50)
    headers = HeaderFactory("uav9")
    flood = [
        ExperienceRecord(
            h=headers.next(),
            task="coverage",
            role="searcher",
            uav="uav9",
            episode=0,
            round=t,
            state_text=f"task coverage role searcher spam {t}",
            skill="hold_position",
            invocation="hold_position()",
            reward=100.0,
            ret=100.0,
            run=RUN,
        )
        for t in range(200)
    ]
    taken = sum(intake.offer(KEYS.experience("uav9"), r, "searcher") for r in flood)
    assert (taken, intake.refused, intake.pending) == (50, 150, 50)
    # an honest peer is not crowded out
    honest = HeaderFactory("uav0")
    mem = own_memory()
    play(mem, "uav0", 1)
    assert intake.offer(KEYS.experience("uav0"), published(mem, "uav0", 0, honest), "searcher")
    receiver = await AsyncExperienceMemory.open(tmp_path / "uav1.db", gamma=0.9, run=RUN)
    receiver.sync.max_records_per_sender = 20
    await intake.store(receiver)
    by_origin: dict[str, int] = {}
    for r in stored(tmp_path / "uav1.db"):
        by_origin[r.origin] = by_origin.get(r.origin, 0) + 1
    assert by_origin["uav9"] <= 20  # the memory's per-sender cap
    assert by_origin["uav0"] == 1
    await receiver.aclose()


async def test_a_late_joiner_fetches_its_roles_records_from_peers_queryables(
    zenoh_net: ZenohNet, tmp_path: Path
) -> None:
    a, b, late = [await zenoh_net.open(n) for n in ("uav0", "uav2", "uav1")]
    keys = Keys("sim")
    servers, mems = {}, {}
    for uav, mesh, role in (("uav0", a, "searcher"), ("uav2", b, "leader")):
        headers = HeaderFactory(uav)
        sharing = RoundSharing(mesh, keys, uav, headers, SharedIntake(uav), gamma=0.9)
        sharing.start()
        mem = own_memory()
        play(mem, uav, 5, role, sharing)
        servers[uav] = sharing
        mems[uav] = mem
    intake = SharedIntake("uav1")
    joiner = RoundSharing(late, keys, "uav1", HeaderFactory("uav1"), intake)
    taken = 0
    for _ in range(20):  # the queryables' declarations reach the joiner's session first
        taken = await joiner.fetch("searcher")
        if taken:
            break
        await asyncio.sleep(0.1)
    assert taken == 5  # uav0's searcher records; uav2's leader records are not ours
    assert intake.pending == 5
    assert not intake.arrived(RUN, "uav0", 0, 4)  # fetched: not a round's expected record
    # served with their returns as they stand in the sender's memory (not as first sent)
    receiver = await AsyncExperienceMemory.open(tmp_path / "uav1.db", gamma=0.9, run=RUN)
    await intake.store(receiver)
    await receiver.aclose()
    sender = [(r.round, r.ret) for r in mems["uav0"].records("coverage", "searcher")]
    assert [(r.round, r.ret) for r in stored(tmp_path / "uav1.db")] == sender
    for s in servers.values():
        await s.aclose()


def test_a_served_batch_fits_one_payload() -> None:
    mesh: Any = None  # batches are built without a mesh
    sharing = RoundSharing(mesh, KEYS, "uav0", HeaderFactory("uav0"), SharedIntake("uav0"))
    headers = HeaderFactory("uav0")
    for t in range(MAX_BATCH_RECORDS + 10):
        sharing.published(
            ExperienceRecord(
                h=headers.next(), task="coverage", role="searcher", uav="uav0", episode=0,
                round=t, state_text="x" * (MAX_TEXT // 2), skill="explore_local",
                invocation="explore_local()", run=RUN,
            )
        )  # fmt: skip
    batch = sharing.batch()
    assert batch is not None
    assert 0 < len(batch.records) <= MAX_BATCH_RECORDS
    assert len(msgspec.msgpack.encode(batch)) <= BATCH_BYTES + 4096
    assert batch.records[-1].round == MAX_BATCH_RECORDS + 9  # the newest are served


async def test_held_rewards_reach_an_equal_horizon_estimators_book(tmp_path: Path) -> None:
    """horizon:3 counts the rewards after a record: a peer's record of round 0, followed by
    held rounds 1-2 and a record of round 3, has 4 (eligible) only if the held ones came."""
    sender = own_memory()
    books = RoundSharing(cast(Any, None), KEYS, "uav0", HeaderFactory("uav0"),
                         SharedIntake("uav0"), 0.9)  # fmt: skip
    receiver = await AsyncExperienceMemory.open(
        tmp_path / "uav1.db", gamma=0.9, run=RUN, estimator=Estimator.parse("horizon:3")
    )
    intake = SharedIntake("uav1")
    headers = HeaderFactory("uav0")
    text = "task coverage role searcher landmark L0 near"
    await receiver.warm("coverage", "searcher")  # the group and its book exist first
    for t in range(4):
        play_one(sender, t, decide=t in (0, 3))
        books.note_reward(0, t, reward(t))
        if t in (0, 3):
            wire = published(sender, "uav0", t, headers)
            wire = msgspec.structs.replace(wire, held_rewards=books.held_rewards(0, t))
            intake.offer(KEYS.experience("uav0"), wire, "searcher")
            await intake.store(receiver)
    found = await receiver.neighbourhood_of("coverage", "searcher", text)
    await receiver.aclose()
    assert [n.key[2] for n in found] == [0]  # round 0 eligible: r0..r3 are known
