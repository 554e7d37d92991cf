"""Why the experience correction does what it does: figures from adaptation traces.

``python -m aeroweaver_lab.bench.adaptation_why DIR [--gamma 0.95]`` reads every
``DIR/runs/<task>/seed<S>/<variant>/trace.jsonl`` written by ``bench.adaptation`` (with
``--bench``: a ``bench run`` directory's AeroWeaver and beta = 0 cells), also a paired-mode
directory's ``runs/<base>/<task>/seq<S>/<cell>`` (variants named by base and estimator),
and prints (and writes to ``DIR/why.md``) per task and variant:

* how far apart the base scores are (top-1 minus top-2 log-prob of the labels that came
  back) against how far apart the correction pushes them (beta times the spread of the
  options' advantages), and how often the correction changed the pick;
* what the changed picks were: ``hold_position``, or the skill this UAV chose the round
  before (a recency signature), against how often the base winner was that skill anyway;
* the mean advantage of the skill chosen last round against the other options' skills;
* holds by cause, bound-rule fallbacks;

and, from the rewards alone, how an in-flight return depends on its age: a record of
round s seen at round t has collected only t - s rewards, so with negative rewards young
records look better whatever was chosen (``age_bias``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import statistics
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from aeroweaver_edge.contracts.defaults import HOLD_SKILL
from aeroweaver_edge.contracts.hold_reasons import HOLD_CAUSES
from aeroweaver_lab.bench.episodes import read_trace


def _skill_of(option: str) -> str:
    """``"B. cover_landmark(target_id=L0)"`` -> ``cover_landmark``."""
    return option.split(". ", 1)[-1].split("(", 1)[0]


def _median(xs: Sequence[float]) -> float | None:
    return statistics.median(xs) if xs else None


def _mean(xs: Sequence[float]) -> float | None:
    return statistics.fmean(xs) if xs else None


def decision_figures(trace: Iterable[Mapping[str, Any]], beta: float) -> dict[str, Any]:
    gaps: list[float] = []
    pushes: list[float] = []
    scored = corrected = to_hold = to_last = base_last = bound = to_unseen = 0
    adv_last: list[float] = []
    adv_other: list[float] = []
    # corrected picks of hold: entries (not holding the round before) and repeats
    hold_entry = hold_entry_unseen = 0
    adv_hold_repeat: list[float] = []
    adv_winner_at_entry: list[float] = []
    holds = dict.fromkeys(HOLD_CAUSES, 0)
    decisions = 0
    previous: dict[tuple[int, str], str] = {}  # (episode, uav) -> last chosen skill
    for row in trace:
        if row.get("type") != "round":
            continue
        for uav, d in sorted(row.get("decisions", {}).items()):
            decisions += 1
            cause = d.get("hold_cause")
            if cause in holds:
                holds[cause] += 1
            key = (row["episode"], uav)
            last = previous.get(key)
            options = d.get("options") or []
            base = d.get("base") or {}
            adv = d.get("advantage") or {}
            if options and base:
                scored += 1
                labels = [o.split(".", 1)[0] for o in options]
                skills = dict(zip(labels, (_skill_of(o) for o in options), strict=True))
                ranked = sorted((v for k, v in base.items() if k in skills), reverse=True)
                if len(ranked) >= 2:
                    gaps.append(ranked[0] - ranked[1])
                values = [adv.get(lb, 0.0) for lb in labels]
                pushes.append(beta * (max(values) - min(values)))
                base_winner = max((lb for lb in labels if lb in base), key=lambda lb: base[lb])
                base_last += last is not None and skills[base_winner] == last
                if last is not None and last in skills.values():
                    for lb in labels:
                        (adv_last if skills[lb] == last else adv_other).append(adv.get(lb, 0.0))
                if d.get("corrected"):
                    corrected += 1
                    pick = skills.get(d.get("chosen") or "", "")
                    to_hold += pick == HOLD_SKILL
                    a_pick = adv.get(d.get("chosen") or "", 0.0)
                    if pick == HOLD_SKILL and last == HOLD_SKILL:
                        adv_hold_repeat.append(a_pick)
                    elif pick == HOLD_SKILL:
                        hold_entry += 1
                        hold_entry_unseen += a_pick == 0.0
                        adv_winner_at_entry.append(adv.get(base_winner, 0.0))
                    to_last += last is not None and pick == last
                    # an option without experience (A = 0) beat a base winner whose skill
                    # looked worse than its neighbourhood (A < 0): "unseen means average"
                    to_unseen += (
                        adv.get(d.get("chosen") or "", 0.0) == 0.0
                        and adv.get(base_winner, 0.0) < 0.0
                    )
                bound += str(d.get("reason", "")).startswith("bound rule")
            if d.get("skill"):
                previous[key] = d["skill"]
    return {
        "decisions": decisions,
        "scored": scored,
        "base_gap_median": _median(gaps),
        "correction_push_median": _median(pushes),
        "push_exceeds_gap": (
            sum(p > g for p, g in zip(pushes, gaps, strict=False)) / len(gaps) if gaps else None
        ),
        "corrected": corrected,
        "corrected_to_hold": to_hold,
        "hold_entries": hold_entry,
        "hold_entries_unseen": hold_entry_unseen,
        "advantage_winner_at_hold_entry_mean": _mean(adv_winner_at_entry),
        "hold_repeats": len(adv_hold_repeat),
        "advantage_hold_at_repeat_mean": _mean(adv_hold_repeat),
        "corrected_to_last_skill": to_last,
        "corrected_to_unseen": to_unseen,
        "base_winner_is_last_skill": base_last,
        "advantage_last_skill_mean": _mean(adv_last),
        "advantage_other_skills_mean": _mean(adv_other),
        "bound_rule": bound,
        "holds_by_cause": holds,
    }


def age_bias(traces: Iterable[list[dict[str, Any]]], gamma: float) -> dict[str, Any]:
    """Mean in-flight return of a record by its age (rounds of rewards it has collected),
    and of finalised records, from each UAV's per-round rewards."""
    by_age: dict[int, list[float]] = {}
    final: list[float] = []
    for trace in traces:
        rewards: dict[tuple[int, str], list[float]] = {}
        for row in trace:
            if row.get("type") != "round":
                continue
            for uav in row.get("decisions", {}):
                r = row.get("rewards", {}).get(uav)
                if r is not None:
                    rewards.setdefault((row["episode"], uav), []).append(float(r))
        for rs in rewards.values():
            n = len(rs)
            for s in range(n):
                g = 0.0
                for k in range(s, n):
                    g += gamma ** (k - s) * rs[k]
                    age = k - s + 1
                    by_age.setdefault(age, []).append(g)
                final.append(g)
    ages = [a for a in (1, 2, 4, 8, 16) if a in by_age]
    return {
        "in_flight_by_age": {a: round(statistics.fmean(by_age[a]), 3) for a in ages},
        "finalised_mean": round(statistics.fmean(final), 3) if final else None,
    }


