"""Retrieval sensitivity study: recall@K of each task's required skills under rewording.

Mirrors the paper's prompt-perturbation study (original, paraphrases, reordered sentences,
appended distractor chatter), but measures what the harness can check without flying: whether
the skills a task needs are retrieved. Three measurements per phrasing:

* ``text``: BM25 ranking of the whole library for the raw mission text (the retriever alone);
* ``text+body``: the same with each skill's prose body indexed too;
* ``harness``: the full no-LLM pipeline (rule parser -> catalogue -> template roles ->
  per-UAV top-K of Pack(q, ρ, g)); recall over the union of the UAVs' active sets
  (``hold_position`` excluded from K, as in activation).

Recall@K = |required ∩ retrieved@K| / |required|, averaged over the nine tasks (macro).
Run: ``python -m aeroweaver_lab.retrieval_eval [--skills DIR] [--phrasings FILE] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from aeroweaver_edge.skills import SkillRegistry, load_skills
from commander.harness import plan_mission
from commander.mission_parser import MissionParseError, guess_task
from commander.retrieval import BM25Retriever

DATA = Path(__file__).with_name("data") / "mission_phrasings.json"
VARIANTS = ("original", "paraphrase_1", "paraphrase_2", "paraphrase_3", "reordered", "distractor")
KS = (3, 5, 8)
MODES = ("text", "text+body", "harness")
ROSTER = tuple(f"uav{i}" for i in range(10))


@dataclass(frozen=True)
class TaskPhrasings:
    required: tuple[str, ...]
    phrasings: dict[str, str]


def load_phrasings(path: Path = DATA) -> dict[str, TaskPhrasings]:
    raw = json.loads(path.read_text(encoding="utf-8"))
    out: dict[str, TaskPhrasings] = {}
    for task, entry in raw["tasks"].items():
        phr = entry["phrasings"]
        if set(phr) != set(VARIANTS):
            raise ValueError(f"{path}: task {task}: variants must be exactly {VARIANTS}")
        out[task] = TaskPhrasings(tuple(entry["required_skills"]), dict(phr))
    return out


def recall_at_k(retrieved: Sequence[str], required: Sequence[str], k: int) -> float:
    top = set(retrieved[:k])
    return sum(1 for r in required if r in top) / len(required) if required else 1.0


@dataclass(frozen=True)
class Row:
    mode: str
    task: str
    variant: str
    k: int
    recall: float
    found: tuple[str, ...]
    missed: tuple[str, ...]
    note: str = ""


def _row(
    mode: str,
    task: str,
    variant: str,
    k: int,
    got: Sequence[str],
    required: Sequence[str],
    note: str = "",
) -> Row:
    hit = set(got)
    return Row(
        mode,
        task,
        variant,
        k,
        sum(r in hit for r in required) / len(required) if required else 1.0,
        tuple(r for r in required if r in hit),
        tuple(r for r in required if r not in hit),
        note,
    )


def retriever_rows(
    registry: SkillRegistry,
    data: Mapping[str, TaskPhrasings],
    ks: Sequence[int] = KS,
    *,
    include_body: bool = False,
) -> list[Row]:
    retriever = BM25Retriever(registry.documents(), include_body=include_body)
    mode = "text+body" if include_body else "text"
    rows = []
    for task, tp in data.items():
        for variant in VARIANTS:
            ranked = [h.name for h in retriever.rank(tp.phrasings[variant])]
            rows += [_row(mode, task, variant, k, ranked[:k], tp.required) for k in ks]
    return rows


async def harness_rows(
    registry: SkillRegistry,
    data: Mapping[str, TaskPhrasings],
    ks: Sequence[int] = KS,
    roster: Sequence[str] = ROSTER,
) -> list[Row]:
    rows = []
    for task, tp in data.items():
        for variant in VARIANTS:
            text = tp.phrasings[variant]
            for k in ks:
                try:
                    plan = await plan_mission(text, roster, registry, None, k)
                except MissionParseError as e:
                    rows.append(_row("harness", task, variant, k, (), tp.required, str(e)))
                    continue
                union = {s for a in plan.assignments.values() for s in a.skills}
                note = "" if plan.task == task else f"parsed as {plan.task}"
                rows.append(_row("harness", task, variant, k, sorted(union), tp.required, note))
    return rows


def parser_accuracy(data: Mapping[str, TaskPhrasings]) -> dict[str, float]:
    """Share of tasks whose phrasing the rule parser assigns the right task type."""
    return {
        v: sum(guess_task(tp.phrasings[v]).best == t for t, tp in data.items()) / len(data)
        for v in VARIANTS
    }


def summarise(rows: Sequence[Row]) -> dict[str, dict[str, dict[int, float]]]:
    """mode -> variant (and 'overall') -> k -> macro-mean recall over tasks."""
    out: dict[str, dict[str, dict[int, float]]] = {}
    for mode in dict.fromkeys(r.mode for r in rows):
        m = [r for r in rows if r.mode == mode]
        table: dict[str, dict[int, float]] = {}
        for variant in (*VARIANTS, "overall"):
            sel = m if variant == "overall" else [r for r in m if r.variant == variant]
            ks = sorted({r.k for r in sel})
            table[variant] = {k: _mean([r.recall for r in sel if r.k == k]) for k in ks}
        out[mode] = table
    return out


def _mean(xs: Sequence[float]) -> float:
    return sum(xs) / len(xs) if xs else 0.0


def run_study(
    registry: SkillRegistry, data: Mapping[str, TaskPhrasings], ks: Sequence[int] = KS
) -> dict[str, Any]:
    rows = (
        retriever_rows(registry, data, ks)
        + retriever_rows(registry, data, ks, include_body=True)
        + asyncio.run(harness_rows(registry, data, ks))
    )
    required = sorted({s for tp in data.values() for s in tp.required})
    return {
        "catalogue": list(registry.names()),
        "required_missing_from_catalogue": [s for s in required if s not in registry],
        "ks": list(ks),
        "summary": summarise(rows),
        "parser_task_accuracy": parser_accuracy(data),
        "rows": [asdict(r) for r in rows],
    }


def markdown(study: Mapping[str, Any]) -> str:
    ks: list[int] = study["ks"]
    summary = study["summary"]
    head = "| variant | " + " | ".join(f"{m} R@{k}" for m in MODES for k in ks) + " |"
    lines = [
        f"Catalogue: {len(study['catalogue'])} skills. Recall@K of required skills, macro "
        "mean over the 9 tasks.",
    ]
    if study["required_missing_from_catalogue"]:
        lines.append(
            "Required but absent from the catalogue (always a miss): "
            + ", ".join(study["required_missing_from_catalogue"])
        )
    lines += ["", head, "|---" * (1 + len(MODES) * len(ks)) + "|"]
    for variant in (*VARIANTS, "overall"):
        cells = [f"{summary[m][variant][k]:.2f}" for m in MODES for k in ks]
        name = f"**{variant}**" if variant == "overall" else variant
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    acc = study["parser_task_accuracy"]
    lines += [
        "",
        "Rule parser task-type accuracy: " + ", ".join(f"{v} {acc[v]:.2f}" for v in VARIANTS),
    ]
    kmax = max(ks)
    lines += ["", f"Misses at K={kmax} (text / harness):", ""]
    lines += ["| task | variant | text missed | harness missed |", "|---|---|---|---|"]
    by = {(r["mode"], r["task"], r["variant"]): r for r in study["rows"] if r["k"] == kmax}
    for (mode, task, variant), r in by.items():
        if mode != "text":
            continue
        h = by[("harness", task, variant)]
        if r["missed"] or h["missed"]:
            hm = ", ".join(h["missed"]) + (f" ({h['note']})" if h["note"] else "")
            lines.append(f"| {task} | {variant} | {', '.join(r['missed']) or '-'} | {hm or '-'} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m aeroweaver_lab.retrieval_eval",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("--skills", type=Path, default=None, help="skills root (default: shipped)")
    ap.add_argument("--phrasings", type=Path, default=DATA)
    ap.add_argument("--json", type=Path, default=None, help="write JSON here instead of stdout")
    ap.add_argument("--k", type=int, nargs="+", default=list(KS))
    args = ap.parse_args(argv)
    study = run_study(load_skills(args.skills), load_phrasings(args.phrasings), args.k)
    print(markdown(study))
    text = json.dumps(study, indent=2)
    if args.json is not None:
        args.json.write_text(text + "\n", encoding="utf-8")
    else:
        print("\n```json\n" + text + "\n```")
    return 0


if __name__ == "__main__":
    sys.exit(main())
