"""Experience memory: returns, idempotence, retrieval arithmetic, sharing, persistence,
quarantine and the asyncio wrapper. Every memory lives on disk in tmp_path."""

from __future__ import annotations

import asyncio
import json
import logging
import math
import sqlite3
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aeroweaver_edge.agent.memory.async_memory import AsyncExperienceMemory
from aeroweaver_edge.agent.memory.experience import (
    ExperienceMemory,
    StoredRecord,
    skill_of,
)
from aeroweaver_edge.agent.memory.index import select_indexed, select_python
from aeroweaver_edge.agent.state_tokens import bucket, jaccard, tokenise
from aeroweaver_edge.config import AgentConfig
from aeroweaver_edge.contracts.wire import ExperienceRecord, Header
from aeroweaver_lab.bench import memory as bench

T, R = "coverage", "searcher"
PEER_RUN = "peer-run"


@pytest.fixture
def db(tmp_path: Path) -> Path:
    return tmp_path / "memory.sqlite"


@pytest.fixture
def mem(db: Path) -> Iterator[ExperienceMemory]:
    m = ExperienceMemory(db, gamma=0.5)
    yield m
    m.close()


def add(
    m: ExperienceMemory,
    rnd: int,
    state: str,
    skill: str,
    ret: float | None = None,
    *,
    uav: str = "u1",
    episode: int | None = None,
    task: str = T,
    role: str = R,
) -> None:
    """Append a one-record trajectory (episode = round unless given) whose return is
    exactly ``ret``, its only reward."""
    episode = rnd if episode is None else episode
    m.append(
        task=task,
        role=role,
        uav=uav,
        episode=episode,
        round=rnd,
        state_text=state,
        skill=skill,
        invocation=f"{skill}()",
    )
    if ret is not None:
        m.add_reward(uav, episode, rnd, ret, "test")


def one(m: ExperienceMemory, uav: str, episode: int, rnd: int) -> StoredRecord:
    rec = m.get(uav, episode, rnd)
    assert rec is not None, (uav, episode, rnd)
    return rec


def header(seq: int, sender: str = "u9", epoch: int = 1) -> Header:
    return Header(sender=sender, epoch=epoch, seq=seq, stamp=0.0)


def peer_record(seq: int, **kw: object) -> ExperienceRecord:
    fields: dict[str, object] = dict(
        task=T,
        role=R,
        uav="u9",
        episode=4,
        round=2,
        state_text="landmark l1 peer",
        skill="cover_landmark",
        invocation="cover_landmark(target=L1)",
        run=PEER_RUN,
    )
    fields.update(kw)
    return ExperienceRecord(h=header(seq), **fields)  # type: ignore[arg-type]


# ---------------------------------------------------------------- tokeniser


def test_tokeniser_words_numbers_and_context() -> None:
    toks = tokenise("Landmark L2 at (-28.0, 24.1) dist 36.7 m; peer uav-3 x=-4.5")
    assert toks == {
        "landmark",
        "l2",
        "l2~-20",
        "l2~20",
        "dist",
        "dist~30",
        "peer",
        "uav-3",
        "x",
        "x~-3",
    }
    # "alike" distances share a bucket, different ones do not
    assert tokenise("dist 31.0") == tokenise("dist 49.9") != tokenise("dist 50.1")
    assert [bucket(v) for v in (0.4, -0.9, 1, 2.9, 3, -7.5, 1e6)] == [
        "0",
        "0",
        "1",
        "2",
        "3",
        "-7",
        "1000",
    ]
    assert jaccard(frozenset("ab"), frozenset("bc")) == pytest.approx(1 / 3)


# ---------------------------------------------------------------- returns


def test_returns_with_gamma_exact(mem: ExperienceMemory) -> None:
    for t in range(4):
        mem.append(
            task=T,
            role=R,
            uav="u1",
            episode=1,
            round=t,
            state_text=f"state {t}",
            skill="hold_position",
            invocation="hold_position()",
        )
    mem.add_reward("u1", 1, 0, 1.0, "sim")
    mem.add_reward("u1", 1, 1, 2.0, "sim")
    mem.add_reward("u1", 1, 2, 4.0, "sim")
    got = [mem.get("u1", 1, t) for t in range(4)]
    # gamma 0.5: G2 = 4; G1 = 2 + 0.5*4 = 4; G0 = 1 + 0.5*2 + 0.25*4 = 3; G3 not yet rewarded
    assert [g.ret if g else None for g in got] == [3.0, 4.0, 4.0, None]
    assert [g.reward if g else None for g in got] == [1.0, 2.0, 4.0, None]
    assert got[0] is not None
    assert got[0].reward_source == "sim"


