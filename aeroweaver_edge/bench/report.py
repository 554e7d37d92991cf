"""Tables and CSV from a benchmark directory's finished cells (``bench.runner``).

Everything is recomputed from the cells' per-episode figures (which come from the traces):
return mean and sample SD over episodes (all seeds), tokens and LLM calls per episode
(UAVs' and central node's), decision latency p50/p95 over all decisions, uncached prompt
tokens per LLM call, invalid-choice rate (answers without a usable label / decisions) and
holds by cause. ``write_report`` writes ``results.csv``, ``table.md`` and the plots.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aeroweaver_edge.bench.episodes import episode_metrics, read_trace
from aeroweaver_edge.hold_reasons import HOLD_CAUSES
from aeroweaver_edge.json_out import write_json_file

PAPER_K = {  # the paper's task scales K_t for relative ablation scores (Table 3)
    "coverage": 17.077,
    "pursuit_evasion": 17.606,
    "guided_navigation": 15.029,
    "private_communication": 15.969,
    "circular_formation": 16.801,
    "line_formation": 14.280,
    "world_communication": 35.217,
    "collection_delivery": 10.881,
    "goal_concealment": 13.505,
}
ABLATIONS = ("no_activation", "no_coordination", "beta0")


@dataclass
class CellStats:
    """One (task, condition): its episodes pooled over seeds."""

    task: str
    condition: str
    title: str
    seeds: list[int] = field(default_factory=list)
    returns: list[float] = field(default_factory=list)
    tokens: list[int] = field(default_factory=list)  # per episode, UAVs + central
    central_tokens: list[int] = field(default_factory=list)
    calls: list[int] = field(default_factory=list)
    latencies: list[float] = field(default_factory=list)
    decisions: int = 0
    invalid: int = 0
    holds: dict[str, int] = field(default_factory=lambda: dict.fromkeys(HOLD_CAUSES, 0))
    prompt: int = 0
    cached: int = 0
    model: str | None = None
    mismatches: list[str] = field(default_factory=list)
    central_rounds: int = 0
    reviews_asked: int = 0
    reviews_agreed: int = 0
    revised_rounds: int = 0

    @property
    def n(self) -> int:
        return len(self.returns)

    def mean(self, xs: Sequence[float]) -> float | None:
        return statistics.fmean(xs) if xs else None

    @property
    def sd(self) -> float | None:
        return statistics.stdev(self.returns) if len(self.returns) > 1 else None

    def percentile(self, q: float) -> float | None:
        ys = sorted(self.latencies)
        if not ys:
            return None
        return ys[min(len(ys) - 1, round(q * (len(ys) - 1)))]

    @property
    def uncached_per_call(self) -> float | None:
        calls = sum(self.calls)
        return (self.prompt - self.cached) / calls if calls else None

    @property
    def uncached_per_decision(self) -> float | None:
        return (self.prompt - self.cached) / self.decisions if self.decisions else None

    @property
    def invalid_rate(self) -> float | None:
        return self.invalid / self.decisions if self.decisions else None

    def absorb(self, other: CellStats) -> None:
        """Pool another cell's episodes into this one (a condition over all tasks)."""
        self.seeds += other.seeds
        self.returns += other.returns
        self.tokens += other.tokens
        self.central_tokens += other.central_tokens
        self.calls += other.calls
        self.latencies += other.latencies
        self.decisions += other.decisions
        self.invalid += other.invalid
        for k, v in other.holds.items():
            self.holds[k] = self.holds.get(k, 0) + v
        self.prompt += other.prompt
        self.cached += other.cached
        self.model = self.model or other.model
        self.central_rounds += other.central_rounds
        self.reviews_asked += other.reviews_asked
        self.reviews_agreed += other.reviews_agreed
        self.revised_rounds += other.revised_rounds

    def figures(self) -> dict[str, Any]:
        """The table's figures as numbers (summary.json)."""

        def r(x: float | None, digits: int = 3) -> float | None:
            return None if x is None else round(x, digits)

        episodes = len(self.calls)
        return {
            "cells": len(self.seeds),
            "episodes": episodes,
            "return_mean": r(self.mean(self.returns)),
            "return_sd": r(self.sd),
            "tokens_per_episode": r(self.mean(self.tokens), 1),
            "central_tokens_per_episode": r(self.mean(self.central_tokens), 1),
            "llm_calls_per_episode": r(self.mean(self.calls), 2),
            "decisions": self.decisions,
            "latency_p50_s": r(self.percentile(0.5)),
            "latency_p95_s": r(self.percentile(0.95)),
            "uncached_prompt_per_call": r(self.uncached_per_call, 1),
            "uncached_prompt_per_decision": r(self.uncached_per_decision, 1),
            "invalid_rate": r(self.invalid_rate, 4),
            "holds_per_episode": {
                k: r(v / episodes, 2) for k, v in self.holds.items() if v and episodes
            },
            "model": self.model,
            "central_rounds": self.central_rounds,
            "reviews_agreed": self.reviews_agreed,
            "reviews_asked": self.reviews_asked,
            "revised_rounds": self.revised_rounds,
        }


