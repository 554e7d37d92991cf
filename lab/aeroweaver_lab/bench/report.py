"""Tables and CSV from a benchmark directory's finished cells (``bench.runner``).

Everything is recomputed from the cells' per-episode figures (which come from the traces):
return mean, sample SD and a 95 % bootstrap interval over episodes (all seeds); paired
Wilcoxon signed-rank tests of every condition against AeroWeaver on the same (seed,
episode), Holm-corrected over the whole table (``bench.stats``); tokens and LLM calls per
episode and per round (UAVs' and central node's, plus one LLM Commander setup for the
conditions that use its activation, ``bench.setup_cost``); position bias (share of picks
among >= 2 options that took the first label); decision latency p50/p95, uncached prompt
tokens per LLM call, invalid-choice rate and holds by cause. ``write_report`` writes
``results.csv``, ``table.md``, ``summary.json`` and the plots; nothing in them depends on
when or where it is run, so ``--report-only`` rebuilds them byte for byte from the archive.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import statistics
from collections.abc import Container, Iterable, Sequence
from pathlib import Path
from typing import Any

from aeroweaver_edge.contracts.hold_reasons import HOLD_CAUSES
from aeroweaver_edge.runtime.json_out import write_json_file
from aeroweaver_lab.bench.cells import CellStats, add_known
from aeroweaver_lab.bench.episodes import episode_metrics, read_trace
from aeroweaver_lab.bench.run_time import markdown as run_time_markdown
from aeroweaver_lab.bench.run_time import run_time
from aeroweaver_lab.bench.setup_cost import SETUP_CONDITIONS
from aeroweaver_lab.bench.stats import holm, wilcoxon

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


def _predates_figures(episode: dict[str, Any]) -> bool:
    """An episode summary written before one of today's figures existed."""
    reviews = episode.get("central_reviews")
    if reviews is None or "picks" not in episode:
        return True
    return bool(reviews.get("asked")) and "disagreed" not in reviews


def load_cells(out: Path, seeds: Container[int] | None = None) -> list[dict[str, Any]]:
    """The complete cells (of ``seeds`` only, if given). A cell written before a per-episode
    figure existed gets its episodes recomputed from its trace (the source of every figure)
    when the trace is there."""
    cells = []
    for path in sorted((out / "runs").glob("*/*/seed*.json")):
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(data, dict) and data.get("bench", {}).get("complete"):
            if seeds is not None and data["bench"].get("seed") not in seeds:
                continue
            eps = data.get("episodes") or []
            trace = out / str(data["bench"].get("trace", ""))
            stale = any(_predates_figures(e) for e in eps)
            if stale and trace.is_file():
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
        s.finished.append(str(b.get("finished", ""))[:10])
        counted = b["condition"] in SETUP_CONDITIONS
        setup = b.get("setup_tokens") if counted else 0
        s.setup_missing += counted and setup is None
        for i, e in enumerate(data["episodes"]):
            if e["team_return"] is not None:
                s.returns.append(float(e["team_return"]))
                s.paired[(int(b["seed"]), int(e["episode"]))] = float(e["team_return"])
            spent = int(setup or 0) if i == 0 else 0  # once per run: its first episode
            s.setup.append(spent)
            s.tokens.append(int(e["tokens_total"]) + spent)
            s.per_round.append((int(e["tokens_total"]) + spent) / max(1, int(e["rounds"])))
            s.picks += int(e.get("picks", 0))
            s.first_picks += int(e.get("first_label_picks", 0))
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
            s.reviews_disagreed += int(reviews.get("disagreed", 0))
            s.revised_rounds += int(e.get("central_revised_rounds", 0))
            calls = e.get("central_revision_calls")
            s.revision_calls = add_known(s.revision_calls, None if calls is None else int(calls))
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


def _same_returns(a: CellStats, b: CellStats | None) -> str:
    """In how many of the (seed, episode) pairs both ran the returns are equal: the same world,
    so equal returns mean the same choices (HMAS-2 against Centralized)."""
    diffs = a.paired_diffs(b) if b is not None else []
    return f"{diffs.count(0.0)} of {len(diffs)} episodes" if diffs else "–"


def paired_q(full: CellStats | None, ablation: CellStats | None, k_t: float) -> float | None:
    """The paper's Q = 1 + (R_m - R_full) / K_t over the (seed, episode) pairs both ran: with
    n = 10 for AeroWeaver and n = 5 for an ablation, unpaired means compare other worlds."""
    if full is None or ablation is None:
        return None
    diffs = ablation.paired_diffs(full)
    return 1 + statistics.fmean(diffs) / k_t if diffs else None