def test_returns_paper_gamma_and_delivery_order(tmp_path: Path) -> None:
    """gamma 0.95; rewards arriving before their records (and out of order) still count."""
    rewards = [0.3, -1.25, 2.0, 0.5]
    with ExperienceMemory(tmp_path / "m.sqlite", gamma=0.95) as m:
        m.add_reward("u1", 7, 3, rewards[3], "sim")
        m.add_reward("u1", 7, 1, rewards[1], "sim")
        for t in range(4):
            m.append(
                task=T,
                role=R,
                uav="u1",
                episode=7,
                round=t,
                state_text="s",
                skill="hold_position",
                invocation="hold_position()",
            )
        m.add_reward("u1", 7, 2, rewards[2], "sim")
        m.add_reward("u1", 7, 0, rewards[0], "sim")
        for t in range(4):
            want = sum(0.95 ** (u - t) * rewards[u] for u in range(t, 4))
            rec = m.get("u1", 7, t)
            assert rec is not None
            assert rec.ret == pytest.approx(want, abs=1e-12)
            assert rec.reward == rewards[t]


def test_other_trajectories_untouched(mem: ExperienceMemory) -> None:
    mem.append(
        task=T, role=R, uav="u1", episode=1, round=0, state_text="s", skill="a", invocation="a()"
    )
    mem.append(
        task=T, role=R, uav="u2", episode=1, round=0, state_text="s", skill="a", invocation="a()"
    )
    mem.append(
        task=T, role=R, uav="u1", episode=2, round=0, state_text="s", skill="a", invocation="a()"
    )
    mem.add_reward("u1", 1, 0, 5.0, "sim")
    assert [one(mem, *k).ret for k in (("u1", 1, 0), ("u2", 1, 0), ("u1", 2, 0))] == [
        5.0,
        None,
        None,
    ]


def test_reward_idempotent_and_replaced(mem: ExperienceMemory) -> None:
    mem.append(
        task=T, role=R, uav="u1", episode=1, round=0, state_text="s", skill="a", invocation="a()"
    )
    mem.append(
        task=T, role=R, uav="u1", episode=1, round=1, state_text="s", skill="a", invocation="a()"
    )
    assert mem.add_reward("u1", 1, 1, 2.0, "sim") is True
    assert mem.add_reward("u1", 1, 1, 2.0, "sim") is False  # duplicate delivery
    assert one(mem, "u1", 1, 0).ret == 1.0
    # a corrected value replaces the old one instead of adding to it
    assert mem.add_reward("u1", 1, 1, 6.0, "sim") is True
    assert one(mem, "u1", 1, 0).ret == 3.0
    assert one(mem, "u1", 1, 1).ret == 6.0
    assert mem.add_reward("u1", 1, 1, math.nan, "sim") is False
    assert one(mem, "u1", 1, 1).ret == 6.0


def test_append_deduplicates(mem: ExperienceMemory) -> None:
    assert (
        mem.append(
            task=T,
            role=R,
            uav="u1",
            episode=1,
            round=0,
            state_text="s",
            skill="a",
            invocation="a()",
        )
        is True
    )
    assert (
        mem.append(
            task=T,
            role=R,
            uav="u1",
            episode=1,
            round=0,
            state_text="other",
            skill="b",
            invocation="b()",
        )
        is False
    )
    assert len(mem) == 1
    assert one(mem, "u1", 1, 0).skill == "a"


def test_finalise_and_export(mem: ExperienceMemory) -> None:
    for t in range(3):
        mem.append(
            task=T,
            role=R,
            uav="u1",
            episode=1,
            round=t,
            state_text="s",
            skill="cover_landmark",
            invocation=f"cover_landmark(target=L{t})",
        )
        mem.add_reward("u1", 1, t, 1.0, "sim")
    mem.append(
        task=T, role=R, uav="u1", episode=2, round=0, state_text="s", skill="a", invocation="a()"
    )
    assert mem.export_final("u1", 1) == []
    assert mem.finalise("u1", 1) == 3
    assert mem.finalise("u1", 1) == 0
    out = mem.export_final("u1", 1)
    assert [(r.round, r.final) for r in out] == [(0, True), (1, True), (2, True)]
    assert one(mem, "u1", 2, 0).final is False
    wire = out[0].to_wire(header(1, sender="u1"))
    assert (wire.uav, wire.round, wire.ret, wire.final, wire.reward_source) == (
        "u1",
        0,
        1.0 + 0.5 + 0.25,
        True,
        "sim",
    )
    assert wire.invocation == "cover_landmark(target=L0)"
    assert wire.skill == "cover_landmark"


