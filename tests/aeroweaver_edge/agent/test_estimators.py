"""Advantage estimators: parsing, the paper's arithmetic kept, equal-horizon returns
recomputed from the stored rewards (live, reopened, peers', both retrieval paths), and the
minimum-support remedy. Every memory lives on disk in tmp_path."""

from __future__ import annotations

import math
import random
from pathlib import Path

import pytest

from aeroweaver_edge.agent.estimators import (
    ENV_ESTIMATOR,
    PAPER,
    Estimator,
    HorizonBook,
    estimator_from_env,
)
from aeroweaver_edge.agent.memory import experience as memory_mod
from aeroweaver_edge.agent.memory.async_memory import AsyncExperienceMemory
from aeroweaver_edge.agent.memory.experience import ExperienceMemory
from aeroweaver_edge.config import AgentConfig
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.contracts.wire import ExperienceRecord, Header

T, R = "coverage", "searcher"
GAMMA = 0.9


def test_parse_names_and_round_trip() -> None:
    assert Estimator.parse("paper") == PAPER
    assert PAPER.is_paper
    assert Estimator.parse("horizon:3") == Estimator(horizon=3)
    assert Estimator.parse("support:4").name == "support:4"
    e = Estimator.parse(" support:4 , horizon:3 ")
    assert e == Estimator(3, 4)
    assert e.name == "horizon:3,support:4"
    assert Estimator.parse(e.name) == e
    assert Estimator.parse("paper,horizon:2").name == "horizon:2"


@pytest.mark.parametrize(
    "bad",
    [
        "",
        "pap",
        "horizon",
        "horizon:0",
        "horizon:x",
        "support:-1",
        "horizon:3,",
        "h:3",
        "scale:2",
        "shrink",
        "shrink:0",
        "centre",
    ],
)
def test_parse_refuses_with_one_line(bad: str) -> None:
    with pytest.raises(ValueError, match="estimator") as err:
        Estimator.parse(bad)
    assert "\n" not in str(err.value)
    assert "estimator" in str(err.value)


def test_from_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ENV_ESTIMATOR, raising=False)
    assert estimator_from_env() == PAPER
    monkeypatch.setenv(ENV_ESTIMATOR, "horizon:2")
    assert estimator_from_env() == Estimator(2)
    monkeypatch.setenv(ENV_ESTIMATOR, "horizon:zero")
    with pytest.raises(UserError, match="AEROWEAVER_ESTIMATOR: estimator 'horizon:zero'"):
        estimator_from_env()


def test_memory_from_config_reads_the_config_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """The override is applied where a config enters the program (agent.choices), so the
    memory a daemon opens follows its config, whatever the environment says."""
    import asyncio

    monkeypatch.setenv(ENV_ESTIMATOR, "support:3")
    m = ExperienceMemory.from_config(AgentConfig(estimator="horizon:2"))
    assert m.estimator == Estimator(2)
    m.close()

    async def go() -> Estimator:
        m = await AsyncExperienceMemory.from_config(AgentConfig(estimator="horizon:3,scale"))
        try:
            return m.sync.estimator
        finally:
            await m.aclose()

    assert asyncio.run(go()) == Estimator(3, scale=True)


def test_paper_arithmetic_unchanged() -> None:
    values = [1.0, -2.0, 0.5, 3.0, -1.25]
    skills = [0, 1, 0, 2, 1]
    a = PAPER.advantages(values, skills, {"x": 0, "y": 1, "z": 2, "unseen": -1})
    base = math.fsum(values) / len(values)
    assert a["x"] == math.fsum([1.0, 0.5]) / 2 - base
    assert a["y"] == math.fsum([-2.0, -1.25]) / 2 - base
    assert a["z"] == 3.0 - base
    assert a["unseen"] == 0.0


def test_support_floor_for_thin_and_unseen_skills() -> None:
    values = [1.0, 2.0, -1.0, -3.0, 10.0]
    skills = [0, 0, 1, 1, 2]  # skill 2 has one record: below support 2
    a = Estimator(None, 2).advantages(values, skills, {"x": 0, "y": 1, "thin": 2, "new": -1})
    base = math.fsum(values) / len(values)
    assert a["x"] == 1.5 - base
    assert a["y"] == -2.0 - base
    assert a["thin"] == a["new"] == a["y"]  # no promotion without evidence
    nothing = Estimator(None, 9).advantages(values, skills, {"x": 0})
    assert nothing == {"x": 0.0}