def skill_records(memory_dir: Path) -> dict[str, dict[str, float]]:
    """Per skill, over the UAVs' own records in kept memory files: how many, their mean
    round and mean (final) return -- where a skill was used, and what followed."""
    import sqlite3

    by: dict[str, list[tuple[int, float]]] = {}
    for path in sorted(memory_dir.glob("*.sqlite3")):
        with contextlib.closing(sqlite3.connect(f"file:{path}?mode=ro", uri=True)) as db:
            rows = db.execute("SELECT round, skill, ret FROM records WHERE origin = ''")
            for rnd, skill, ret in rows:
                if ret is not None:
                    by.setdefault(skill, []).append((int(rnd), float(ret)))
    return {
        s: {
            "records": len(xs),
            "mean_round": round(statistics.fmean(r for r, _ in xs), 1),
            "mean_return": round(statistics.fmean(g for _, g in xs), 2),
        }
        for s, xs in sorted(by.items())
    }


def analyse(out: Path, gamma: float) -> list[dict[str, Any]]:
    rows = []
    legacy = (out / "runs").glob("*/seed*/*/result.json")
    paired = (out / "runs").glob("*/*/seq*/*/result.json")  # runs/<base>/<task>/seq<S>/<cell>
    for result_path in sorted([*legacy, *paired]):
        result = json.loads(result_path.read_text(encoding="utf-8"))
        trace = read_trace(result_path.parent / "trace.jsonl")
        figures = decision_figures(trace, float(result["beta"]))
        variant = result["variant"]
        if result.get("estimator", "paper") != "paper" and result["beta"] > 0:
            variant += f" {result['estimator']}"
        if result.get("base", "reference") != "reference":
            variant = f"[{result['base']}] {variant}"
        rows.append(
            {
                "task": result["task"],
                "seed": result["seed"],
                "variant": variant,
                "selector": result["selector"],
                "mean_return": _mean([e["team_return"] for e in result["episodes"]]),
                **figures,
                "age_bias": age_bias([trace], gamma),
                "skills": (
                    skill_records(result_path.parent / "memory")
                    if (result_path.parent / "memory").is_dir()
                    else {}
                ),
            }
        )
    return rows


