"""Bounded, attributable peer experience (issue 22): per-sender caps on stored records and
bytes with the sender's oldest evicted first, a cap on an over-represented sender's share
of a neighbourhood, per-sender counts in ``memory stats``, and the shared intake's
per-sender bound. Every memory lives on disk in tmp_path."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from aeroweaver_edge.agent.estimators import Estimator
from aeroweaver_edge.agent.memory import experience as memory_module
from aeroweaver_edge.agent.memory import tools as memory_tools
from aeroweaver_edge.agent.memory.experience import ExperienceMemory
from aeroweaver_edge.agent.memory.shared_intake import SharedIntake
from aeroweaver_edge.cli.main import main
from aeroweaver_edge.contracts.wire import ExperienceRecord, Header, Keys

T, R = "coverage", "searcher"
K = Keys("s")


def rec(sender: str, rnd: int, *, text: str = "landmark l1 near", ret: float = 1.0,
        skill: str = "cover_landmark", run: str = "r") -> ExperienceRecord:  # fmt: skip
    return ExperienceRecord(
        h=Header(sender=sender, epoch=1, seq=rnd + 1, stamp=0.0), task=T, role=R, uav=sender,
        episode=0, round=rnd, state_text=text, skill=skill, invocation=f"{skill}()",
        ret=ret, reward=ret, final=True, run=run,
    )  # fmt: skip


def own(m: ExperienceMemory, rnd: int, text: str, skill: str, ret: float) -> None:
    m.append(task=T, role=R, uav="me", episode=0, round=rnd, state_text=text, skill=skill,
             invocation=f"{skill}()")  # fmt: skip
    m.add_reward("me", 0, rnd, ret, "test")


def senders(m: ExperienceMemory) -> dict[str, int]:
    out: dict[str, int] = {}
    for r in m.records(T, R):
        out[r.origin or r.uav] = out.get(r.origin or r.uav, 0) + 1
    return out


def test_a_sender_is_capped_and_loses_its_oldest_first(tmp_path: Path) -> None:
    m = ExperienceMemory(tmp_path / "m.sqlite3", max_records_per_sender=50)
    own(m, 0, "landmark l1", "hold_position", 0.0)
    for i in range(10):
        assert m.ingest(rec("honest", i))
    for i in range(300):
        assert m.ingest(rec("evil", i, run=f"evil-{i // 100}"))
    held = senders(m)
    assert held["me"] == 1
    assert held["honest"] == 10
    assert 50 - 50 // 8 <= held["evil"] <= 50  # evicted down to 7/8 of the cap at a time
    kept = sorted(r.round for r in m.records(T, R) if r.origin == "evil")
    assert kept == list(range(300 - held["evil"], 300))  # the newest: oldest evicted first
    assert m.evicted == 300 - held["evil"]
    m.close()
    again = ExperienceMemory(tmp_path / "m.sqlite3", max_records_per_sender=50)  # reopened
    for i in range(300, 400):
        assert again.ingest(rec("evil", i))
    assert senders(again)["evil"] <= 50
    again.close()


def test_bytes_per_sender_are_capped_too(tmp_path: Path) -> None:
    m = ExperienceMemory(tmp_path / "m.sqlite3", max_bytes_per_sender=4000)
    for i in range(100):
        m.ingest(rec("evil", i, text=f"word{i} " * 20))
    stats = memory_tools.stats([tmp_path / "m.sqlite3"])
    assert 0 < stats["by_sender"]["evil"]["bytes"] <= 4000
    assert stats["by_sender"]["evil"]["records"] < 100
    huge = rec("evil", 1000, text="x" * 4001)
    assert not m.ingest(huge)  # larger than the whole cap: refused, nothing evicted for it
    m.close()


@pytest.mark.parametrize("small_group", [2048, 0], ids=["python", "numpy"])
@pytest.mark.parametrize("estimator", ["paper", "horizon:3", "horizon:3,centre"])
def test_evicted_records_leave_the_neighbourhood(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, estimator: str, small_group: int
) -> None:
    """Under every estimator and both selection paths: the horizon estimators keep their
    own per-record book, and an evicted position must not stay eligible through it. (No
    share cap here: it would hide the evicted records behind the sender's newest ones.)"""
    monkeypatch.setattr(memory_module, "SMALL_GROUP", small_group)
    m = ExperienceMemory(
        tmp_path / "m.sqlite3", max_records_per_sender=5, neighbourhood=8,
        max_sender_share=1.0, estimator=Estimator.parse(estimator),
    )  # fmt: skip
    own(m, 0, "landmark l1 near", "hold_position", 0.0)
    m.warm(T, R)  # the index exists before the flood: eviction keeps it in step
    for i in range(40):
        m.ingest(rec("evil", i, ret=100.0))
    near = m.neighbourhood_of(T, R, "landmark l1 near")
    evil = [n for n in near if n.key[0] == "evil"]
    assert 1 <= len(evil) <= 5
    assert {n.key[2] for n in evil} <= set(range(35, 40))  # only the newest are left
    m.close()


def test_an_over_represented_peer_gets_at_most_half_the_neighbourhood(tmp_path: Path) -> None:
    m = ExperienceMemory(tmp_path / "m.sqlite3", neighbourhood=8)
    for i in range(4):
        own(m, i, f"landmark l{i} far", "cover_landmark", 1.0)
    for i in range(4):
        m.ingest(rec("honest", i, text=f"landmark l{i} far"))
    for i in range(40):  # identical to the query: the best possible matches
        m.ingest(rec("evil", i, text="landmark l9 query", skill="hold_position", ret=100.0))
    near = m.neighbourhood_of(T, R, "landmark l9 query")
    assert len(near) == 8
    assert sum(1 for n in near if n.key[0] == "evil") == 4  # cap: half of K
    # The others' places are the next-best records of others (own and the honest peer).
    assert {n.key[0] for n in near} - {"evil"} <= {"me", "honest"}
    uncapped = ExperienceMemory(tmp_path / "m.sqlite3", neighbourhood=8, max_sender_share=1.0)
    assert all(n.key[0] == "evil" for n in uncapped.neighbourhood_of(T, R, "landmark l9 query"))
    uncapped.close()
    m.close()


def test_balanced_peers_are_not_capped(tmp_path: Path) -> None:
    """An honest same-role peer holds no more than this daemon: the selection is exactly
    the uncapped one (honest decisions do not change)."""
    capped = ExperienceMemory(tmp_path / "a.sqlite3", neighbourhood=8, run="r0")
    plain = ExperienceMemory(tmp_path / "b.sqlite3", neighbourhood=8, max_sender_share=1.0,
                             run="r0")  # fmt: skip
    for m in (capped, plain):
        for i in range(12):
            own(m, i, f"landmark l{i % 3} far", "cover_landmark", float(i))
        for i in range(12):
            m.ingest(rec("peer", i, text="landmark l9 query", ret=float(-i)))
    for q in ("landmark l9 query", "landmark l1 far", "landmark l2 query"):
        assert capped.neighbourhood_of(T, R, q) == plain.neighbourhood_of(T, R, q)
    # ... while one more peer record would make it over-represented, and capped:
    for m in (capped, plain):
        m.ingest(rec("peer", 12, text="landmark l9 query", ret=-12.0))
    q = "landmark l9 query"
    assert capped.neighbourhood_of(T, R, q) != plain.neighbourhood_of(T, R, q)
    capped.close()
    plain.close()


def test_memory_stats_counts_records_and_bytes_per_sender(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "uav0.sqlite3"
    m = ExperienceMemory(path)
    own(m, 0, "landmark l1", "hold_position", 0.0)
    for i in range(3):
        m.ingest(rec("uav1", i))
    m.close()
    assert main(["memory", "stats", str(tmp_path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["by_sender"]["uav1"]["records"] == 3
    assert data["by_sender"]["uav1"]["shared"] == 3
    assert data["by_sender"]["me"] == {"records": 1, "bytes": data["by_sender"]["me"]["bytes"],
                                       "shared": 0}  # fmt: skip
    assert data["files"][0]["by_sender"]["uav1"]["bytes"] > 0
    assert main(["memory", "stats", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "uav0.sqlite3: me 1 (" in out
    assert "uav1 3 (" in out
    assert ", shared)" in out


def test_shared_intake_bounds_pending_records_per_sender() -> None:
    intake = SharedIntake("me", max_per_sender=5)
    taken = [intake.offer(K.experience("evil"), rec("evil", i), R) for i in range(20)]
    assert sum(taken) == 5
    assert intake.refused == 15
    assert intake.offer(K.experience("honest"), rec("honest", 0), R)  # others unaffected
