"""Experience memory across runs, writers and failures: run identity, v1 migration,
concurrent writers, required memory, and kill -9 consistency. Real SQLite files on disk."""

from __future__ import annotations

import math
import multiprocessing
import sqlite3
from pathlib import Path
from typing import Any

import pytest

from aeroweaver_edge.agent.memory.async_memory import AsyncExperienceMemory
from aeroweaver_edge.agent.memory.experience import (
    LEGACY_RUN,
    SCHEMA_VERSION,
    ExperienceMemory,
    MemoryUnavailable,
    new_run_id,
)
from aeroweaver_edge.agent.memory.tools import check_file, memory_files, stats
from aeroweaver_edge.config import AgentConfig
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.contracts.wire import ExperienceRecord, Header
from aeroweaver_lab.bench import memory_kill

T, R = "coverage", "searcher"


def episode(m: ExperienceMemory, uav: str, ep: int, rewards: list[float], skill: str) -> None:
    """One trajectory the way the daemon writes it: decision, then last round's reward."""
    for rnd, reward in enumerate(rewards):
        assert m.append(
            task=T,
            role=R,
            uav=uav,
            episode=ep,
            round=rnd,
            state_text=f"landmark l{rnd}",
            skill=skill,
            invocation=f"{skill}()",
        )
        assert m.add_reward(uav, ep, rnd, reward, "sim")
    m.finalise(uav, ep)


def test_second_run_on_the_same_file_stores_everything_and_mixes_nothing(tmp_path: Path) -> None:
    """Issue 8: run 2 (episodes restart at 0) stored 0 decisions and overwrote run 1's rewards."""
    db = tmp_path / "uav0.sqlite3"
    with ExperienceMemory(db, gamma=0.5) as first:
        episode(first, "uav0", 0, [1.0, 2.0, 4.0], "cover")
        run1 = first.run
        before = [(r.round, r.reward, r.ret) for r in first.records(T, R)]
    with ExperienceMemory(db, gamma=0.5) as second:
        assert second.run != run1
        episode(second, "uav0", 0, [-8.0, -8.0, -8.0], "hold")
        rows = second.records(T, R)
        assert len(rows) == 6
        mine = [(r.round, r.reward, r.ret, r.skill) for r in rows if r.run == second.run]
        assert mine == [(0, -8.0, -14.0, "hold"), (1, -8.0, -12.0, "hold"), (2, -8.0, -8.0, "hold")]
        theirs = [(r.round, r.reward, r.ret) for r in rows if r.run == run1]
        assert theirs == before == [(0, 1.0, 3.0), (1, 2.0, 4.0), (2, 4.0, 4.0)]
        assert second.get("uav0", 0, 1, run=run1) is not None
        mine_1 = next(r for r in rows if r.run == second.run and r.round == 1)
        assert second.get("uav0", 0, 1) == mine_1
    assert check_file(db) == []


def test_a_reward_never_reaches_another_runs_decision(tmp_path: Path) -> None:
    db = tmp_path / "m.sqlite3"
    with ExperienceMemory(db, run="run-a") as a:
        a.append(
            task=T,
            role=R,
            uav="uav0",
            episode=0,
            round=0,
            state_text="s",
            skill="cover",
            invocation="cover()",
        )
    with ExperienceMemory(db, run="run-b") as b:
        assert b.add_reward("uav0", 0, 0, 5.0, "sim")  # run b has no decision there
        assert b.get("uav0", 0, 0) is None
        rec = b.get("uav0", 0, 0, run="run-a")
        assert rec is not None
        assert (rec.reward, rec.ret) == (None, None)
        # a decision of run b appended later still picks up run b's own reward
        assert b.append(
            task=T,
            role=R,
            uav="uav0",
            episode=0,
            round=0,
            state_text="s",
            skill="hold",
            invocation="hold()",
        )
        mine = b.get("uav0", 0, 0)
        assert mine is not None
        assert (mine.reward, mine.ret) == (5.0, 5.0)
    assert check_file(db) == []