def test_shrink_and_scale_arithmetic() -> None:
    values = [1.0, 2.0, 3.0, 6.0]
    skills = [0, 0, 1, 2]
    wanted = {"a": 0, "b": 1, "c": 2, "new": -1}
    base = math.fsum(values) / len(values)
    sd = math.sqrt(math.fsum((v - base) ** 2 for v in values) / len(values))
    shrunk = Estimator(shrink=2).advantages(values, skills, wanted)
    assert shrunk["a"] == pytest.approx((1.5 - base) * 2 / 4)
    assert shrunk["b"] == pytest.approx((3.0 - base) * 1 / 3)
    assert shrunk["new"] == 0.0  # unseen: the neighbourhood's mean, as in the paper
    scaled = Estimator(scale=True).advantages(values, skills, wanted)
    assert scaled["c"] == pytest.approx((6.0 - base) / sd)
    assert scaled["new"] == 0.0
    # the push no longer depends on the reward scale
    tiny = Estimator(scale=True).advantages([v / 1000 for v in values], skills, wanted)
    assert tiny == pytest.approx(scaled)
    # a neighbourhood without spread says nothing, however small the float noise
    flat = Estimator(scale=True).advantages([1.0, 1.0 + 1e-12], [0, 1], {"a": 0, "b": 1})
    assert max(abs(x) for x in flat.values()) < 1e-8
    t = Estimator(tscore=True).advantages(values, skills, wanted)
    assert t["a"] == pytest.approx((1.5 - base) / sd * math.sqrt(2))  # two records
    assert t["b"] == pytest.approx(scaled["b"])  # one record: as scale
    with pytest.raises(ValueError, match="scale or tscore"):
        Estimator.parse("scale,tscore")
    e = Estimator.parse("scale,shrink:4,centre,horizon:3")
    assert e.name == "horizon:3,centre,shrink:4,scale"
    assert Estimator.parse(e.name) == e
    assert not e.is_paper


def g_h(rewards: dict[int, float], t: int, h: int) -> float:
    return math.fsum(GAMMA ** (u - t) * r for u, r in sorted(rewards.items()) if t <= u < t + h)


def test_book_any_delivery_order_and_replacement() -> None:
    rng = random.Random(5)
    rewards = {u: rng.uniform(-2, 2) for u in range(8)}
    book = HorizonBook(3, GAMMA)
    events: list[tuple[str, int]] = [("rec", t) for t in range(8)] + [("rew", u) for u in range(8)]
    rng.shuffle(events)
    added: list[int] = []
    for kind, x in events:
        if kind == "rec":
            book.added(len(added), ("run", "u1", 0, x))
            added.append(x)
        else:
            book.reward(("run", "u1", 0, x), rewards[x])
    book.reward(("run", "u1", 0, 4), 7.0)  # a corrected value replaces the old one
    rewards[4] = 7.0
    for i, t in enumerate(added):
        assert book.value(i) == g_h(rewards, t, 3)
        assert book.eligible(i, final=False) == (8 - t >= 3)
        assert book.eligible(i, final=True)


def test_book_eligibility_counts_rewards_at_or_after_the_round() -> None:
    book = HorizonBook(2, GAMMA)
    book.added(0, ("r", "u", 0, 5), [(4, 1.0)])  # an earlier reward does not count
    assert not book.eligible(0, final=True)
    book.reward(("r", "u", 0, 5), 2.0)
    assert not book.eligible(0, final=False)
    assert book.eligible(0, final=True)
    book.reward(("r", "u", 0, 9), 3.0)  # beyond the horizon: counts, adds nothing
    assert book.eligible(0, final=False)
    assert book.value(0) == 2.0


def fill(m: ExperienceMemory, rng: random.Random, *, episodes: int, rounds: int) -> None:
    """Trajectories with rewards delivered late (the previous round's at each decision)."""
    for ep in range(episodes):
        for rnd in range(rounds):
            skill = rng.choice(["cover", "explore", "hold_position"])
            state = f"landmark l{rng.randrange(3)} near {rng.randrange(4)} {skill[:2]}"
            m.append(
                task=T, role=R, uav="u1", episode=ep, round=rnd,
                state_text=state, skill=skill, invocation=f"{skill}()",
            )  # fmt: skip
            if rnd:
                m.add_reward("u1", ep, rnd - 1, rng.uniform(-3, 1), "test")
        if ep < episodes - 1:  # the last episode stays in flight
            m.add_reward("u1", ep, rounds - 1, rng.uniform(-3, 1), "test")
            m.finalise("u1", ep)


def recomputed(m: ExperienceMemory, h: int) -> dict[tuple[str, int, int], float | None]:
    """Every record's H-step value from the stored rows alone (None: not eligible)."""
    rows = m._db.execute("SELECT uav, episode, round, reward FROM rewards").fetchall()
    by_traj: dict[tuple[str, int], dict[int, float]] = {}
    for uav, ep, rnd, r in rows:
        by_traj.setdefault((uav, ep), {})[rnd] = r
    out: dict[tuple[str, int, int], float | None] = {}
    for rec in m.records(T, R):
        rw = by_traj.get((rec.uav, rec.episode), {})
        n = sum(1 for u in rw if u >= rec.round)
        ok = n >= h or (rec.final and n > 0)
        out[(rec.uav, rec.episode, rec.round)] = g_h(rw, rec.round, h) if ok else None
    return out