def load_cells(out: Path) -> list[dict[str, Any]]:
    """The complete cells. A cell written before a per-episode figure existed gets its
    episodes recomputed from its trace (the source of every figure) when the trace is there."""
    cells = []
    for path in sorted((out / "runs").glob("*/*/seed*.json")):
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(data, dict) and data.get("bench", {}).get("complete"):
            eps = data.get("episodes") or []
            trace = out / str(data["bench"].get("trace", ""))
            if any("central_reviews" not in e for e in eps) and trace.is_file():
                with contextlib.suppress(OSError, ValueError):
                    data["episodes"] = episode_metrics(read_trace(trace))
            cells.append(data)
    return cells


def aggregate(cells: Iterable[dict[str, Any]]) -> dict[tuple[str, str], CellStats]:
    stats: dict[tuple[str, str], CellStats] = {}
    for data in cells:
        b = data["bench"]
        s = stats.setdefault(
            (b["task"], b["condition"]), CellStats(b["task"], b["condition"], b["title"])
        )
        s.seeds.append(b["seed"])
        s.model = data["summary"].get("model") or s.model
        s.mismatches += [f"seed {b['seed']}: {p}" for p in b.get("trace_check", [])]
        for e in data["episodes"]:
            if e["team_return"] is not None:
                s.returns.append(float(e["team_return"]))
            s.tokens.append(int(e["tokens_total"]))
            ct = e["tokens"]["central"]
            s.central_tokens.append(int(ct["prompt"] + ct["completion"]))
            s.calls.append(int(e["llm_calls_total"]))
            s.latencies += [float(x) for x in e["latency_s"]]
            s.decisions += int(e["decisions"])
            s.invalid += int(e["invalid"])
            for k, v in e["holds_by_cause"].items():
                s.holds[k] = s.holds.get(k, 0) + int(v)
            for side in ("uavs", "central"):
                s.prompt += int(e["tokens"][side]["prompt"])
                s.cached += int(e["tokens"][side]["prompt_cached"])
            s.central_rounds += int(e.get("central_rounds", 0))
            reviews = e.get("central_reviews", {})
            s.reviews_asked += int(reviews.get("asked", 0))
            s.reviews_agreed += int(reviews.get("agreed", 0))
            s.revised_rounds += int(e.get("central_revised_rounds", 0))
    return stats


RATIO_BASELINES = ("hmas2", "centralized")


def token_ratios(
    stats: dict[tuple[str, str], CellStats], tasks: Sequence[str]
) -> dict[str, dict[str, float | None]]:
    """Per task: AeroWeaver's mean tokens per episode over each baseline's (HMAS-2,
    Centralized); None where either side has no finished cell or the baseline spent none."""
    ratios: dict[str, dict[str, float | None]] = {}
    for t in tasks:
        a = stats.get((t, "aeroweaver"))
        row: dict[str, float | None] = {}
        for c in RATIO_BASELINES:
            b = stats.get((t, c))
            num = a.mean(a.tokens) if a else None
            den = b.mean(b.tokens) if b else None
            row[c] = num / den if num is not None and den else None
        ratios[t] = row
    return ratios


def _num(x: float | None, digits: int = 2) -> str:
    return "–" if x is None or not math.isfinite(x) else f"{x:,.{digits}f}"


def _ret(s: CellStats | None) -> str:
    if s is None or not s.returns:
        return "–"
    sd = s.sd
    return (
        f"{s.mean(s.returns):.2f} ± {sd:.2f} (n={s.n})"
        if sd is not None
        else (f"{s.mean(s.returns):.2f} (n=1)")
    )