# ---------------------------------------------------------------- retrieval


def test_exact_task_and_role_filter(mem: ExperienceMemory) -> None:
    state = "landmark l1 peer uav2"
    add(mem, 0, state, "a", 10.0, task="pursuit")
    add(mem, 1, state, "a", 10.0, role="speaker")
    add(mem, 2, state, "b", 1.0)
    add(mem, 3, state, "c", 3.0)
    assert [n.key[2] for n in mem.neighbourhood_of(T, R, state)] == [3, 2]
    assert mem.advantages(T, R, state, ["a", "b", "c"]) == {"a": 0.0, "b": -1.0, "c": 1.0}
    assert mem.advantages("pursuit", R, state, ["a"]) == {"a": 0.0}  # one record: baseline


def test_top_k_by_jaccard_with_recency_tiebreak(db: Path) -> None:
    with ExperienceMemory(db, neighbourhood=3) as m:
        query = "alpha bravo charlie delta"
        add(m, 0, "alpha bravo charlie delta", "x", 1.0)  # J = 1
        add(m, 1, "alpha bravo", "x", 1.0)  # J = 1/2, oldest of the tie
        add(m, 2, "alpha bravo", "x", 1.0)  # J = 1/2
        add(m, 3, "alpha bravo charlie delta", "x")  # J = 1 but no return yet: not eligible
        add(m, 4, "bravo charlie", "x", 1.0)  # J = 1/2, newest of the tie
        add(m, 5, "alpha bravo charlie echo", "x", 1.0)  # J = 3/5
        add(m, 6, "echo foxtrot", "x", 1.0)  # J = 0: never a neighbour
        got = m.neighbourhood_of(T, R, query)
        assert [(n.key[2], n.similarity) for n in got] == [(0, 1.0), (5, 0.6), (4, 0.5)]
        m.add_reward("u1", 3, 3, 1.0, "sim")  # now eligible; newest of the J = 1 tie
        assert [n.key[2] for n in m.neighbourhood_of(T, R, query)] == [3, 0, 5]
        m.neighbourhood = 10
        assert [n.key[2] for n in m.neighbourhood_of(T, R, query)] == [3, 0, 5, 4, 2, 1]


def test_baseline_and_per_skill_advantage(mem: ExperienceMemory) -> None:
    s = "landmark l1 dist 12 peer uav2"
    for rnd, (skill, ret) in enumerate(
        [("cover", 4.0), ("cover", 2.0), ("hold", -1.0), ("explore", 1.0), ("hold", 0.0)]
    ):
        add(mem, rnd, s, skill, ret)
    baseline = (4 + 2 - 1 + 1 + 0) / 5  # 1.2
    adv = mem.advantages(T, R, s, ["cover", "hold", "explore", "send_status"])
    assert adv == pytest.approx(
        {
            "cover": 3.0 - baseline,
            "hold": -0.5 - baseline,
            "explore": 1.0 - baseline,
            "send_status": 0.0,
        },
        abs=1e-12,
    )


def test_unseen_skill_and_empty_memory_give_zero(mem: ExperienceMemory) -> None:
    assert mem.advantages(T, R, "anything", ["a", "b"]) == {"a": 0.0, "b": 0.0}
    add(mem, 0, "landmark l1", "a", 2.0)
    add(mem, 1, "landmark l1", "b", 0.0)
    assert mem.advantages(T, R, "landmark l1", ["c"]) == {"c": 0.0}
    assert mem.advantages(T, R, "no overlap at all", ["a"]) == {"a": 0.0}
    assert mem.advantages(T, R, "", ["a"]) == {"a": 0.0}


def test_parameterisations_share_skill_advantage(mem: ExperienceMemory) -> None:
    s = "landmark l1 landmark l2"
    mem.append(
        task=T,
        role=R,
        uav="u1",
        episode=1,
        round=0,
        state_text=s,
        skill="cover_landmark",
        invocation="cover_landmark(target=L1)",
    )
    mem.append(
        task=T,
        role=R,
        uav="u1",
        episode=1,
        round=1,
        state_text=s,
        skill="cover_landmark",
        invocation="cover_landmark(target=L2)",
    )
    mem.append(
        task=T,
        role=R,
        uav="u1",
        episode=1,
        round=2,
        state_text=s,
        skill="hold_position",
        invocation="hold_position()",
    )
    mem.add_reward("u1", 1, 2, 0.0, "sim")  # G2 = 0
    mem.add_reward("u1", 1, 1, 2.0, "sim")  # G1 = 2
    mem.add_reward("u1", 1, 0, 1.0, "sim")  # G0 = 1 + 0.5*2 = 2
    want = 2.0 - 4.0 / 3.0
    adv = mem.advantages(
        T, R, s, ["cover_landmark", "cover_landmark(target=L1)", "cover_landmark(target=L9)"]
    )
    assert adv == pytest.approx(dict.fromkeys(adv, want), abs=1e-12)
    assert skill_of("cover_landmark(target=L1)") == "cover_landmark"