def test_two_open_writers_interleave_without_key_errors(tmp_path: Path) -> None:
    """Two concurrent runs on one file, each with its index loaded (the KeyError of issue 8)."""
    db = tmp_path / "m.sqlite3"
    with ExperienceMemory(db, gamma=0.5) as a, ExperienceMemory(db, gamma=0.5) as b:
        for m in (a, b):
            m.warm(T, R)
        for rnd in range(4):
            for m, r in ((a, 1.0), (b, 2.0)):
                assert m.append(
                    task=T,
                    role=R,
                    uav="uav0",
                    episode=0,
                    round=rnd,
                    state_text=f"landmark l{rnd}",
                    skill="cover",
                    invocation="cover()",
                )
                assert m.add_reward("uav0", 0, rnd, r, "sim")
        assert a.finalise("uav0", 0) == 4
        assert b.finalise("uav0", 0) == 4
        assert [r.ret for r in a.export_final("uav0", 0)] == [1.875, 1.75, 1.5, 1.0]
        assert [r.ret for r in b.export_final("uav0", 0)] == [3.75, 3.5, 3.0, 2.0]
    with ExperienceMemory(db) as m:
        assert len(m) == 8
    assert check_file(db) == []


def _open_in_step(directory: str, files: int, barrier: Any) -> None:
    """One process of the race below: open file i when the other process does."""
    from aeroweaver_edge.agent.memory.store import Store

    for i in range(files):
        barrier.wait(timeout=30)  # a failed sibling breaks the barrier: no hang
        Store(Path(directory) / f"m{i}.sqlite3", gamma=0.5, required=True).db.close()


def test_two_processes_opening_a_fresh_file_at_once_both_get_it(tmp_path: Path) -> None:
    """SQLite answers the second WAL switch of a fresh file with SQLITE_BUSY at once,
    past the busy timeout (stop 27's CI failure: 30 of 120 such opens failed)."""
    ctx = multiprocessing.get_context("spawn")  # no fork of a process with live threads
    barrier = ctx.Barrier(2)
    procs = [ctx.Process(target=_open_in_step, args=(str(tmp_path), 60, barrier)) for _ in range(2)]
    for proc in procs:
        proc.start()
    for proc in procs:
        proc.join(timeout=120)
        if proc.is_alive():
            proc.kill()
    assert [proc.exitcode for proc in procs] == [0, 0]
    assert all(check_file(tmp_path / f"m{i}.sqlite3") == [] for i in range(60))


def test_shared_records_are_deduplicated_by_run(tmp_path: Path) -> None:
    def rec(run: str, seq: int, ret: float) -> ExperienceRecord:
        return ExperienceRecord(
            h=Header(sender="uav9", epoch=1, seq=seq, stamp=0.0),
            task=T, role=R, uav="uav9", episode=0, round=3, state_text="landmark l1",
            skill="cover", invocation="cover()", reward=ret, ret=ret, final=True, run=run,
        )  # fmt: skip

    with ExperienceMemory(tmp_path / "m.sqlite3") as m:
        assert m.ingest(rec("run-1", 1, 1.0))
        assert m.ingest(rec("run-2", 2, 2.0))  # same (uav, episode, round), another run
        assert not m.ingest(rec("run-1", 3, 1.0))  # a repeat of run 1's record
        assert sorted((r.run, r.ret) for r in m.records(T, R)) == [("run-1", 1.0), ("run-2", 2.0)]


