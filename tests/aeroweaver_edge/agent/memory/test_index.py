"""The neighbourhood selections of ``agent.memory_index`` against a brute-force top K.

Every selection (plain Python, the numpy scan, the pruned indexed one) must return exactly
the brute-force answer: the top K eligible records by Jaccard overlap > 0, best first, ties
to the newest, with the same float similarities. The data are random but built to tie
(small vocabularies, equal token-set sizes), with records that have no return yet, ended
trajectories, evicted records and groups that grow between queries; a selection that
loses or adds one neighbour fails here."""

from __future__ import annotations

import math
import random
from pathlib import Path

import pytest

from aeroweaver_edge.agent.estimators import Estimator, HorizonBook
from aeroweaver_edge.agent.memory import experience as memory_module
from aeroweaver_edge.agent.memory.experience import ExperienceMemory
from aeroweaver_edge.agent.memory.index import (
    Group,
    Selection,
    eligible,
    prepare,
    select_indexed,
    select_python,
    select_scan,
)
from aeroweaver_edge.agent.state_tokens import jaccard, tokenise
from aeroweaver_edge.contracts.wire import ExperienceRecord, Header

SELECTIONS = {"python": select_python, "scan": select_scan, "indexed": select_indexed}


def brute(
    group: Group, sets: list[frozenset[str]], query: frozenset[str], k: int, fin_only: bool
) -> Selection:
    """Every record scored on its own: the definition, with no index."""
    scored = []
    for i, tokens in enumerate(sets):
        if not eligible(group, i, fin_only) or not tokens & query:
            continue
        scored.append((jaccard(tokens, query), i))
    scored.sort(key=lambda x: (-x[0], -x[1]))
    return [i for _, i in scored[:k]], [s for s, _ in scored[:k]]