def _holds(s: CellStats) -> str:
    per = max(1, len(s.calls))
    parts = [f"{k} {v / per:.1f}" for k, v in s.holds.items() if v]
    return ", ".join(parts) if parts else "none"


def markdown(
    stats: dict[tuple[str, str], CellStats], tasks: Sequence[str], conditions: Sequence[str]
) -> str:
    from aeroweaver_edge.bench.conditions import CONDITIONS

    tasks = [t for t in tasks if any((t, c) in stats for c in conditions)]
    conds = [c for c in conditions if any((t, c) in stats for t in tasks)]
    titles = [CONDITIONS[c].title for c in conds]
    out = ["### Episode return (mean ± sample SD over episodes)", ""]
    out += ["| task | " + " | ".join(titles) + " |", "|---" * (len(conds) + 1) + "|"]
    for t in tasks:
        out.append(f"| {t} | " + " | ".join(_ret(stats.get((t, c))) for c in conds) + " |")
    out += ["", "### Tokens per episode (UAVs' calls + the central node's)", ""]
    out += ["| task | " + " | ".join(titles) + " |", "|---" * (len(conds) + 1) + "|"]
    for t in tasks:
        cells = []
        for c in conds:
            s = stats.get((t, c))
            cells.append(_num(s.mean(s.tokens), 0) if s and s.tokens else "–")
        out.append(f"| {t} | " + " | ".join(cells) + " |")
    if "aeroweaver" in conds and ({"hmas2", "centralized"} & set(conds)):
        out += [
            "",
            "### Token ratio per episode: AeroWeaver / baseline (< 1: AeroWeaver uses fewer)",
            "",
            "| task | AeroWeaver / HMAS-2 | AeroWeaver / Centralized |",
            "|---|---|---|",
        ]
        ratios = token_ratios(stats, tasks)
        for t in tasks:
            row = [_num(ratios[t][c], 2) for c in RATIO_BASELINES]
            out.append(f"| {t} | " + " | ".join(row) + " |")
    ablations = [c for c in ABLATIONS if c in conds]
    if "aeroweaver" in conds and ablations:
        out += [
            "",
            "### Ablations as the paper's relative score Q = 1 + (R_m - R_full) / K_t",
            "",
            "| task | " + " | ".join(CONDITIONS[c].title for c in ablations) + " |",
            "|---" * (len(ablations) + 1) + "|",
        ]
        for t in tasks:
            full = stats.get((t, "aeroweaver"))
            row = []
            for c in ablations:
                m = stats.get((t, c))
                if full and m and full.returns and m.returns:
                    q = (
                        1
                        + (statistics.fmean(m.returns) - statistics.fmean(full.returns))
                        / PAPER_K[t]
                    )
                    row.append(f"{q:.3f}")
                else:
                    row.append("–")
            out.append(f"| {t} | " + " | ".join(row) + " |")
    out += [
        "",
        "### Per task and condition",
        "",
        "| task | condition | episodes | return | tokens / episode (central) | LLM calls / "
        "episode | decision latency p50 / p95 (s) | uncached prompt tokens / call | "
        "invalid choices | holds per episode by cause |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for t in tasks:
        for c in conds:
            s = stats.get((t, c))
            if s is None:
                continue
            central = s.mean(s.central_tokens) if any(s.central_tokens) else None
            tok = _num(s.mean(s.tokens), 0) + (f" ({_num(central, 0)})" if central else "")
            inv = s.invalid_rate
            out.append(
                f"| {t} | {s.title} | {s.n} | {_ret(s)} | {tok} | {_num(s.mean(s.calls), 1)} | "
                f"{_num(s.percentile(0.5), 2)} / {_num(s.percentile(0.95), 2)} | "
                f"{_num(s.uncached_per_call, 0)} | "
                f"{'–' if inv is None else f'{100 * inv:.1f} %'} | {_holds(s)} |"
            )
    hmas2 = [(t, stats[(t, "hmas2")]) for t in tasks if (t, "hmas2") in stats]
    if any(s.reviews_asked for _, s in hmas2):
        out += [
            "",
            "### HMAS-2: local reviews and central revisions",
            "",
            "| task | episodes | reviews agreeing with the plan | rounds the revision changed |",
            "|---|---|---|---|",
        ]
        for t, s in hmas2:
            agree = f"{s.reviews_agreed} of {s.reviews_asked}" if s.reviews_asked else "–"
            out.append(f"| {t} | {s.n} | {agree} | {s.revised_rounds} of {s.central_rounds} |")
    bad = [(k, s.mismatches) for k, s in stats.items() if s.mismatches]
    if bad:
        out += ["", "Trace vs summary mismatches:"]
        out += [f"- {k[0]} / {k[1]}: {'; '.join(m)}" for k, m in bad]
    return "\n".join(out) + "\n"


CSV_FIELDS = [
    "task",
    "condition",
    "seed",
    "episode",
    "team_return",
    "rounds",
    "reason",
    "decisions",
    "holds",
    *[f"holds_{c}" for c in HOLD_CAUSES],
    "invalid",
    "llm_calls_uavs",
    "llm_calls_central",
    "tokens_total",
    "prompt_uavs",
    "prompt_cached_uavs",
    "completion_uavs",
    "prompt_central",
    "prompt_cached_central",
    "completion_central",
    "latency_p50_s",
    "latency_p95_s",
    "model",
]


def _pct(xs: Sequence[float], q: float) -> float | None:
    ys = sorted(xs)
    return round(ys[min(len(ys) - 1, round(q * (len(ys) - 1)))], 4) if ys else None


def csv_rows(cells: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    for data in cells:
        b = data["bench"]
        for e in data["episodes"]:
            t = e["tokens"]
            rows.append(
                {
                    "task": b["task"],
                    "condition": b["condition"],
                    "seed": b["seed"],
                    "episode": e["episode"],
                    "team_return": e["team_return"],
                    "rounds": e["rounds"],
                    "reason": e["reason"],
                    "decisions": e["decisions"],
                    "holds": e["holds"],
                    **{f"holds_{c}": e["holds_by_cause"].get(c, 0) for c in HOLD_CAUSES},
                    "invalid": e["invalid"],
                    "llm_calls_uavs": e["llm_calls"]["uavs"],
                    "llm_calls_central": e["llm_calls"]["central"],
                    "tokens_total": e["tokens_total"],
                    "prompt_uavs": t["uavs"]["prompt"],
                    "prompt_cached_uavs": t["uavs"]["prompt_cached"],
                    "completion_uavs": t["uavs"]["completion"],
                    "prompt_central": t["central"]["prompt"],
                    "prompt_cached_central": t["central"]["prompt_cached"],
                    "completion_central": t["central"]["completion"],
                    "latency_p50_s": _pct(e["latency_s"], 0.5),
                    "latency_p95_s": _pct(e["latency_s"], 0.95),
                    "model": data["summary"].get("model") or data["summary"].get("selector"),
                }
            )
    rows.sort(key=lambda r: (r["task"], r["condition"], r["seed"], r["episode"]))
    return rows


def summary(
    stats: dict[tuple[str, str], CellStats], tasks: Sequence[str], conditions: Sequence[str]
) -> dict[str, Any]:
    """A small machine-readable digest of the table: per task and condition, per condition
    pooled over tasks, and the per-task token ratios."""
    per: dict[str, dict[str, Any]] = {}
    pooled: dict[str, CellStats] = {}
    for t in tasks:
        for c in conditions:
            s = stats.get((t, c))
            if s is None:
                continue
            per.setdefault(t, {})[c] = s.figures()
            pooled.setdefault(c, CellStats("*", c, s.title)).absorb(s)
    return {
        "cells_finished": sum(len(s.seeds) for s in stats.values()),
        "by_task": per,
        "by_condition": {c: pooled[c].figures() for c in conditions if c in pooled},
        "token_ratios": {
            t: {f"aeroweaver/{c}": (None if v is None else round(v, 4)) for c, v in row.items()}
            for t, row in token_ratios(stats, tasks).items()
        },
    }


def write_report(out: Path, *, tasks: Sequence[str], conditions: Sequence[str]) -> None:
    cells = load_cells(out)
    rows = csv_rows(cells)
    with (out / "results.csv").open("w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        w.writerows(rows)
    stats = aggregate(cells)
    (out / "table.md").write_text(markdown(stats, tasks, conditions), encoding="utf-8")
    write_json_file(out / "summary.json", summary(stats, tasks, conditions))
    from aeroweaver_edge.bench.plots import write_plots

    write_plots(out, stats, tasks, conditions)


__all__ = [
    "CellStats",
    "aggregate",
    "csv_rows",
    "load_cells",
    "markdown",
    "summary",
    "token_ratios",
    "write_report",
]