V1_SCHEMA = """
CREATE TABLE schema_version (version INTEGER NOT NULL);
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL) WITHOUT ROWID;
CREATE TABLE records (
    seq INTEGER PRIMARY KEY AUTOINCREMENT, task TEXT NOT NULL, role TEXT NOT NULL,
    uav TEXT NOT NULL, episode INTEGER NOT NULL, round INTEGER NOT NULL,
    state_text TEXT NOT NULL, tokens TEXT NOT NULL, skill TEXT NOT NULL,
    invocation TEXT NOT NULL, reward REAL, ret REAL, final INTEGER NOT NULL DEFAULT 0,
    origin TEXT NOT NULL DEFAULT '', reward_source TEXT NOT NULL DEFAULT '',
    src_epoch INTEGER NOT NULL DEFAULT 0, src_seq INTEGER NOT NULL DEFAULT 0,
    created_at REAL NOT NULL, UNIQUE (uav, episode, round)
);
CREATE INDEX records_by_role ON records (task, role, seq);
CREATE TABLE rewards (
    uav TEXT NOT NULL, episode INTEGER NOT NULL, round INTEGER NOT NULL,
    reward REAL NOT NULL, source TEXT NOT NULL, PRIMARY KEY (uav, episode, round)
) WITHOUT ROWID;
INSERT INTO schema_version VALUES (1);
INSERT INTO meta VALUES ('tokenizer', '1'), ('gamma', '0.5');
"""


def make_v1(path: Path) -> None:
    conn = sqlite3.connect(path)
    conn.executescript(V1_SCHEMA)
    for rnd, (reward, ret) in enumerate([(1.0, 2.0), (2.0, 2.0)]):
        conn.execute(
            "INSERT INTO records (task, role, uav, episode, round, state_text, tokens, skill, "
            "invocation, reward, ret, final, created_at) VALUES (?, ?, 'uav0', 0, ?, ?, ?, "
            "'cover', 'cover()', ?, ?, 1, 0.0)",
            (T, R, rnd, f"landmark l{rnd}", f"l{rnd} landmark", reward, ret),
        )
        conn.execute("INSERT INTO rewards VALUES ('uav0', 0, ?, ?, 'sim')", (rnd, reward))
    conn.commit()
    conn.close()


def test_version_1_file_is_migrated_in_place(tmp_path: Path) -> None:
    db = tmp_path / "uav0.sqlite3"
    make_v1(db)
    assert stats([db])["files"][0]["schema_version"] == 1
    assert stats([db])["files"][0]["runs"] == [LEGACY_RUN]
    with ExperienceMemory(db, gamma=0.5) as m:
        assert m.migrated_from == 1
        assert m.quarantined is None
        old = m.records(T, R)
        assert [(r.run, r.round, r.reward, r.ret, r.final) for r in old] == [
            (LEGACY_RUN, 0, 1.0, 2.0, True),
            (LEGACY_RUN, 1, 2.0, 2.0, True),
        ]
        # the next run's episode 0 no longer collides with the migrated one
        episode(m, "uav0", 0, [3.0], "hold")
        assert len(m) == 3
        assert m.advantages(T, R, "landmark l0", ["cover", "hold"])["hold"] > 0
    conn = sqlite3.connect(db)
    assert conn.execute("SELECT version FROM schema_version").fetchall() == [(SCHEMA_VERSION,)]
    conn.close()
    with ExperienceMemory(db) as m:  # a second open does not migrate again
        assert m.migrated_from is None
        assert len(m) == 3
    assert check_file(db) == []


def test_newer_schema_is_refused_and_left_untouched(tmp_path: Path) -> None:
    db = tmp_path / "m.sqlite3"
    with ExperienceMemory(db) as m:
        m.append(
            task=T,
            role=R,
            uav="uav0",
            episode=0,
            round=0,
            state_text="s",
            skill="a",
            invocation="a()",
        )
    conn = sqlite3.connect(db)
    conn.execute("UPDATE schema_version SET version = ?", (SCHEMA_VERSION + 1,))
    conn.commit()
    conn.close()
    before = db.read_bytes()
    with pytest.raises(MemoryUnavailable, match="newer release") as info:
        ExperienceMemory(db, required=True)
    assert info.value.during == "open"
    with ExperienceMemory(db) as m:  # not required: flies on with RAM memory
        assert m.degraded is not None
        assert "newer release" in m.degraded
        assert m.quarantined is None
    assert db.read_bytes() == before
    assert not list(tmp_path.glob("*.corrupt-*"))