BENCH_VARIANTS = {"aeroweaver": "beta=0.8", "beta0": "beta=0"}  # same selector, beta differs


def analyse_bench(out: Path, gamma: float) -> list[dict[str, Any]]:
    """The same figures from a ``bench run`` directory's AeroWeaver and beta = 0 cells
    (``runs/<task>/<condition>/seed<S>.trace.jsonl``): one episode per cell, so the
    correction acts only on the episode's own in-flight records."""
    rows = []
    for cond, variant in BENCH_VARIANTS.items():
        for cell_path in sorted((out / "runs").glob(f"*/{cond}/seed*.json")):
            cell = json.loads(cell_path.read_text(encoding="utf-8"))
            b = cell.get("bench", {})
            if not b.get("complete"):
                continue
            trace = read_trace(out / b["trace"])
            header = next((r for r in trace if r.get("type") == "run"), {})
            beta = float(header.get("beta", 0.8 if cond == "aeroweaver" else 0.0))
            rows.append(
                {
                    "task": b["task"],
                    "seed": b["seed"],
                    "variant": variant,
                    "selector": cell["summary"].get("selector"),
                    "mean_return": _mean(
                        [e["team_return"] for e in cell["episodes"] if e["team_return"] is not None]
                    ),
                    **decision_figures(trace, beta),
                    "age_bias": age_bias([trace], gamma),
                    "skills": {},
                }
            )
    return rows


