"""Okapi BM25 over skill documents (DESIGN §7: names, descriptions, tags and aliases).

Written here (about 60 lines of numpy) rather than taken from a package: the corpus is a few
dozen short documents, the scoring must be deterministic and inspectable for the recall
study, and the tokenizer is the part that matters. The tokenizer lower-cases, splits on
anything that is not a letter or digit (so ``cover_landmark`` is ``cover landmark``), drops a
small stop-word list and strips common English suffixes so that ``pursuers``, ``pursue`` and
``pursuing`` meet. Including the prose body is optional (``include_body``); the recall study
measures both.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from aeroweaver_edge.skills import SkillDocument

_STOP_TEXT = """a an and are as at be been but by can do does each for from has have if in into
is it its itself may must no not of on once or our should so than that the their them then
there these they this those to too us was we were what when where which while who will with
you your i me my he she his her all any also just only own same such very about above after
again against before below between both during further here how more most other out over some
through under until up"""
STOP_WORDS = frozenset(_STOP_TEXT.split())
_SPLIT = re.compile(r"[^a-z0-9]+")
# Verb, noun and derivational endings, longest first; plurals are handled before them.
_ENDINGS = ("ation", "ition", "ing", "ion", "ate", "ed", "er", "or", "ly", "e", "y")


def stem(word: str) -> str:
    """A light suffix stripper: consistent more than correct (``covering`` -> ``cov``)."""
    if len(word) <= 3 or word.isdigit():
        return word
    if word.endswith("ies"):
        word = word[:-3] + "y"
    elif word.endswith("sses"):
        word = word[:-2]
    elif word.endswith("s") and not word.endswith(("ss", "us", "is")):
        word = word[:-1]
    for _ in range(2):  # "delivered" -> "deliver" -> "deliv", "deliver" -> "deliv"
        for suffix in _ENDINGS:
            if word.endswith(suffix) and len(word) - len(suffix) >= 3:
                word = word[: -len(suffix)]
                break
        else:
            break
    return word


def tokenize(text: str) -> list[str]:
    return [stem(t) for t in _SPLIT.split(text.lower()) if t and t not in STOP_WORDS]


def document_text(doc: SkillDocument, include_body: bool = False) -> str:
    """The fields retrieval reads; identifiers have their underscores split by the tokenizer."""
    parts = [doc.name, doc.description, " ".join(doc.tags), " ".join(doc.aliases)]
    if include_body:
        parts.append(doc.body)
    return "\n".join(parts)


@dataclass(frozen=True)
class Hit:
    doc: SkillDocument
    score: float

    @property
    def name(self) -> str:
        return self.doc.name


class BM25Index:
    """Okapi BM25 (Robertson et al.) with the non-negative Lucene IDF over plain texts."""

    def __init__(self, texts: Sequence[str], *, k1: float = 1.2, b: float = 0.75) -> None:
        self.k1, self.b = k1, b
        tokens = [tokenize(t) for t in texts]
        vocab = sorted({t for doc in tokens for t in doc})
        self._index = {t: i for i, t in enumerate(vocab)}
        tf = np.zeros((len(tokens), len(vocab)))
        for row, doc in enumerate(tokens):
            for term, n in Counter(doc).items():
                tf[row, self._index[term]] = n
        lengths = tf.sum(axis=1)
        avg = float(lengths.mean()) if len(tokens) else 0.0
        df = (tf > 0).sum(axis=0)
        n_docs = len(tokens)
        self._idf = np.log1p((n_docs - df + 0.5) / (df + 0.5))
        norm = k1 * (1.0 - b + b * lengths / avg) if avg else np.ones_like(lengths)
        # Precomputed term weights: score(q, d) = sum over q's terms of this matrix's column.
        self._weights = self._idf * tf * (k1 + 1.0) / (tf + norm[:, None])
        self.size = n_docs

    def scores(self, query: str) -> np.ndarray:
        """One BM25 score per document; each distinct query term counts once."""
        cols = sorted({self._index[t] for t in tokenize(query) if t in self._index})
        if not cols:
            return np.zeros(self.size)
        out: np.ndarray = self._weights[:, cols].sum(axis=1)
        return out

    def idf(self, term: str) -> float:
        i = self._index.get(stem(term.lower()))
        return float(self._idf[i]) if i is not None else math.nan


class BM25Retriever:
    """BM25 over skill documents (names, descriptions, tags, aliases; optionally the body)."""

    def __init__(
        self,
        docs: Iterable[SkillDocument],
        *,
        include_body: bool = False,
        k1: float = 1.2,
        b: float = 0.75,
    ) -> None:
        self.docs: tuple[SkillDocument, ...] = tuple(docs)
        self.include_body = include_body
        self.k1, self.b = k1, b
        self._bm25 = BM25Index([document_text(d, include_body) for d in self.docs], k1=k1, b=b)

    def scores(self, query: str) -> np.ndarray:
        """One BM25 score per document; each distinct query term counts once."""
        return self._bm25.scores(query)

    def rank(
        self, query: str, k: int | None = None, *, among: Sequence[str] | None = None
    ) -> list[Hit]:
        """The best ``k`` documents with a positive score, best first (ties: catalogue order).

        ``among`` restricts the ranking to the named skills (a task-level catalogue) while
        keeping the whole library's IDF.
        """
        scores = self.scores(query)
        allowed = None if among is None else set(among)
        order = sorted(range(len(self.docs)), key=lambda i: (-scores[i], i))
        hits = [
            Hit(self.docs[i], float(scores[i]))
            for i in order
            if scores[i] > 0 and (allowed is None or self.docs[i].name in allowed)
        ]
        return hits if k is None else hits[:k]

    def idf(self, term: str) -> float:
        return self._bm25.idf(term)


def rank(
    docs: Iterable[SkillDocument], query: str, k: int, *, include_body: bool = False
) -> list[tuple[SkillDocument, float]]:
    """One-shot ``rank(query, k)`` over ``docs`` as (skill, score) pairs."""
    return [(h.doc, h.score) for h in BM25Retriever(docs, include_body=include_body).rank(query, k)]


__all__ = [
    "STOP_WORDS",
    "BM25Index",
    "BM25Retriever",
    "Hit",
    "document_text",
    "rank",
    "stem",
    "tokenize",
]