def test_required_memory_on_an_unusable_path_raises_at_open(tmp_path: Path) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    with pytest.raises(MemoryUnavailable, match="cannot be used") as info:
        ExperienceMemory(blocker / "uav0.sqlite3", required=True)
    assert info.value.during == "open"
    assert str(blocker) in str(info.value)


async def test_required_memory_from_config_raises_and_optional_falls_back(
    tmp_path: Path,
) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    path = str(blocker / "uav0.sqlite3")
    with pytest.raises(MemoryUnavailable):
        await AsyncExperienceMemory.from_config(AgentConfig(memory_path=path))
    mem = await AsyncExperienceMemory.from_config(
        AgentConfig(memory_path=path, memory_required=False, run_id="sim-run-1")
    )
    try:
        assert mem.sync.degraded is not None
        assert mem.run == "sim-run-1"
        assert await mem.append(
            task=T,
            role=R,
            uav="uav0",
            episode=0,
            round=0,
            state_text="s",
            skill="a",
            invocation="a()",
        )
    finally:
        await mem.aclose()


def test_required_memory_raises_on_a_failed_write(tmp_path: Path) -> None:
    with ExperienceMemory(tmp_path / "m.sqlite3", required=True) as m:
        m.append(
            task=T,
            role=R,
            uav="u1",
            episode=0,
            round=0,
            state_text="landmark l1",
            skill="a",
            invocation="a()",
        )
        pages = m._db.execute("PRAGMA page_count").fetchone()[0]
        m._db.execute(f"PRAGMA max_page_count = {pages}")  # the next new page is "disk full"
        big = "landmark " + "filler " * 4000
        with pytest.raises(MemoryUnavailable, match="append failed") as info:  # noqa: PT012
            for t in range(1, 40):
                m.append(
                    task=T,
                    role=R,
                    uav="u1",
                    episode=0,
                    round=t,
                    state_text=big + str(t),
                    skill="b",
                    invocation="b()",
                )
        assert info.value.during == "write"
        assert m.write_errors == 1
        # retrieval stays advisory: it still answers
        assert m.advantages(T, R, "landmark l1", ["a"]) == {"a": 0.0}


def test_a_failed_peer_ingest_is_dropped_even_when_memory_is_required(tmp_path: Path) -> None:
    """Losing a peer's copy loses none of our own records: it never stops the daemon."""
    with ExperienceMemory(tmp_path / "m.sqlite3", required=True) as m:
        pages = m._db.execute("PRAGMA page_count").fetchone()[0]
        m._db.execute(f"PRAGMA max_page_count = {pages}")
        results = [
            m.ingest(
                ExperienceRecord(
                    h=Header(sender="uav9", epoch=1, seq=i + 1, stamp=0.0),
                    task=T,
                    role=R,
                    uav="uav9",
                    episode=0,
                    round=i,
                    state_text=f"x{i} " * 1000,
                    skill="cover",
                    invocation="cover()",
                    run="peer",
                )
            )
            for i in range(20)
        ]  # no MemoryUnavailable raised
        assert results.count(False) == m.write_errors > 0


def test_run_ids_are_unique_and_validated() -> None:
    assert len({new_run_id() for _ in range(100)}) == 100
    assert AgentConfig(run_id="20260101T000000-abcd1234").run_id is not None
    with pytest.raises(ValueError, match="run id"):
        AgentConfig(run_id="a/b")


# ---------------------------------------------------------------- memory_tools