def test_finalised_only_variant(db: Path) -> None:
    with ExperienceMemory(db, finalised_only=True) as m:
        add(m, 0, "landmark l1", "a", 2.0, episode=1)
        add(m, 0, "landmark l1", "b", 0.0, episode=2)
        assert m.advantages(T, R, "landmark l1", ["a"]) == {"a": 0.0}  # nothing final yet
        m.finalise("u1", 1)
        m.finalise("u1", 2)
        assert m.advantages(T, R, "landmark l1", ["a", "b"]) == {"a": 1.0, "b": -1.0}


# ---------------------------------------------------------------- shared swarm memory


def test_ingest_dedup_and_update(mem: ExperienceMemory) -> None:
    s = "landmark l1 peer"
    assert mem.ingest(peer_record(5)) is True
    assert mem.ingest(peer_record(5)) is False  # same copy again
    assert mem.ingest(peer_record(6)) is False  # newer copy, same content
    assert mem.advantages(T, R, s, ["cover_landmark"]) == {"cover_landmark": 0.0}
    assert mem.neighbourhood_of(T, R, s) == []  # no return yet: not eligible
    assert mem.ingest(peer_record(7, reward=1.0, ret=1.5, reward_source="sim")) is True
    assert [n.ret for n in mem.neighbourhood_of(T, R, s)] == [1.5]
    assert mem.ingest(peer_record(6, reward=1.0, ret=0.1)) is False  # older version
    final = peer_record(8, reward=1.0, ret=2.5, final=True)
    assert mem.ingest(final) is True
    assert mem.ingest(peer_record(9, reward=1.0, ret=9.0)) is False  # never un-finalise
    rec = mem.get("u9", 4, 2, run=PEER_RUN)
    assert rec is not None
    assert (rec.ret, rec.final, rec.origin, rec.run) == (2.5, True, "u9", PEER_RUN)
    assert [n.ret for n in mem.neighbourhood_of(T, R, s)] == [2.5]
    assert len(mem) == 1
    # a peer's record is credited by its publisher, not by our reward stream
    mem.add_reward("u9", 4, 2, 100.0, "sim")
    assert mem.get("u9", 4, 2, run=PEER_RUN) == rec


def test_ingest_never_overwrites_own_records(mem: ExperienceMemory) -> None:
    add(mem, 0, "landmark l1", "a", 1.0)
    echo = ExperienceRecord(
        h=header(99, sender="u1", epoch=99),
        task=T,
        role=R,
        uav="u1",
        episode=0,
        round=0,
        state_text="landmark l1",
        skill="a",
        invocation="a()",
        reward=7.0,
        ret=7.0,
        final=True,
        run=mem.run,
    )
    assert mem.ingest(echo) is False
    assert one(mem, "u1", 0, 0).ret == 1.0


@pytest.mark.parametrize(
    "bad",
    [dict(ret=math.inf), dict(reward=math.nan), dict(state_text="x" * 5000), dict(skill="")],
)
def test_ingest_refuses_malformed(mem: ExperienceMemory, bad: dict[str, object]) -> None:
    assert mem.ingest(peer_record(1, **bad)) is False
    assert len(mem) == 0


def test_ingest_round_trip_between_daemons(tmp_path: Path) -> None:
    with ExperienceMemory(tmp_path / "a.sqlite") as a, ExperienceMemory(tmp_path / "b.sqlite") as b:
        for t in range(3):
            a.append(
                task=T,
                role=R,
                uav="u1",
                episode=1,
                round=t,
                state_text=f"landmark l{t}",
                skill="cover_landmark",
                invocation="cover_landmark()",
            )
            a.add_reward("u1", 1, t, float(t), "sim")
        a.finalise("u1", 1)
        for i, rec in enumerate(a.export_final("u1", 1)):
            assert b.ingest(rec.to_wire(header(i + 1, sender="u1"))) is True
        mine = [(r.round, r.ret, r.final, r.run) for r in a.records(T, R)]
        assert [(r.round, r.ret, r.final, r.run) for r in b.records(T, R)] == mine
        assert {r.run for r in b.records(T, R)} == {a.run}
        assert {r.origin for r in b.records(T, R)} == {"u1"}


