from __future__ import annotations

import math

from aeroweaver_edge.skills import SkillDocument, SkillRegistry
from commander.retrieval import BM25Retriever, document_text, rank, stem, tokenize


def _doc(name: str, description: str, tags: tuple[str, ...] = (), body: str = "") -> SkillDocument:
    return SkillDocument(name, description, tags, (), body)


DOCS = [
    _doc("pursue_target", "Chase a visible evader.", ("pursuit", "pursuer")),
    _doc("cover_landmark", "Fly over a landmark so it counts as covered.", ("coverage",)),
    _doc(
        "hold_position", "Hover where you are.", ("hold",), body="Use when pursuing is pointless."
    ),
]


def test_tokenizer_splits_identifiers_stems_and_drops_stop_words() -> None:
    assert tokenize("cover_landmark") == ["cov", "landmark"]
    assert tokenize("The pursuers are pursuing") == [stem("pursuer"), stem("pursue")]
    assert stem("pursuers") == stem("pursue") == stem("pursuing")
    assert stem("delivered") == stem("deliver") == stem("delivery")
    assert stem("formation") == stem("form")


def test_rank_orders_by_bm25_and_skips_zero_scores() -> None:
    hits = rank(DOCS, "chase the pursuer", k=3)
    assert [d.name for d, _ in hits] == ["pursue_target"]
    assert hits[0][1] > 0
    assert rank(DOCS, "zzz qqq", k=3) == []


def test_rank_respects_k_and_among() -> None:
    r = BM25Retriever(DOCS)
    assert len(r.rank("landmark chase hover", 2)) == 2
    assert [h.name for h in r.rank("landmark chase hover", among=["hold_position"])] == [
        "hold_position"
    ]


def test_body_is_optional() -> None:
    assert "pointless" not in document_text(DOCS[2])
    assert "pointless" in document_text(DOCS[2], include_body=True)
    assert BM25Retriever(DOCS).rank("pointless") == []
    assert [h.name for h in BM25Retriever(DOCS, include_body=True).rank("pointless")] == [
        "hold_position"
    ]


def test_idf_is_higher_for_rarer_terms() -> None:
    r = BM25Retriever(DOCS)
    assert r.idf("landmark") > 0
    assert math.isnan(r.idf("unknownword"))


def test_whole_library_ranks_the_obvious_skill_first(registry: SkillRegistry) -> None:
    r = BM25Retriever(registry.documents())
    assert r.rank("cover the landmarks", 1)[0].name == "cover_landmark"
    assert len(r.rank("cover the landmarks", 3)) == 3
