"""The tokeniser's fast scan gives exactly the token sets of its rules, written plainly."""

from __future__ import annotations

import random
import re

import pytest

from aeroweaver_edge.agent.state_tokens import STOPWORDS, bucket, tokenise

_WORD_OR_NUMBER = re.compile(r"[a-z][a-z0-9]*(?:[_-][a-z0-9]+)*|\d+(?:\.\d+)?")


def rules(text: str) -> frozenset[str]:
    """The module docstring's rules one token at a time (the implementation before the
    single-scan rewrite, kept as the reference)."""
    low = text.lower()
    out: set[str] = set()
    context = ""
    for match in _WORD_OR_NUMBER.finditer(low):
        tok = match.group()
        if tok[0].isalpha():
            if tok not in STOPWORDS:
                out.add(tok)
                context = tok
            continue
        value = float(tok)
        start = match.start()
        if start >= 1 and low[start - 1] == "-" and (start < 2 or not low[start - 2].isalnum()):
            value = -value
        out.add(f"{context}~{bucket(value)}")
    return frozenset(out)


@pytest.mark.parametrize(
    "text",
    [
        "landmark L2 at (-28.0, 24.1) dist 36.7 m",
        "x=-4.5 y-3 uav-3 5-3 --7 -0.4 é-3 ٣-2 _-5 ²-1 -12",
        "own pos (12.0, -70.0) vel (0.0, 0.0); round 3/24",
        "",
    ],
)
def test_known_texts(text: str) -> None:
    assert tokenise(text) == rules(text)


def test_random_texts_over_signs_separators_and_unicode() -> None:
    rng = random.Random(7)
    alphabet = "ab-_.0123456789 é٣²Z(),=x-\n"
    for _ in range(20_000):
        text = "".join(rng.choice(alphabet) for _ in range(rng.randint(0, 24)))
        assert tokenise(text) == rules(text), repr(text)