# ---------------------------------------------------------------- persistence


def fill_small(m: ExperienceMemory) -> None:
    for ep in range(1, 4):
        for t in range(6):
            skill = ("cover", "hold", "explore")[(ep + t) % 3]
            m.append(
                task=T,
                role=R,
                uav="u1",
                episode=ep,
                round=t,
                state_text=f"landmark l{t % 3} dist {5 * t} peer uav{ep}",
                skill=skill,
                invocation=f"{skill}(target=L{t})",
            )
            m.add_reward("u1", ep, t, float((ep * 7 + t * 3) % 5) - 2.0, "sim")
        m.finalise("u1", ep)
    m.ingest(peer_record(1, reward=3.0, ret=3.0, final=True))


def test_restart_persistence(db: Path) -> None:
    queries = ["landmark l1 dist 10 peer uav2", "landmark l0 peer uav1", "landmark l1 peer"]
    skills = ["cover", "hold", "explore", "cover_landmark", "unseen"]
    with ExperienceMemory(db) as m:
        fill_small(m)
        before = [m.advantages(T, R, q, skills) for q in queries]
        hoods = [m.neighbourhood_of(T, R, q) for q in queries]
        rows = m.records(T, R)
    assert any(v != 0.0 for adv in before for v in adv.values())
    with ExperienceMemory(db) as m:  # a restart is a new run: the old records stay as they are
        assert m.quarantined is None
        assert m.warm(T, R) == len(rows) == 19
        assert m.records(T, R) == rows
        assert [m.advantages(T, R, q, skills) for q in queries] == before
        assert [m.neighbourhood_of(T, R, q) for q in queries] == hoods


def test_index_built_before_writes_matches_rebuilt_index(db: Path) -> None:
    """The lazily loaded index, then kept in sync by writes, equals a fresh rebuild."""
    q = "landmark l1 dist 10 peer uav2"
    with ExperienceMemory(db) as m:
        m.advantages(T, R, q, [])  # load the (empty) index first: every write now syncs it
        fill_small(m)
        live = m.neighbourhood_of(T, R, q)
    with ExperienceMemory(db) as m:
        assert m.neighbourhood_of(T, R, q) == live


def test_gamma_change_recomputes_own_returns(db: Path) -> None:
    with ExperienceMemory(db, gamma=0.5) as m:
        for t in range(2):
            m.append(
                task=T,
                role=R,
                uav="u1",
                episode=1,
                round=t,
                state_text="s",
                skill="a",
                invocation="a()",
            )
            m.add_reward("u1", 1, t, 2.0, "sim")
    with ExperienceMemory(db, gamma=1.0) as m:
        assert [r.ret for r in m.records(T, R)] == [4.0, 2.0]


def test_corrupt_file_is_quarantined(db: Path, caplog: pytest.LogCaptureFixture) -> None:
    db.write_bytes(b"this is not a database" * 200)
    with caplog.at_level(logging.ERROR), ExperienceMemory(db) as m:
        assert m.quarantined is not None
        assert m.quarantined.exists()
        assert m.quarantined.read_bytes().startswith(b"this is not a database")
        add(m, 0, "landmark l1", "a", 1.0)
        assert len(m) == 1
    assert "quarantined" in caplog.text
    assert str(m.quarantined) in caplog.text
    with ExperienceMemory(db) as m:  # the fresh file is healthy and kept
        assert m.quarantined is None
        assert len(m) == 1


def test_a_file_whose_writer_died_at_birth_is_initialised_not_set_aside(db: Path) -> None:
    """The version table exists but holds no row yet: nothing to quarantine."""
    conn = sqlite3.connect(db)
    conn.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
    conn.commit()
    conn.close()
    with ExperienceMemory(db) as m:
        assert m.quarantined is None
        add(m, 0, "landmark l1", "a", 1.0)
        assert len(m) == 1
    assert list(db.parent.glob("*.corrupt-*")) == []