def test_horizon_memory_matches_recompute_live_reopened_and_numpy(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    h = 3
    est = Estimator(h)
    db = tmp_path / "m.sqlite"
    m = ExperienceMemory(db, gamma=GAMMA, neighbourhood=10_000, estimator=est)
    m.warm(T, R)  # the index exists before the writes: the live path is exercised
    fill(m, random.Random(1), episodes=3, rounds=10)
    expect = recomputed(m, h)
    assert any(v is None for v in expect.values())
    assert any(v is not None for v in expect.values())
    query = "landmark l1 near 2"
    live = {(n.key): n.ret for n in m.neighbourhood_of(T, R, query)}
    assert live == {k: v for k, v in expect.items() if v is not None}
    a_live = m.advantages(T, R, query, ["cover", "explore", "hold_position"])
    m.close()
    m2 = ExperienceMemory(db, gamma=GAMMA, neighbourhood=10_000, estimator=est)
    assert {n.key: n.ret for n in m2.neighbourhood_of(T, R, query)} == live
    assert m2.advantages(T, R, query, ["cover", "explore", "hold_position"]) == a_live
    m2._groups.clear()
    monkeypatch.setattr(memory_mod, "SMALL_GROUP", 1)  # the numpy path selects the same
    assert {n.key: n.ret for n in m2.neighbourhood_of(T, R, query)} == live
    assert m2.advantages(T, R, query, ["cover", "explore", "hold_position"]) == a_live
    m2.close()


def test_horizon_from_peer_records(tmp_path: Path) -> None:
    """A peer's finalised trajectory carries one reward per record: enough for G^H."""
    src = ExperienceMemory(tmp_path / "a.sqlite", gamma=GAMMA, run="peer")
    fill(src, random.Random(2), episodes=2, rounds=6)
    dst = ExperienceMemory(
        tmp_path / "b.sqlite", gamma=GAMMA, neighbourhood=1000, estimator=Estimator(2)
    )
    dst.warm(T, R)
    for i, rec in enumerate(src.export("u1", 0)):
        assert dst.ingest(rec.to_wire(Header(sender="u9", epoch=1, seq=i + 1, stamp=0.0)))
    expect = {k: v for k, v in recomputed(src, 2).items() if k[1] == 0}
    got = {n.key: n.ret for n in dst.neighbourhood_of(T, R, "landmark l0 near 1")}
    assert got == expect
    src.close()
    dst.close()


def test_paper_default_is_bit_identical_to_explicit_paper(tmp_path: Path) -> None:
    a = ExperienceMemory(tmp_path / "a.sqlite", gamma=GAMMA)
    b = ExperienceMemory(tmp_path / "b.sqlite", gamma=GAMMA, estimator=Estimator.parse("paper"))
    for m in (a, b):
        fill(m, random.Random(3), episodes=2, rounds=8)
    for q in ("landmark l0 near 1 co", "landmark l2 near 3 ho"):
        names = ["cover", "explore", "hold_position", "unseen"]
        assert a.advantages(T, R, q, names) == b.advantages(T, R, q, names)
        stored = {(x.uav, x.episode, x.round): x.ret for x in a.records(T, R)}
        assert all(n.ret == stored[n.key] for n in a.neighbourhood_of(T, R, q))
    a.close()
    b.close()


def test_unknown_record_reward_for_peer_update(tmp_path: Path) -> None:
    """An updated peer copy (in flight -> final with its reward) updates the book."""
    m = ExperienceMemory(tmp_path / "m.sqlite", gamma=GAMMA, estimator=Estimator(1))
    m.warm(T, R)
    fields: dict[str, object] = dict(
        task=T, role=R, uav="u9", episode=1, round=0, state_text="landmark l1",
        skill="cover", invocation="cover()", run="p",
    )  # fmt: skip
    m.ingest(ExperienceRecord(h=Header(sender="u9", epoch=1, seq=1, stamp=0.0), **fields))  # type: ignore[arg-type]
    assert m.neighbourhood_of(T, R, "landmark l1") == []
    final = {**fields, "reward": -2.0, "ret": -2.0, "final": True}
    m.ingest(ExperienceRecord(h=Header(sender="u9", epoch=1, seq=2, stamp=0.0), **final))  # type: ignore[arg-type]
    assert [n.ret for n in m.neighbourhood_of(T, R, "landmark l1")] == [-2.0]
    m.close()


def test_centre_subtracts_the_per_round_mean_of_the_group(tmp_path: Path) -> None:
    est = Estimator.parse("horizon:2,centre")
    assert est.name == "horizon:2,centre"
    with pytest.raises(ValueError, match="centre needs a horizon"):
        Estimator.parse("centre")
    m = ExperienceMemory(tmp_path / "m.sqlite", gamma=GAMMA, neighbourhood=10_000, estimator=est)
    fill(m, random.Random(4), episodes=3, rounds=8)
    expect = recomputed(m, 2)
    by_round: dict[int, list[float]] = {}
    for (_, _, rnd), v in expect.items():
        if v is not None:
            by_round.setdefault(rnd, []).append(v)
    got = {n.key: n.ret for n in m.neighbourhood_of(T, R, "landmark l1 near 2")}
    assert got
    for key, v in got.items():
        want = expect[key]
        assert want is not None
        assert v == pytest.approx(want - sum(by_round[key[2]]) / len(by_round[key[2]]), abs=1e-12)
    m.close()