def random_group(
    rng: random.Random, n: int, vocab: list[str], *, book: HorizonBook | None = None
) -> tuple[Group, list[frozenset[str]]]:
    """``vocab[0]`` is in every record (an "everywhere" token), the rest with skewed
    frequencies so that some tokens are dense columns and some are rare."""
    group = Group(book)
    sets = []
    weights = [1.0 / (j + 1) for j in range(len(vocab) - 1)]
    for i in range(n):
        size = rng.randint(1, min(8, len(vocab) - 1))
        tokens = frozenset([vocab[0], *rng.choices(vocab[1:], weights, k=size)])
        ret = None if rng.random() < 0.2 else rng.choice([-1.0, 0.0, 0.5])
        key = ("run", f"u{i % 3}", i // 30, i % 30)
        rewards = [] if ret is None else [(i % 30, ret)]
        group.add(key, i, tokens, rng.choice("abc"), ret, rng.random() < 0.4,
                  rng.choice(["", "", "p1", "p2"]), rewards)  # fmt: skip
        sets.append(tokens)
    return group, sets


def random_query(rng: random.Random, vocab: list[str]) -> frozenset[str]:
    extra = ["absent1", "absent2"] if rng.random() < 0.3 else []
    return frozenset(rng.sample(vocab, rng.randint(0, min(9, len(vocab)))) + extra)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("fin_only", [False, True])
def test_every_selection_is_the_brute_force_top_k(seed: int, fin_only: bool) -> None:
    rng = random.Random(seed)
    vocab = [f"t{j}" for j in range(rng.choice([4, 12, 40]))]
    book = HorizonBook(2, 0.9) if seed % 2 else None
    group, sets = random_group(rng, rng.choice([50, 700, 3000]), vocab, book=book)
    for i in rng.sample(range(len(group)), len(group) // 10):  # evictions
        group.remove(group.keys[i])
    for _ in range(40):
        query = random_query(rng, vocab)
        k = rng.choice([1, 3, 32, 200])
        want = brute(group, sets, query, k, fin_only)
        for name, select in SELECTIONS.items():
            assert select(group, query, k, fin_only) == want, (name, sorted(query), k)


def test_many_exact_ties_keep_the_newest() -> None:
    """Identical token sets: every similarity ties, so the K newest eligible records win."""
    group = Group()
    same = frozenset({"a", "b", "c"})
    for i in range(5000):
        group.add(("r", "u", 0, i), i, same, "s", 1.0 if i % 7 else None, False)
    want = [i for i in range(4999, -1, -1) if i % 7][:32]
    for select in SELECTIONS.values():
        pos, sim = select(group, frozenset({"a", "b"}), 32, False)
        assert pos == want
        assert sim == [2 / 3] * 32


def test_dense_columns_follow_a_growing_group() -> None:
    """The indexed selection caches 0/1 columns of frequent tokens; records appended after
    a query (and records evicted meanwhile) must count at the next one."""
    rng = random.Random(5)
    vocab = [f"t{j}" for j in range(10)]
    group, sets = random_group(rng, 3000, vocab)
    queries = [random_query(rng, vocab) for _ in range(20)]
    for round_ in range(4):
        for query in queries:
            assert select_indexed(group, query, 32, False) == brute(group, sets, query, 32, False)
        more, more_sets = random_group(rng, 500, vocab)
        for i in range(len(more)):  # append: positions continue where the group ends
            group.add(("r2", str(round_), i, 0), len(group), more_sets[i], "a", more.ret[i], False)
            sets.append(more_sets[i])
        for i in rng.sample(range(len(group)), 50):
            group.remove(group.keys[i])
    assert group.dense  # the frequent tokens did use the cached columns


def test_prepared_columns_select_the_same() -> None:
    """``prepare`` (run when a large group is loaded) builds every frequent token's column
    up front; the selections are unchanged, also after the group grows."""
    rng = random.Random(8)
    vocab = [f"t{j}" for j in range(30)]
    group, sets = random_group(rng, 4000, vocab)
    assert prepare(group) == len(group.dense) > 0
    for i in range(4000, 4500):
        tokens = frozenset(rng.sample(vocab, 4))
        group.add(("r", "u", 9, i), i, tokens, "a", 1.0, True)
        sets.append(tokens)
    for _ in range(30):
        query = random_query(rng, vocab)
        assert select_indexed(group, query, 32, False) == brute(group, sets, query, 32, False)


def test_a_token_that_becomes_rare_drops_its_column() -> None:
    group = Group()
    for i in range(4000):
        group.add(("r", "u", 0, i), i, frozenset({"x", "early"} if i < 1000 else {"x", "y"}),
                  "s", 1.0, True)  # fmt: skip
    select_indexed(group, frozenset({"early", "y"}), 8, False)
    assert "early" in group.dense
    for i in range(4000, 40000):
        group.add(("r", "u", 0, i), i, frozenset({"x", "y"}), "s", 1.0, True)
    select_indexed(group, frozenset({"early", "y"}), 8, False)
    assert "early" not in group.dense  # now in 1/40 of the group: not worth n bytes


def _peer(sender: str, rnd: int, text: str, ret: float) -> ExperienceRecord:
    return ExperienceRecord(
        h=Header(sender=sender, epoch=1, seq=rnd + 1, stamp=0.0), task="coverage",
        role="searcher", uav=sender, episode=0, round=rnd, state_text=text, skill="s",
        invocation="s()", ret=ret, reward=ret, final=True, run="peer-run",
    )  # fmt: skip


def _text(rng: random.Random) -> str:
    words = ["landmark l1", "landmark l2", "peer uav2", "peer uav3", "north", "uncovered l3"]
    return " ".join(rng.sample(words, rng.randint(1, 4))) + f" dist {rng.randint(0, 40)} m"


@pytest.mark.parametrize("estimator", ["paper", "horizon:3"])
def test_memory_neighbourhood_is_brute_force_after_evictions(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, estimator: str
) -> None:
    """Through ExperienceMemory, on disk, with peers flooding over their caps while the
    index exists: the indexed neighbourhood (numpy from the first record) equals the
    brute-force top K over the rows the table still holds, and the advantages equal those
    of the plain-Python selection bit for bit."""
    monkeypatch.setattr(memory_module, "SMALL_GROUP", 0)
    rng = random.Random(3)
    m = ExperienceMemory(tmp_path / "m.sqlite3", max_records_per_sender=40, neighbourhood=16,
                         max_sender_share=1.0, estimator=Estimator.parse(estimator))  # fmt: skip
    for t in range(90):
        m.append(task="coverage", role="searcher", uav="me", episode=t // 24, round=t % 24,
                 state_text=_text(rng), skill=rng.choice(["a", "b"]), invocation="x()")  # fmt: skip
        if rng.random() < 0.8:
            m.add_reward("me", t // 24, t % 24, rng.uniform(-1, 1), "test")
        if t % 24 == 23:
            m.finalise("me", t // 24)
        if t == 10:
            m.warm("coverage", "searcher")  # the index exists before the floods
    for i in range(150):
        m.ingest(_peer(rng.choice(["p1", "p2"]), i, _text(rng), rng.uniform(-1, 1)))
    assert m.evicted > 0
    rows = {(r.run, r.uav, r.episode, r.round): r for r in m.records("coverage", "searcher")}
    for _ in range(30):
        state = _text(rng)
        query = tokenise(state)
        got = m.neighbourhood_of("coverage", "searcher", state)
        group = m._group("coverage", "searcher")
        live = [
            (jaccard(tokenise(rows[key].state_text), query), i)
            for key, i in group.pos.items()
            if eligible(group, i, False) and tokenise(rows[key].state_text) & query
        ]
        assert len(live) <= len(rows)
        live.sort(key=lambda x: (-x[0], -x[1]))
        assert [(n.run, *n.key) for n in got] == [group.keys[i] for _, i in live[:16]]
        assert all(math.isfinite(n.similarity) for n in got)
        fast = m.advantages("coverage", "searcher", state, ["a", "b", "s", "c"])
        monkeypatch.setattr(memory_module, "SMALL_GROUP", 10**9)
        assert m.advantages("coverage", "searcher", state, ["a", "b", "s", "c"]) == fast
        monkeypatch.setattr(memory_module, "SMALL_GROUP", 0)
    m.close()


@pytest.mark.parametrize("small_group", [0, 10**9])
@pytest.mark.parametrize("own_records", [0, 30])
def test_capped_neighbourhood_is_the_capped_walk_over_the_whole_order(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, small_group: int, own_records: int
) -> None:
    """Peers holding more than this daemon (all of them, for a late joiner) are capped to
    half of K. The selection widens its prefix of the best-first order only while the caps
    leave places open; it must equal the capped walk over the whole brute-force order,
    including when one peer owns every best match and the walk runs deep."""
    monkeypatch.setattr(memory_module, "SMALL_GROUP", small_group)
    rng = random.Random(11)
    k = 8
    m = ExperienceMemory(tmp_path / "m.sqlite3", neighbourhood=k, max_records_per_sender=10**6)
    for t in range(own_records):
        m.append(task="coverage", role="searcher", uav="me", episode=0, round=t,
                 state_text=_text(rng), skill="a", invocation="a()")  # fmt: skip
        m.add_reward("me", 0, t, rng.uniform(-1, 1), "test")
    m.finalise("me", 0)
    # p1 floods near-copies of the queries; p2 and p3 hold a few ordinary records.
    for i in range(600):
        m.ingest(_peer("p1", i, "landmark l1 peer uav2 north dist 7 m", rng.uniform(-1, 1)))
    for i in range(40):
        m.ingest(_peer(rng.choice(["p2", "p3"]), 1000 + i, _text(rng), rng.uniform(-1, 1)))
    rows = {(r.run, r.uav, r.episode, r.round): r for r in m.records("coverage", "searcher")}
    per_origin: dict[str, int] = {}
    for r in rows.values():
        per_origin[r.origin] = per_origin.get(r.origin, 0) + 1
    mine = per_origin.get("", 0)
    heavy = {o for o, n in per_origin.items() if o != "" and n > mine}
    assert "p1" in heavy
    cap = max(1, int(0.5 * k))
    for state in ["landmark l1 peer uav2 north dist 7 m"] + [_text(rng) for _ in range(20)]:
        query = tokenise(state)
        group = m._group("coverage", "searcher")
        order = sorted(
            (
                (jaccard(tokenise(rows[key].state_text), query), i, key)
                for key, i in group.pos.items()
                if tokenise(rows[key].state_text) & query
            ),
            key=lambda x: (-x[0], -x[1]),
        )
        expected: list[tuple[str, ...]] = []
        taken: dict[str, int] = {}
        for _, _, key in order:
            origin = rows[key].origin
            if origin in heavy:
                if taken.get(origin, 0) >= cap:
                    continue
                taken[origin] = taken.get(origin, 0) + 1
            expected.append(key)
            if len(expected) == k:
                break
        got = [(n.run, *n.key) for n in m.neighbourhood_of("coverage", "searcher", state)]
        assert got == expected
    m.close()