@pytest.mark.parametrize("version", [0, -1, "two"])
def test_an_invalid_schema_version_is_set_aside(
    db: Path, version: object, caplog: pytest.LogCaptureFixture
) -> None:
    """A version no release ever wrote: the file is quarantined untouched, a fresh one used."""
    conn = sqlite3.connect(db)
    conn.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
    conn.execute("INSERT INTO schema_version VALUES (?)", (version,))
    conn.commit()
    conn.close()
    with caplog.at_level(logging.ERROR), ExperienceMemory(db) as m:
        assert m.quarantined is not None
        assert len(m) == 0
    assert f"schema version {version!r} is not valid" in caplog.text
    aside = sqlite3.connect(m.quarantined)
    try:
        assert aside.execute("SELECT version FROM schema_version").fetchall() == [(version,)]
    finally:
        aside.close()


def test_damaged_index_page_fails_integrity_check(db: Path) -> None:
    with ExperienceMemory(db) as m:
        fill_small(m)
    conn = sqlite3.connect(db)
    root = conn.execute("SELECT rootpage FROM sqlite_master WHERE name = 'records_by_role'")
    page = root.fetchone()[0]
    size = conn.execute("PRAGMA page_size").fetchone()[0]
    conn.close()
    with db.open("r+b") as f:
        f.seek(page * size - 200)
        f.write(b"\x00" * 200)
    with ExperienceMemory(db) as m:
        assert m.quarantined is not None
        assert len(m) == 0
        assert m.advantages(T, R, "landmark l1", ["cover"]) == {"cover": 0.0}


def test_foreign_database_is_set_aside(db: Path) -> None:
    conn = sqlite3.connect(db)
    conn.execute("CREATE TABLE something_else (x)")
    conn.commit()
    conn.close()
    with ExperienceMemory(db) as m:
        assert m.quarantined is not None
        assert len(m) == 0


def test_unusable_path_falls_back_to_in_memory(tmp_path: Path) -> None:
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("x")
    with ExperienceMemory(blocker / "memory.sqlite") as m:
        assert m.degraded is not None
        add(m, 0, "landmark l1", "a", 1.0)
        assert len(m) == 1


def test_disk_full_is_dropped_not_raised(mem: ExperienceMemory) -> None:
    add(mem, 0, "landmark l1", "a", 1.0)
    pages = mem._db.execute("PRAGMA page_count").fetchone()[0]
    mem._db.execute(f"PRAGMA max_page_count = {pages}")  # the next new page is "disk full"
    big = "landmark l1 " + "filler " * 2000
    for t in range(1, 20):
        mem.append(
            task=T,
            role=R,
            uav="u1",
            episode=1,
            round=t,
            state_text=big + str(t),
            skill="b",
            invocation="b()",
        )
    assert mem.write_errors > 0
    assert mem.advantages(T, R, "landmark l1", ["a"]) == {"a": 0.0}  # still answers
    assert all(
        n.key[2] == 0 or mem.get(*n.key, run=n.run) for n in mem.neighbourhood_of(T, R, "landmark")
    )


def test_from_config_and_in_memory() -> None:
    m = ExperienceMemory.from_config(AgentConfig(gamma=0.5, neighbourhood=2))
    assert (m.path, m.gamma, m.neighbourhood) == (None, 0.5, 2)
    add(m, 0, "landmark l1", "a", 1.0)
    assert len(m) == 1
    m.close()


# ---------------------------------------------------------------- oracle property


def oracle(records: list[StoredRecord], state: str, k: int, skills: list[str]) -> dict[str, float]:
    q = tokenise(state)
    scored = [(jaccard(q, tokenise(r.state_text)), r.seq, r) for r in records if r.ret is not None]
    hood = sorted((x for x in scored if x[0] > 0), key=lambda x: (-x[0], -x[1]))[:k]
    if not hood:
        return dict.fromkeys(skills, 0.0)
    base = sum(r.ret for _, _, r in hood if r.ret is not None) / len(hood)
    out = {}
    for s in skills:
        rets = [r.ret for _, _, r in hood if r.skill == s and r.ret is not None]
        out[s] = sum(rets) / len(rets) - base if rets else 0.0
    return out


WORDS = st.sampled_from(["landmark", "l1", "l2", "peer", "uav2", "dist", "msg", "hold"])
STATE = st.lists(st.one_of(WORDS, st.integers(-80, 80).map(str)), max_size=6).map(" ".join)