def paired_tests(
    stats: dict[tuple[str, str], CellStats], tasks: Sequence[str], conditions: Sequence[str]
) -> dict[tuple[str, str], dict[str, Any]]:
    """Every (task, condition) against AeroWeaver on the episodes both ran (same seed and
    episode index: the same world): the mean paired difference (condition - AeroWeaver),
    the Wilcoxon signed-rank p, and Holm's adjusted p within the condition (family: its
    tasks). Key ``("*", c)``: all tasks pooled, each difference divided by the paper's task
    scale K_t (a difference in Q), Holm-adjusted over the conditions.

    Why these families: an exact test on n pairs cannot go below p = 2 / 2^n, so over a
    whole table of 54 tests even n = 10 (p >= 0.002, x 54 = 0.105) could never reject; per
    condition (9 tasks) n = 10 can (0.018). The pooled test has 9 x n pairs."""
    found: dict[tuple[str, str], dict[str, Any]] = {}
    pooled: dict[str, list[float]] = {}
    for t in tasks:
        full = stats.get((t, "aeroweaver"))
        if full is None:
            continue
        for c in conditions:
            other = stats.get((t, c))
            if c == "aeroweaver" or other is None:
                continue
            diffs = other.paired_diffs(full)
            pooled.setdefault(c, []).extend(d / PAPER_K.get(t, 1.0) for d in diffs)
            found[(t, c)] = _test(diffs)
    for c in sorted({c for _, c in found}):
        family = [k for k in found if k[1] == c]
        for k, adj in zip(family, holm([found[k]["p"] for k in family]), strict=True):
            found[k]["p_holm"] = adj
    overall = {("*", c): _test(d) for c, d in pooled.items()}
    for k, adj in zip(overall, holm([v["p"] for v in overall.values()]), strict=True):
        overall[k]["p_holm"] = adj
    return found | overall


def _test(diffs: Sequence[float]) -> dict[str, Any]:
    test = wilcoxon(diffs)
    return {
        "pairs": len(diffs),
        "mean_diff": statistics.fmean(diffs) if diffs else None,
        "nonzero": 0 if test is None else test.n,
        "w_plus": None if test is None else test.w_plus,
        "p": None if test is None else test.p,
    }


def _num(x: float | None, digits: int = 2) -> str:
    return "–" if x is None or not math.isfinite(x) else f"{x:,.{digits}f}"


def _ret(s: CellStats | None) -> str:
    """Mean [95 % bootstrap interval] (n)."""
    if s is None or not s.returns:
        return "–"
    ci = s.ci
    if ci is None:
        return f"{s.mean(s.returns):.2f} (n=1)"
    return f"{s.mean(s.returns):.2f} [{ci[0]:.2f}, {ci[1]:.2f}] (n={s.n})"


def _p(x: float | None) -> str:
    return "–" if x is None else ("< 0.001" if x < 0.001 else f"{x:.3f}")


def _pair(test: dict[str, Any] | None) -> str:
    if test is None or not test["pairs"]:
        return "–"
    if test["p"] is None:
        return f"Δ 0 on all {test['pairs']} pairs"
    return (
        f"Δ {test['mean_diff']:+.2f}, p {_p(test['p'])} (Holm {_p(test['p_holm'])}), "
        f"{test['nonzero']} of {test['pairs']} pairs differ"
    )


def header(stats: dict[tuple[str, str], CellStats]) -> list[str]:
    """Model(s), episodes and dates of the cells: every table says what it is of."""
    models = sorted({s.model for s in stats.values() if s.model})
    dates = sorted({d for s in stats.values() for d in s.finished if d})
    ns = sorted({s.n for s in stats.values()})
    span = f"{dates[0]} to {dates[-1]}" if len(dates) > 1 else (dates[0] if dates else "?")
    n_text = f"{ns[0]}" if len(ns) == 1 else (f"{ns[0]}–{ns[-1]}" if ns else "0")
    return [
        f"Model: {', '.join(models) or 'none (scripted only)'}; episodes per cell n = {n_text}; "
        f"cells finished {span}. Intervals: 95 % percentile bootstrap of the mean "
        "(5,000 resamples, fixed seed). p: two-sided exact Wilcoxon signed-rank test against "
        "AeroWeaver on the same (seed, episode), Holm-adjusted over each condition's tasks; "
        "with n pairs no p can be below 2 / 2^n (n = 5: 0.0625).",
        "",
    ]


