"""Tokenise a state description for the Jaccard retrieval of experience memory (DESIGN §5).

Two states are "alike" when they share many tokens, so the tokeniser decides what alike
means. The rules, in order:

* lower-case; split into words and numbers, everything else separates tokens. A word
  starts with a letter and may hold digits and inner ``_``/``-`` (``[a-z][a-z0-9]*`` joined
  by ``_`` or ``-``), so identifiers such as ``l2``, ``uav3`` or ``uav-3`` stay whole;
* words in a small stop list (articles, prepositions, units) are dropped: they occur in
  every state and would only inflate every union;
* a number never stands alone. It becomes ``<context>~<bucket>`` where the context is the
  last kept word before it (``landmark l2 at (-28.0, 24.1) dist 36.7 m`` gives ``l2~-20``,
  ``l2~20`` and ``dist~30``), so "36 m from L2" and "36 m from a peer" do not match,
  while 24.1 and 27.9 from the same thing do;
* buckets are signed and roughly geometric (edges 1, 2, 3, 5, 7, 10, 15, 20, 30, 50, 70,
  100, 150, 200, 300, 500, 700, 1000): one ~1.5x step per bucket keeps ±20 % distance
  differences together, near distances stay fine (the 3 m completion radius is an edge)
  and anything below 1 is ``0``. A ``-`` counts as a sign only when it does not follow a
  letter or digit (``(-4.5`` and ``x=-4.5`` are negative);
* the result is a set: Jaccard overlap ignores multiplicity.

Bump ``TOKENIZER_VERSION`` whenever these rules change: stored token sets are rebuilt
from the stored state text when the version differs.
"""

from __future__ import annotations

import re
from bisect import bisect_right
from functools import lru_cache
from typing import Final

TOKENIZER_VERSION: Final = 1

# A word, or a number with its sign: a ``-`` is a sign when no letter or digit precedes it
# (``[^\W_]`` is exactly ``str.isalnum``). Three groups, so ``findall`` yields plain tuples.
_SCAN = re.compile(r"([a-z][a-z0-9]*(?:[_-][a-z0-9]+)*)|((?<![^\W_])-)?(\d+(?:\.\d+)?)")

_EDGES: Final = (1, 2, 3, 5, 7, 10, 15, 20, 30, 50, 70, 100, 150, 200, 300, 500, 700, 1000)

_ARTICLES_ETC = "a an the of to and or is are at in on for from by with as it its this that be"
_UNITS = "m s ms mps deg rad km h"  # trail numbers; must not become the next number's context
STOPWORDS: Final = frozenset(_ARTICLES_ETC.split()) | frozenset(_UNITS.split())


def bucket(value: float) -> str:
    """Signed geometric bucket label: the lower edge of the band ``|value|`` falls in."""
    magnitude = abs(value)
    if magnitude < _EDGES[0]:
        return "0"
    label = str(_EDGES[bisect_right(_EDGES, magnitude) - 1])
    return "-" + label if value < 0 else label


@lru_cache(maxsize=4096)  # bounded: state text can come from peers
def _number_label(number: str, negative: bool) -> str:
    value = float(number)
    return bucket(-value if negative else value)


def tokenise(text: str) -> frozenset[str]:
    """The token set of a state description (rules in the module docstring). Every
    stored record and every retrieval tokenises, so this is the write path's hot loop."""
    out: set[str] = set()
    add = out.add
    context = ""
    for word, minus, number in _SCAN.findall(text.lower()):
        if word:
            if word not in STOPWORDS:
                add(word)
                context = word
        else:
            add(f"{context}~{_number_label(number, bool(minus))}")
    return frozenset(out)


def jaccard(a: frozenset[str], b: frozenset[str]) -> float:
    """Reference Jaccard overlap (the memory computes the same thing vectorised)."""
    if not a and not b:
        return 0.0
    inter = len(a & b)
    return inter / (len(a) + len(b) - inter)