@settings(max_examples=40, deadline=None)
@given(
    rows=st.lists(
        st.tuples(
            STATE, st.sampled_from(["a", "b", "c"]), st.one_of(st.none(), st.integers(-5, 5))
        ),
        max_size=40,
    ),
    query=STATE,
    k=st.integers(1, 6),
)
def test_advantages_match_bruteforce_oracle(
    rows: list[tuple[str, str, int | None]], query: str, k: int
) -> None:
    with ExperienceMemory(None, neighbourhood=k, gamma=0.9) as m:
        m.advantages(T, R, query, [])  # index live while writing
        for i, (state, skill, reward) in enumerate(rows):
            m.append(
                task=T,
                role=R,
                uav=f"u{i % 3}",
                episode=i // 3,
                round=i,
                state_text=state,
                skill=skill,
                invocation=f"{skill}()",
            )
            if reward is not None:
                m.add_reward(f"u{i % 3}", i // 3, i, float(reward), "sim")
        want = oracle(m.records(T, R), query, k, ["a", "b", "c", "d"])
        assert m.advantages(T, R, query, ["a", "b", "c", "d"]) == pytest.approx(want, abs=1e-9)


# ---------------------------------------------------------------- asyncio wrapper


async def test_async_wrapper_does_not_block_the_loop(db: Path) -> None:
    mem = await AsyncExperienceMemory.open(db, gamma=0.5)
    threads: set[int] = set()
    inner = mem.sync
    original = inner.advantages

    def slow_advantages(*args: object, **kw: object) -> dict[str, float]:
        # A slow disk: the worker is stuck until the loop has ticked three times (at most
        # 5 s). Had the call run on the loop, no tick could happen: the count stays 0.
        threads.add(threading.get_ident())
        deadline = time.monotonic() + 5.0
        while ticks < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
        return original(*args, **kw)  # type: ignore[arg-type]

    inner.advantages = slow_advantages  # type: ignore[method-assign]
    ticks = 0

    async def ticker() -> None:
        nonlocal ticks
        while True:
            await asyncio.sleep(0.01)
            ticks += 1

    tick_task = asyncio.create_task(ticker())
    try:
        for t in range(3):
            assert await mem.append(
                task=T,
                role=R,
                uav="u1",
                episode=1,
                round=t,
                state_text="landmark l1",
                skill="a",
                invocation="a()",
            )
            assert await mem.add_reward("u1", 1, t, 1.0, "sim")
        assert await mem.finalise("u1", 1) == 3
        await asyncio.sleep(0.02)
        ticks = 0
        adv = await mem.advantages(T, R, "landmark l1", iter(["a", "b"]))
        assert adv == {"a": 0.0, "b": 0.0}
        assert ticks >= 3  # the loop ran while the worker was stuck; 0 if it had been blocked
        assert threads
        assert threading.get_ident() not in threads
        assert await mem.count() == 3
        assert [r.round for r in await mem.export_final("u1", 1)] == [0, 1, 2]
        assert (await mem.get("u1", 1, 0)) is not None
        assert await mem.ingest(peer_record(1, reward=1.0, ret=1.0)) is True
        assert len(await mem.neighbourhood_of(T, R, "landmark l1")) == 4
    finally:
        tick_task.cancel()
        await mem.aclose()
    await mem.aclose()  # idempotent
    assert not any(t.name.startswith("aw-memory") for t in threading.enumerate())
    with pytest.raises(RuntimeError, match="closed"):
        await mem.count()
    # the worker closed the connection it created; the data is on disk
    with ExperienceMemory(db) as m:
        assert len(m) == 4


async def test_async_from_config_in_memory() -> None:
    mem = await AsyncExperienceMemory.from_config(AgentConfig())
    try:
        assert await mem.append(
            task=T,
            role=R,
            uav="u1",
            episode=1,
            round=0,
            state_text="s",
            skill="a",
            invocation="a()",
        )
        assert await mem.count() == 1
        assert await mem.warm(T, R) == 1
    finally:
        await mem.aclose()


# ---------------------------------------------------------------- benchmark entry point


def test_bench_runs_and_prints_one_json_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert bench.main(["--records", "150", "--queries", "5"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    result = json.loads(out[0])
    assert result["records"] == 150
    assert {"p50_ms", "p99_ms", "fill_s", "db_bytes"} <= result.keys()
    assert result["db_bytes"] > 0
    assert result["transactions"] == "per episode"


def test_bench_per_write_and_bad_counts(capsys: pytest.CaptureFixture[str]) -> None:
    """``--per-write`` commits each write alone and stores the same records; a count
    below 1 is a usage error (exit 2, one line), not a traceback."""
    assert bench.main(["--records", "80", "--queries", "3", "--per-write"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert (result["records"], result["transactions"]) == (80, "per write")
    for argv in (["--records", "0"], ["--queries", "-1"]):
        assert bench.main(argv) == 2
        assert capsys.readouterr().err == (
            "bench memory: --records and --queries must be at least 1\n"
        )


def test_bench_fill_stores_the_same_records_batched_or_not(tmp_path: Path) -> None:
    """One transaction per episode is only faster: the rows and returns are those of one
    transaction per write."""
    import random

    rows = []
    for per_write in (False, True):
        with ExperienceMemory(tmp_path / f"{per_write}.sqlite", run="r") as mem:
            bench.fill(mem, 100, random.Random(4), per_write=per_write)
            rows.append([(r.uav, r.episode, r.round, r.ret, r.final, r.state_text)
                         for r in mem.records(bench.TASK, bench.ROLE)])  # fmt: skip
    assert len(rows[0]) == 100
    assert rows[0] == rows[1]


def test_the_cli_passes_every_bench_memory_flag(capsys: pytest.CaptureFixture[str]) -> None:
    """``aeroweaver bench memory`` is the benchmark's own parser (docs/performance.md types
    ``--writer backlog --check-whole`` there); a flag it lacks is one line, exit 2."""
    from aeroweaver_edge.cli.main import main as cli

    argv = ["bench", "memory", "--records", "150", "--queries", "2", "--writer", "backlog"]
    assert cli([*argv, "--check-whole"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert (result["writer"], result["same_neighbourhood"]) == ("backlog", "2 of 2")
    with pytest.raises(SystemExit) as exit_:
        cli(["bench", "memory", "--bogus"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "unrecognized arguments: --bogus" in err
    assert len(err.strip().splitlines()) == 1


def test_bench_backlog_stores_peers_finalised_records(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--writer backlog`` stores peers' finalised records through ``store_peers``: every
    record is kept, final, with its discounted return; it does not mix with --per-write.
    ``--check-whole`` compares each neighbourhood with the whole-group selection."""
    import random

    with ExperienceMemory(tmp_path / "b.sqlite", run="me") as mem:
        bench.fill_backlog(mem, 100, random.Random(4))
        stored = mem.records(bench.TASK, bench.ROLE)
    assert len(stored) == 100
    assert all(r.final and r.origin in bench.UAVS for r in stored)
    by_trajectory: dict[tuple[str, int], list[StoredRecord]] = {}
    for r in stored:
        by_trajectory.setdefault((r.uav, r.episode), []).append(r)
    for records in by_trajectory.values():
        records.sort(key=lambda r: r.round)
        for i, r in enumerate(records):
            assert r.reward is not None
            assert r.ret is not None
            expected = sum(0.95**j * (x.reward or 0.0) for j, x in enumerate(records[i:]))
            assert r.ret == pytest.approx(expected)
    argv = ["--records", "150", "--queries", "3", "--writer", "backlog", "--check-whole"]
    assert bench.main(argv) == 0
    result = json.loads(capsys.readouterr().out)
    assert (result["records"], result["writer"]) == (150, "backlog")
    assert result["same_neighbourhood"] == "3 of 3"  # every peer is capped: a late joiner
    assert bench.main(["--records", "10", "--writer", "backlog", "--per-write"]) == 2
    assert capsys.readouterr().err == "bench memory: --per-write applies to --writer own only\n"


@pytest.mark.parametrize("finalised_only", [False, True])
def test_python_and_numpy_retrieval_select_the_same_neighbourhood(
    tmp_path: Path, finalised_only: bool
) -> None:
    """Small groups are scored in plain Python, large ones with numpy: same records, same
    order, same similarities, on states built to tie (small vocabulary) and with records
    that have no return yet."""
    import random

    rnd = random.Random(11)
    words = ["landmark L0", "landmark L1", "peer uav1", "peer uav2", "north", "east", "round"]
    mem = ExperienceMemory(tmp_path / "m.sqlite", neighbourhood=8, finalised_only=finalised_only)
    with mem:
        for t in range(300):
            state = " ".join(rnd.sample(words, rnd.randint(1, 4))) + f" {rnd.randint(0, 3)} m"
            mem.append(
                task=T, role=R, uav="u1", episode=t // 24, round=t % 24, state_text=state,
                skill=rnd.choice(["a", "b", "c"]), invocation="x()",
            )  # fmt: skip
            if rnd.random() < 0.8:
                mem.add_reward("u1", t // 24, t % 24, rnd.uniform(-1, 1), "test")
            if t % 24 == 23:
                mem.finalise("u1", t // 24)
        group = mem._group(T, R)
        for _ in range(60):
            query = tokenise(" ".join(rnd.sample(words, rnd.randint(0, 5))) + " 2 m")
            python = select_python(group, query, mem.neighbourhood, finalised_only)
            assert python == select_indexed(group, query, mem.neighbourhood, finalised_only)