def test_stats_counts_by_task_and_role(tmp_path: Path) -> None:
    with ExperienceMemory(tmp_path / "uav0.sqlite3") as a:
        episode(a, "uav0", 0, [1.0, 1.0], "cover")
        a.append(
            task=T,
            role="speaker",
            uav="uav0",
            episode=1,
            round=0,
            state_text="s",
            skill="talk",
            invocation="talk()",
        )
    with ExperienceMemory(tmp_path / "uav1.sqlite3") as b:
        episode(b, "uav1", 0, [1.0], "cover")
        b.append(
            task="pursuit",
            role="chaser",
            uav="uav1",
            episode=0,
            round=5,
            state_text="s",
            skill="chase",
            invocation="chase()",
        )
    (tmp_path / "notes.txt").write_text("not a memory")
    files = memory_files(tmp_path)
    assert [f.name for f in files] == ["uav0.sqlite3", "uav1.sqlite3"]
    got = stats(files)
    assert got["records"] == 5
    assert got["by_task"] == {"coverage": {"searcher": 3, "speaker": 1}, "pursuit": {"chaser": 1}}
    counts = (got["rewards"], got["rewarded_records"], got["final_records"], got["runs"])
    assert counts == (3, 3, 3, 2)


def test_memory_files_of_a_missing_or_empty_dir_is_a_user_error(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="does not exist"):
        memory_files(tmp_path / "nope")
    with pytest.raises(UserError, match="no experience-memory file"):
        memory_files(tmp_path)


def test_check_finds_a_reward_on_the_wrong_decision(tmp_path: Path) -> None:
    db = tmp_path / "m.sqlite3"
    with ExperienceMemory(db, gamma=0.5) as m:
        episode(m, "uav0", 0, [1.0, 2.0], "cover")
    assert check_file(db) == []
    conn = sqlite3.connect(db)
    conn.execute("UPDATE rewards SET reward = 9.0 WHERE round = 1")  # mixed in from elsewhere
    conn.commit()
    conn.close()
    problems = check_file(db)
    assert len(problems) == 3  # round 1's reward, and both returns that include it
    assert sum("reward 2.0 but delivered 9.0" in p for p in problems) == 1
    assert sum("rewards give" in p for p in problems) == 2


def test_check_reports_a_corrupt_file(tmp_path: Path) -> None:
    db = tmp_path / "m.sqlite3"
    db.write_bytes(b"SQLite format 3\x00" + b"\xff" * 4000)
    problems = check_file(db)
    assert len(problems) == 1
    assert "DatabaseError" in problems[0] or "integrity" in problems[0]


# ---------------------------------------------------------------- kill -9


def test_lost_records_catches_a_missing_acknowledged_write(tmp_path: Path) -> None:
    """The kill test's oracle can fail: an acknowledged write that is not in the file."""
    db = tmp_path / "uav0.sqlite3"
    with ExperienceMemory(db, run="r1") as m:
        m.append(
            task=T,
            role=R,
            uav="uav0",
            episode=0,
            round=0,
            state_text="s",
            skill="cover",
            invocation="cover()",
        )
        m.add_reward("uav0", 0, 0, 1.5, "sim")
    acks = memory_kill.Acks(run="r1")
    for line in ("A uav0 0 0 cover", "R uav0 0 0 1.5"):
        acks.parse(line)
    assert memory_kill.lost_records(db, [acks]) == []
    acks.parse("A uav0 0 1 cover")
    acks.parse("R uav0 0 0 2.5")
    acks.parse("F uav0 0 1")
    lost = memory_kill.lost_records(db, [acks])
    assert len(lost) == 5, lost


@pytest.mark.slow
def test_kill_9_during_concurrent_writes_loses_nothing_acknowledged() -> None:
    """10 SIGKILLs (5 lives of 2 concurrent writers on one file) at random moments."""
    result = memory_kill.run(10, writers=2, max_life_s=0.3, seed=3)
    assert result["kills"] == 10
    assert result["killed_mid_write"] == 10
    assert result["integrity_failures"] == 0
    assert result["acknowledged_decisions"] > 0
    assert result["records_lost"] == 0, result["lost_examples"]
    assert result["consistency_problems"] == 0, result["problem_examples"]
    assert result["quarantined"] == 0
    assert 0 <= result["records_in_flight"] <= 10
    assert not math.isnan(result["wall_s"])