def _f(x: float | None, digits: int = 2) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def markdown(rows: list[dict[str, Any]]) -> str:
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["task"], r["variant"]), []).append(r)
    lines = [
        "| task | variant | seeds | mean return | base gap (median, nats) | beta x advantage "
        "spread (median) | push > gap | corrected picks | of which hold / last round's "
        "skill / unseen (A = 0) | base winner = last skill | A(last skill) vs A(others) | "
        "bound rule | holds: chosen / gate / llm / invalid |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (task, variant), rs in groups.items():
        scored = sum(r["scored"] for r in rs)
        corr = sum(r["corrected"] for r in rs)
        h = {c: sum(r["holds_by_cause"][c] for r in rs) for c in HOLD_CAUSES}

        def pooled(key: str, how: Any = _mean, rs: list[dict[str, Any]] = rs) -> float | None:
            xs = [r[key] for r in rs if r[key] is not None]
            return how(xs) if xs else None

        push = pooled("push_exceeds_gap")
        lines.append(
            f"| {task} | {variant} | {len(rs)} | {_f(pooled('mean_return'))} | "
            f"{_f(pooled('base_gap_median', _median))} | "
            f"{_f(pooled('correction_push_median', _median))} | "
            f"{'–' if push is None else f'{100 * push:.0f} %'} | {corr} of {scored} | "
            f"{sum(r['corrected_to_hold'] for r in rs)} / "
            f"{sum(r['corrected_to_last_skill'] for r in rs)} / "
            f"{sum(r['corrected_to_unseen'] for r in rs)} | "
            f"{sum(r['base_winner_is_last_skill'] for r in rs)} | "
            f"{_f(pooled('advantage_last_skill_mean'))} vs "
            f"{_f(pooled('advantage_other_skills_mean'))} | "
            f"{sum(r['bound_rule'] for r in rs)} | {h['chosen']} / {h['safety_gate']} / "
            f"{h['llm_failure'] + h['deadline']} / {h['invalid_answer']} |"
        )
    lines += [
        "",
        "Corrected picks of hold_position: entries (the UAV did not hold the round before), "
        "of which hold had no experience (A = 0), and the base winner's mean advantage there; "
        "repeats (it held the round before) and hold's mean advantage there:",
        "",
        "| task | variant | entries | of which A(hold) = 0 | A(base winner) at entries | "
        "repeats | A(hold) at repeats |",
        "|---|---|---|---|---|---|---|",
    ]
    for (task, variant), rs in groups.items():

        def weighted(key: str, n_key: str, rs: list[dict[str, Any]] = rs) -> float | None:
            pairs = [(r[key], r[n_key]) for r in rs if r[key] is not None and r[n_key]]
            n = sum(k for _, k in pairs)
            return sum(v * k for v, k in pairs) / n if n else None

        lines.append(
            f"| {task} | {variant} | {sum(r['hold_entries'] for r in rs)} | "
            f"{sum(r['hold_entries_unseen'] for r in rs)} | "
            f"{_f(weighted('advantage_winner_at_hold_entry_mean', 'hold_entries'))} | "
            f"{sum(r['hold_repeats'] for r in rs)} | "
            f"{_f(weighted('advantage_hold_at_repeat_mean', 'hold_repeats'))} |"
        )
    tasks = list(dict.fromkeys(r["task"] for r in rows))
    keys = [1, 2, 4, 8, 16]
    lines += [
        "",
        "In-flight return of a record by the number of rewards it has collected so far "
        "(beta=0 runs, gamma 0.95), against the finalised returns:",
        "",
        "| task | "
        + " | ".join(f"{k} reward{'s' if k > 1 else ''}" for k in keys)
        + " | finalised |",
        "|---" * (len(keys) + 2) + "|",
    ]
    for task in tasks:
        ages = [r["age_bias"] for r in rows if r["task"] == task and r["variant"] == "beta=0"]
        if not ages:
            continue
        finals = [x["finalised_mean"] for x in ages if x["finalised_mean"] is not None]
        cells = [
            _f(_mean([x["in_flight_by_age"][k] for x in ages if k in x["in_flight_by_age"]]))
            for k in keys
        ]
        lines.append(f"| {task} | " + " | ".join(cells) + f" | {_f(_mean(finals))} |")
    with_skills = [r for r in rows if r["skills"]]
    if with_skills:
        lines += [
            "",
            "Where each skill was used and what followed (the UAVs' own records in the kept "
            "memory files, all seeds): records / mean round / mean return:",
            "",
            "| task | variant | skills |",
            "|---|---|---|",
        ]
        groups2: dict[tuple[str, str], dict[str, list[dict[str, float]]]] = {}
        for r in with_skills:
            g = groups2.setdefault((r["task"], r["variant"]), {})
            for skill, v in r["skills"].items():
                g.setdefault(skill, []).append(v)
        for (task, variant), g in groups2.items():
            parts = []
            for skill, vs in sorted(g.items()):
                n = sum(int(v["records"]) for v in vs)
                rnd = sum(v["mean_round"] * v["records"] for v in vs) / n
                ret = sum(v["mean_return"] * v["records"] for v in vs) / n
                parts.append(f"{skill} {n} / {rnd:.1f} / {ret:.2f}")
            lines.append(f"| {task} | {variant} | " + "; ".join(parts) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m aeroweaver_lab.bench.adaptation_why")
    p.add_argument("dir", help="an adaptation output directory (--out of bench.adaptation)")
    p.add_argument("--gamma", type=float, default=0.95)
    p.add_argument(
        "--bench",
        action="store_true",
        help="DIR is a `bench run` directory: compare its AeroWeaver and beta = 0 cells",
    )
    args = p.parse_args(argv)
    out = Path(args.dir)
    rows = analyse_bench(out, args.gamma) if args.bench else analyse(out, args.gamma)
    if not rows:
        print(f"no adaptation runs under {out}/runs", file=sys.stderr)
        return 2
    text = markdown(rows)
    (out / "why.md").write_text(text, encoding="utf-8")
    (out / "why.json").write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
