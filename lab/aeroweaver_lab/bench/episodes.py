"""Per-episode benchmark figures, computed from a run's trace (docs/traces.md).

Every number the benchmark reports per episode is a sum or a percentile over trace lines:
the UAVs' decisions (tokens, LLM calls, latency, hold cause) and, for a baseline, the
central node's calls of each round. ``check_against_summary`` confirms the trace adds up
to the run summary's totals, so a table cell can always be traced back to rounds.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from aeroweaver_edge.contracts.hold_reasons import HOLD_CAUSES


def read_trace(path: Path) -> list[dict[str, Any]]:
    """A trace's lines; ``.gz`` (the benchmark's archived form) is read decompressed."""
    if path.suffix == ".gz":
        import gzip

        with gzip.open(path, "rt", encoding="utf-8") as g:
            return [json.loads(line) for line in g if line.strip()]
    with path.open(encoding="utf-8") as f:
        return [json.loads(line) for line in f if line.strip()]


def _new(episode: int) -> dict[str, Any]:
    return {
        "episode": episode,
        "rounds": 0,
        "reason": None,
        "team_return": None,
        "decisions": 0,
        "holds": 0,
        "holds_by_cause": dict.fromkeys(HOLD_CAUSES, 0),
        "invalid": 0,
        "llm_calls": {"uavs": 0, "central": 0},
        "tokens": {
            "uavs": {"prompt": 0, "prompt_cached": 0, "completion": 0},
            "central": {"prompt": 0, "prompt_cached": 0, "completion": 0},
        },
        "latency_s": [],
        "central_rounds": 0,
        "central_invalid": 0,
        # HMAS-2: the UAVs' local reviews of the central plan, rounds that made the revision
        # call (only a disagreeing review buys one) and rounds where the revision changed the
        # plan for at least one UAV (0 of N: it chose as Centralized)
        "central_reviews": {"asked": 0, "agreed": 0, "disagreed": 0, "failed": 0},
        "central_revision_calls": 0,
        "central_revised_rounds": 0,
        "messages": {"sent": 0},
        # position bias: decisions where a label was picked among >= 2 options, and how
        # many of those picked the first option listed
        "picks": 0,
        "first_label_picks": 0,
    }


def episode_metrics(lines: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One dict per episode: return, decisions, holds by cause, invalid choices, LLM calls
    and tokens (UAVs' and central node's), and every decision's latency."""
    eps: dict[int, dict[str, Any]] = {}
    for row in lines:
        kind = row.get("type")
        if kind == "round":
            e = eps.setdefault(int(row["episode"]), _new(int(row["episode"])))
            e["rounds"] += 1
            e["messages"]["sent"] += len(row.get("messages", []))
            for d in row.get("decisions", {}).values():
                e["decisions"] += 1
                e["holds"] += bool(d.get("held"))
                cause = d.get("hold_cause")
                if cause in e["holds_by_cause"]:
                    e["holds_by_cause"][cause] += 1
                e["invalid"] += cause == "invalid_answer"
                e["llm_calls"]["uavs"] += int(d.get("llm_calls", 0))
                for k in ("prompt", "prompt_cached", "completion"):
                    e["tokens"]["uavs"][k] += int(d.get("tokens", {}).get(k, 0))
                e["latency_s"].append(float(d.get("latency_s", 0.0)))
                options = d.get("options") or []
                if d.get("label") is not None and len(options) >= 2:
                    e["picks"] += 1
                    first = str(options[0]).split(".", 1)[0]
                    e["first_label_picks"] += d["label"] == first
            central = row.get("central")
            if central:
                e["central_rounds"] += 1
                for c in central.get("calls", []):
                    e["llm_calls"]["central"] += int(c.get("requests", 0))
                    e["tokens"]["central"]["prompt"] += int(c.get("prompt", 0))
                    e["tokens"]["central"]["prompt_cached"] += int(c.get("cached", 0))
                    e["tokens"]["central"]["completion"] += int(c.get("completion", 0))
                    if c.get("stage") != "plan":
                        e["central_invalid"] += len(c.get("invalid", {}))
                reviews = central.get("reviews") or {}
                if reviews:
                    e["central_reviews"]["asked"] += len(reviews)
                    e["central_reviews"]["agreed"] += sum(
                        bool(r.get("agree")) for r in reviews.values() if isinstance(r, dict)
                    )
                    # only these buy the revision call; the rest gave no usable answer
                    e["central_reviews"]["disagreed"] += sum(
                        r.get("agree") is False for r in reviews.values() if isinstance(r, dict)
                    )
                    # a review whose LLM call failed reads as "no feedback" to the planner
                    e["central_reviews"]["failed"] += sum(
                        bool(r.get("error")) for r in reviews.values() if isinstance(r, dict)
                    )
                    e["central_revised_rounds"] += central.get("proposal") != central.get("final")
                e["central_revision_calls"] += any(
                    isinstance(c, dict) and c.get("stage") == "revise"
                    for c in central.get("calls") or []
                )
        elif kind == "episode_end":
            e = eps.setdefault(int(row["episode"]), _new(int(row["episode"])))
            e["team_return"] = row.get("team_return")
            e["reason"] = row.get("reason")
    out = []
    for ep in sorted(eps):
        e = eps[ep]
        t = e["tokens"]
        e["tokens_total"] = (
            sum(t["uavs"].values())
            - t["uavs"]["prompt_cached"]
            + sum(t["central"].values())
            - t["central"]["prompt_cached"]
        )
        e["llm_calls_total"] = e["llm_calls"]["uavs"] + e["llm_calls"]["central"]
        out.append(e)
    return out


def check_against_summary(episodes: list[dict[str, Any]], summary: Mapping[str, Any]) -> list[str]:
    """Differences between the trace's sums and the summary's totals (empty: they agree)."""
    problems = []
    total = sum(e["tokens_total"] for e in episodes)
    want = summary.get("tokens", {}).get("total", 0)
    if total != want:
        problems.append(f"tokens: trace {total} vs summary {want}")
    calls = sum(e["llm_calls_total"] for e in episodes)
    if calls != summary.get("llm_calls", 0):
        problems.append(f"llm calls: trace {calls} vs summary {summary.get('llm_calls')}")
    holds = sum(e["holds"] for e in episodes)
    if holds != summary.get("holds", 0):
        problems.append(f"holds: trace {holds} vs summary {summary.get('holds')}")
    for e, s in zip(episodes, summary.get("episodes", []), strict=False):
        a, b = e["team_return"], s.get("team_return")
        if (a is None) != (b is None) or (
            a is not None and b is not None and not math.isclose(a, b, abs_tol=1e-5)
        ):
            problems.append(f"episode {e['episode']} return: trace {a} vs summary {b}")
    return problems


__all__ = ["check_against_summary", "episode_metrics", "read_trace"]