def _peer_record(i: int, text: str) -> ExperienceRecord:
    return ExperienceRecord(
        h=Header(sender="uav9", epoch=1, seq=i + 1, stamp=0.0), task=T, role=R, uav="uav9",
        episode=0, round=i, state_text=text, skill="cover", invocation="cover()", ret=1.0,
        reward=1.0, final=True, run="peer",
    )  # fmt: skip


def test_a_batch_commits_whole_and_matches_single_writes(tmp_path: Path) -> None:
    """A batch stores what the same writes store one transaction each (rows and returns),
    and another connection sees none of it until the block ends."""
    path = tmp_path / "a.sqlite3"
    with (
        ExperienceMemory(path, run="r") as batched,
        ExperienceMemory(tmp_path / "b.sqlite3", run="r") as single,
    ):
        with batched.batch():
            episode(batched, "u1", 0, [1.0, -0.5, 2.0], "a")
            assert batched.ingest_many([_peer_record(i, f"landmark l{i}") for i in range(3)]) == 3
            other = sqlite3.connect(path)
            assert other.execute("SELECT count(*) FROM records").fetchone()[0] == 0
            other.close()
        episode(single, "u1", 0, [1.0, -0.5, 2.0], "a")
        for i in range(3):
            single.ingest(_peer_record(i, f"landmark l{i}"))
        assert [(r.uav, r.round, r.ret, r.final) for r in batched.records(T, R)] == [
            (r.uav, r.round, r.ret, r.final) for r in single.records(T, R)
        ]
        assert batched.advantages(T, R, "landmark l1", ["a", "cover"]) == single.advantages(
            T, R, "landmark l1", ["a", "cover"]
        )


def test_a_failed_batch_rolls_back_whole(tmp_path: Path) -> None:
    """Disk full inside a batch: nothing of the block stays, the index forgets it too, the
    error counts once; a required memory stops for its own writes, and a peers' batch
    (``ingest_many``, a round's intake ``store_peers``) is dropped without stopping it."""
    with ExperienceMemory(tmp_path / "m.sqlite3", required=True, run="r") as m:
        episode(m, "u1", 0, [1.0], "a")
        m.warm(T, R)
        pages = m._db.execute("PRAGMA page_count").fetchone()[0]
        m._db.execute(f"PRAGMA max_page_count = {pages}")
        big = "landmark " + "filler " * 4000
        peers = [_peer_record(i, f"landmark {i} " + "filler " * 500) for i in range(60)]
        assert m.ingest_many(peers) == 0
        assert m.write_errors == 1
        assert m.store_peers([(p, False) for p in peers]) == 0
        assert m.write_errors == 2

        def fill() -> None:
            with m.batch():
                for t in range(1, 40):
                    m.append(task=T, role=R, uav="u1", episode=0, round=t,
                             state_text=big + str(t), skill="b", invocation="b()")  # fmt: skip

        with pytest.raises(MemoryUnavailable, match="batch failed"):
            fill()
        assert m.write_errors == 3
        assert [r.round for r in m.records(T, R)] == [0]
        assert [n.key for n in m.neighbourhood_of(T, R, "landmark")] == [("u1", 0, 0)]


async def test_async_ingest_many_runs_in_the_memory_thread(tmp_path: Path) -> None:
    mem = await AsyncExperienceMemory.open(tmp_path / "m.sqlite3")
    try:
        records = (_peer_record(i, f"landmark l{i}") for i in range(5))  # a generator
        assert await mem.ingest_many(records) == 5
        assert await mem.ingest_many([_peer_record(0, "landmark l0")]) == 0  # same version
        assert await mem.count() == 5
        more = ((_peer_record(i, f"landmark l{i}"), False) for i in range(5, 8))
        assert await mem.store_peers(more) == 3  # a generator, one round's intake
        assert await mem.count() == 8
    finally:
        await mem.aclose()