def _holds(s: CellStats) -> str:
    per = max(1, len(s.calls))
    parts = [f"{k} {v / per:.1f}" for k, v in s.holds.items() if v]
    return ", ".join(parts) if parts else "none"


def markdown(
    stats: dict[tuple[str, str], CellStats], tasks: Sequence[str], conditions: Sequence[str]
) -> str:
    from aeroweaver_lab.bench.conditions import CONDITIONS

    tasks = [t for t in tasks if any((t, c) in stats for c in conditions)]
    conds = [c for c in conditions if any((t, c) in stats for t in tasks)]
    titles = [CONDITIONS[c].title for c in conds]
    out = header({k: v for k, v in stats.items() if k[0] in tasks and k[1] in conds})
    out += ["### Episode return (mean [95 % bootstrap interval] (n episodes))", ""]
    out += ["| task | " + " | ".join(titles) + " |", "|---" * (len(conds) + 1) + "|"]
    for t in tasks:
        out.append(f"| {t} | " + " | ".join(_ret(stats.get((t, c))) for c in conds) + " |")
    others = [c for c in conds if c != "aeroweaver"]
    if "aeroweaver" in conds and others:
        tests = paired_tests(stats, tasks, conds)
        out += [
            "",
            "### Paired against AeroWeaver: mean difference in return (condition − AeroWeaver), "
            "Wilcoxon p (Holm-adjusted over the condition's tasks)",
            "",
            "| task | " + " | ".join(CONDITIONS[c].title for c in others) + " |",
            "|---" * (len(others) + 1) + "|",
        ]
        for t in tasks:
            out.append(f"| {t} | " + " | ".join(_pair(tests.get((t, c))) for c in others) + " |")
        row = [_pair(tests.get(("*", c))) for c in others]
        out.append("| all tasks, Δ / K_t (Holm over conditions) | " + " | ".join(row) + " |")
    out += [
        "",
        "### Position bias: share of picks that took the first option listed "
        "(decisions with >= 2 options)",
        "",
    ]
    out += ["| task | " + " | ".join(titles) + " |", "|---" * (len(conds) + 1) + "|"]
    pooled: dict[str, CellStats] = {}
    for t in tasks:
        row = []
        for c in conds:
            s = stats.get((t, c))
            if s is not None:
                pooled.setdefault(c, CellStats("*", c, s.title)).absorb(s)
            pb = None if s is None else s.position_bias
            row.append("–" if s is None or pb is None else f"{100 * pb:.0f} % of {s.picks}")
        out.append(f"| {t} | " + " | ".join(row) + " |")
    row = []
    for c in conds:
        ps = pooled.get(c)
        pb = None if ps is None else ps.position_bias
        row.append("–" if ps is None or pb is None else f"**{100 * pb:.1f} % of {ps.picks}**")
    out.append("| all tasks | " + " | ".join(row) + " |")
    out += [
        "",
        "### Tokens per episode (UAVs' calls + the central node's + one LLM Commander "
        "setup per run where its activation is used)",
        "",
    ]
    out += ["| task | " + " | ".join(titles) + " |", "|---" * (len(conds) + 1) + "|"]
    for t in tasks:
        cells = []
        for c in conds:
            s = stats.get((t, c))
            cells.append(_num(s.mean(s.tokens), 0) if s and s.tokens else "–")
        out.append(f"| {t} | " + " | ".join(cells) + " |")
    out += ["", "### Tokens per round (per episode: tokens / rounds flown; mean)", ""]
    out += ["| task | " + " | ".join(titles) + " |", "|---" * (len(conds) + 1) + "|"]
    for t in tasks:
        cells = []
        for c in conds:
            s = stats.get((t, c))
            cells.append(_num(s.mean(s.per_round), 0) if s and s.per_round else "–")
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
            "### Ablations as the paper's relative score Q = 1 + (R_m - R_full) / K_t "
            "(on the episodes both ran)",
            "",
            "| task | " + " | ".join(CONDITIONS[c].title for c in ablations) + " |",
            "|---" * (len(ablations) + 1) + "|",
        ]
        for t in tasks:
            full = stats.get((t, "aeroweaver"))
            row = []
            for c in ablations:
                q = paired_q(full, stats.get((t, c)), PAPER_K[t])
                row.append("–" if q is None else f"{q:.3f}")
            out.append(f"| {t} | " + " | ".join(row) + " |")
    out += [
        "",
        "### Per task and condition",
        "",
        "| task | condition | episodes | return | tokens / episode (central) | of which "
        "setup | LLM calls / episode | decision latency p50 / p95 (s) | uncached prompt "
        "tokens / call | invalid choices | holds per episode by cause |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for t in tasks:
        for c in conds:
            s = stats.get((t, c))
            if s is None:
                continue
            central = s.mean(s.central_tokens) if any(s.central_tokens) else None
            tok = _num(s.mean(s.tokens), 0) + (f" ({_num(central, 0)})" if central else "")
            inv = s.invalid_rate
            setup = "–" if c not in SETUP_CONDITIONS else _num(s.mean(s.setup), 0)
            setup += f" ({s.setup_missing} runs unmeasured)" if s.setup_missing else ""
            out.append(
                f"| {t} | {s.title} | {s.n} | {_ret(s)} | {tok} | {setup} | "
                f"{_num(s.mean(s.calls), 1)} | "
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
            "A review that agrees or disagrees is feedback; one without a usable answer (the "
            "call failed or gave no yes/no) is silence, and only a disagreement buys the "
            "revision call.",
            "",
            "| task | episodes | reviews: agreed / disagreed / no usable answer "
            "| rounds with a revision call | rounds the revision changed "
            "| same return as Centralized |",
            "|---|---|---|---|---|---|",
        ]
        for t, s in hmas2:
            twin = _same_returns(s, stats.get((t, "centralized")))
            silent = s.reviews_asked - s.reviews_agreed - s.reviews_disagreed
            agree = (
                f"{s.reviews_agreed} / {s.reviews_disagreed} / {silent} of {s.reviews_asked}"
                if s.reviews_asked
                else "–"
            )
            calls = s.revision_calls
            called = "–" if calls is None else f"{calls} of {s.central_rounds}"
            out.append(
                f"| {t} | {s.n} | {agree} | {called} | {s.revised_rounds} of {s.central_rounds} "
                f"| {twin} |"
            )
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
    "setup_tokens",
    "picks",
    "first_label_picks",
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
        setup = b.get("setup_tokens") if b["condition"] in SETUP_CONDITIONS else 0
        for i, e in enumerate(data["episodes"]):
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
                    "setup_tokens": (setup if i == 0 else 0),
                    "picks": e.get("picks", 0),
                    "first_label_picks": e.get("first_label_picks", 0),
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
    tests = paired_tests(stats, tasks, conditions)
    return {
        "cells_finished": sum(len(s.seeds) for s in stats.values()),
        "paired_vs_aeroweaver": {
            f"{t}/{c}".replace("*/", "all/"): {
                k: round(v, 4) if isinstance(v, float) else v for k, v in test.items()
            }
            for (t, c), test in tests.items()
        },
        "by_task": per,
        "by_condition": {c: pooled[c].figures() for c in conditions if c in pooled},
        "token_ratios": {
            t: {f"aeroweaver/{c}": (None if v is None else round(v, 4)) for c, v in row.items()}
            for t, row in token_ratios(stats, tasks).items()
        },
    }


def write_report(
    out: Path,
    *,
    tasks: Sequence[str],
    conditions: Sequence[str],
    seeds: Container[int] | None = None,
) -> None:
    cells = load_cells(out, seeds)
    rows = csv_rows(cells)
    with (out / "results.csv").open("w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        w.writerows(rows)
    stats = aggregate(cells)
    chosen = [
        c for c in cells if c["bench"]["task"] in tasks and c["bench"]["condition"] in conditions
    ]
    timing = run_time(chosen)
    table = markdown(stats, tasks, conditions) + "\n".join(["", *run_time_markdown(timing)])
    (out / "table.md").write_text(table.rstrip("\n") + "\n", encoding="utf-8")
    write_json_file(
        out / "summary.json", {**summary(stats, tasks, conditions), "run_time": timing.figures()}
    )
    from aeroweaver_lab.bench.plots import write_plots

    write_plots(out, stats, tasks, conditions)


__all__ = [
    "CellStats",
    "aggregate",
    "csv_rows",
    "load_cells",
    "markdown",
    "paired_q",
    "paired_tests",
    "summary",
    "token_ratios",
    "write_report",
]
