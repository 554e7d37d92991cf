"""Peers' shared records: taken on arrival (checked, deduplicated, counted per episode),
stored at the next round start in one canonical order whatever the arrival order."""

from __future__ import annotations

import random
from pathlib import Path

from aeroweaver_edge.agent.memory.async_memory import AsyncExperienceMemory
from aeroweaver_edge.agent.memory.experience import ExperienceMemory
from aeroweaver_edge.agent.memory.shared_intake import MAX_EPISODES, SharedIntake
from aeroweaver_edge.contracts.wire import ExperienceRecord, Header, Keys

KEYS = Keys("si")
RUN = "run-a"


def rec(
    uav: str, episode: int, rnd: int, *, role: str = "searcher", seq: int = 1,
    final: bool = True, ret: float = 1.0, run: str = RUN, sender: str | None = None,
) -> tuple[str, ExperienceRecord]:  # fmt: skip
    h = Header(sender=sender or uav, epoch=7, seq=seq, stamp=0.0)
    r = ExperienceRecord(
        h=h, task="coverage", role=role, uav=uav, episode=episode, round=rnd,
        state_text=f"task coverage role {role} self {uav} round {rnd}", skill="explore_local",
        invocation="explore_local()", reward=0.5, ret=ret, final=final, run=run,
    )  # fmt: skip
    return KEYS.experience(uav), r


def test_only_same_role_peers_own_records_on_their_own_key_are_taken() -> None:
    intake = SharedIntake("uav0")
    assert intake.offer(*rec("uav1", 0, 0), "searcher")
    assert not intake.offer(*rec("uav2", 0, 0, role="leader"), "searcher")  # other role
    assert not intake.offer(*rec("uav0", 0, 1), "searcher")  # our own echo
    assert not intake.offer(*rec("uav1", 0, 2), None)  # no mission: no role to match
    key, forged = rec("uav1", 0, 3, sender="uav2")  # uav2 speaking for uav1
    assert not intake.offer(key, forged, "searcher")
    _, on_wrong_key = rec("uav1", 0, 4)
    assert not intake.offer(KEYS.experience("uav2"), on_wrong_key, "searcher")
    assert intake.refused == 2
    assert intake.taken(RUN, 0) == 1
    assert intake.pending == 1


def test_every_peers_final_record_is_received_whatever_its_role() -> None:
    """The barrier's count: a reassigned peer's records of its old role are not taken but
    are received, so the barrier can tell that nothing it waits for is still on the way."""
    intake = SharedIntake("uav0")
    intake.offer(*rec("uav1", 0, 0, role="leader"), "searcher")
    intake.offer(*rec("uav1", 0, 1), "searcher")
    intake.offer(*rec("uav1", 0, 1, seq=2), "searcher")  # a newer version: the same record
    intake.offer(*rec("uav1", 0, 2, final=False), "searcher")  # in flight: not yet
    intake.offer(*rec("uav2", 0, 0, role="leader"), None)  # no mission yet: still received
    intake.offer(*rec("uav0", 0, 0), "searcher")  # our own echo: not a peer's
    key, forged = rec("uav1", 0, 3, sender="uav2")
    intake.offer(key, forged, "searcher")  # not authentic: not received
    assert (intake.received(RUN, 0), intake.taken(RUN, 0)) == (3, 1)
    assert intake.grown(RUN) == [0]
    assert intake.grown(RUN) == []  # reported: nothing new since
    intake.offer(*rec("uav1", 0, 1, seq=3), "searcher")
    assert intake.grown(RUN) == []  # a version of a record already received
    intake.offer(*rec("uav2", 1, 0), "searcher")
    intake.offer(*rec("uav2", 0, 0, run="other"), "searcher")
    assert intake.grown(RUN) == [1]


def test_counts_distinct_records_per_run_and_episode_newer_versions_replace() -> None:
    intake = SharedIntake("uav0")
    assert intake.offer(*rec("uav1", 0, 0, final=False, seq=1), "searcher")
    assert intake.offer(*rec("uav1", 0, 0, final=True, seq=2), "searcher")  # a newer version
    assert not intake.offer(*rec("uav1", 0, 0, final=True, seq=2), "searcher")  # duplicate
    assert not intake.offer(*rec("uav1", 0, 0, final=False, seq=3), "searcher")  # downgrade
    assert intake.offer(*rec("uav2", 0, 5), "searcher")
    assert intake.offer(*rec("uav2", 1, 0), "searcher")
    assert intake.offer(*rec("uav2", 0, 0, run="other"), "searcher")
    assert (intake.taken(RUN, 0), intake.taken(RUN, 1), intake.taken("other", 0)) == (2, 1, 1)
    assert intake.taken(RUN, 2) == 0


def test_a_flood_is_bounded() -> None:
    intake = SharedIntake("uav0", max_pending=3)
    taken = [intake.offer(*rec("uav1", 0, r), "searcher") for r in range(5)]
    assert taken == [True, True, True, False, False]
    assert intake.refused == 2
    assert intake.pending == 3


def test_received_tallies_are_bounded_under_a_flood_of_episodes() -> None:
    intake = SharedIntake("uav0")
    for episode in range(3 * MAX_EPISODES):
        intake.offer(*rec("uav1", episode, 0, role="leader"), "searcher")
    assert intake.grown(RUN) == list(range(2 * MAX_EPISODES, 3 * MAX_EPISODES))
    assert intake.received(RUN, 0) == 0  # forgotten, oldest first


async def test_storage_order_is_canonical_whatever_the_arrival_order(tmp_path: Path) -> None:
    """Two memories fed the same records in different arrival orders store them in the
    same order (retrieval's recency tie-break then agrees)."""
    records = [rec(u, e, r) for e in (0, 1) for u in ("uav3", "uav1", "uav2") for r in range(4)]
    orders = []
    for i, seed in enumerate((1, 2)):
        shuffled = records[:]
        random.Random(seed).shuffle(shuffled)
        intake = SharedIntake("uav0")
        path = tmp_path / f"m{i}.sqlite3"
        mem = await AsyncExperienceMemory.open(path, run="mine")
        try:
            assert all(intake.offer(k, r, "searcher") for k, r in shuffled)
            assert await intake.store(mem) == len(records)
            assert intake.pending == 0
            assert intake.stored == len(records)
        finally:
            await mem.aclose()
        with ExperienceMemory(path) as reader:
            stored = reader.records("coverage", "searcher")
        orders.append([(s.episode, s.uav, s.round) for s in stored])
    assert orders[0] == orders[1] == sorted(orders[0])
