"""Adaptation experiment: consecutive episodes with persistent, swarm-shared experience
memory, comparing experience-correction variants on the same layouts, on one endpoint.

``python -m aeroweaver_edge.bench.adaptation --tasks coverage goal_concealment \\
    --episodes 10 --seeds 1 --variants 0.8 0 0.8:final --selector scripted --out DIR``

A variant is ``<beta>`` or ``<beta>:final`` (retrieval uses only finalised returns, i.e.
experience of episodes that ended: ``agent.finalised_only``). Episode e of every variant
uses layout seed ``seed + e``, so variants differ only in the correction. Every
(task, seed, variant) run keeps its trace (and, with ``--keep-memory``, its memory files)
under ``DIR/runs/`` and is skipped when its result exists (resumable). Writes
``results.json``, ``results.csv``, ``table.md`` and ``team_return.png`` into ``DIR``;
``bench.adaptation_why`` explains the runs from their traces.
"""

from __future__ import annotations

import argparse
import asyncio
import csv
import json
import math
import shutil
import statistics
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from aeroweaver_edge.bench.episodes import episode_metrics, read_trace
from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.json_out import write_json_file
from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm
from aeroweaver_edge.tasks import TASK_NAMES, canonical_task


@dataclass(frozen=True)
class Variant:
    beta: float
    finalised_only: bool = False

    @property
    def name(self) -> str:
        return f"beta={self.beta:g}" + (" final-only" if self.finalised_only else "")

    @property
    def slug(self) -> str:
        return f"b{self.beta:g}" + ("-final" if self.finalised_only else "")

    @classmethod
    def parse(cls, text: str) -> Variant:
        beta_text, _, flag = text.partition(":")
        try:
            beta = float(beta_text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: expected BETA or BETA:final") from None
        if not math.isfinite(beta) or beta < 0 or flag not in ("", "final"):
            raise argparse.ArgumentTypeError(f"{text!r}: expected BETA >= 0, optionally :final")
        return cls(beta, flag == "final")


def _decisions(trace: list[dict[str, Any]]) -> dict[int, dict[str, int]]:
    """Per episode: decisions, corrected picks and bound-rule fallbacks (from the trace)."""
    out: dict[int, dict[str, int]] = {}
    for row in trace:
        if row.get("type") != "round":
            continue
        e = out.setdefault(row["episode"], {"corrected": 0, "bound_rule": 0})
        for d in row.get("decisions", {}).values():
            e["corrected"] += bool(d.get("corrected"))
            e["bound_rule"] += str(d.get("reason", "")).startswith("bound rule")
    return out


async def run_one(
    task: str,
    seed: int,
    variant: Variant,
    episodes: int,
    uavs: int | None,
    selector: Literal["llm", "scripted"],
    llm: LLMConfig,
    run_dir: Path,
    keep_memory: bool,
    deadline_s: float,
) -> dict[str, Any]:
    await asyncio.to_thread(run_dir.mkdir, parents=True, exist_ok=True)
    trace_path = run_dir / "trace.jsonl"
    with tempfile.TemporaryDirectory(prefix="aw-adapt-") as tmp:
        mem = Path(tmp)
        opts = SwarmOptions(
            task=task,
            uavs=uavs,
            seed=seed,
            episodes=episodes,
            selector=selector,
            llm=llm,
            beta=variant.beta,
            finalised_only=variant.finalised_only,
            memory_dir=mem,
            trace_path=trace_path,
            deadline_s=deadline_s,
        )
        summary = (await run_swarm(opts)).as_dict()
        if keep_memory:
            shutil.copytree(mem, run_dir / "memory", dirs_exist_ok=True)
    trace = read_trace(trace_path)
    eps = episode_metrics(trace)
    extra = _decisions(trace)
    result = {
        "task": task,
        "seed": seed,
        "variant": variant.name,
        "beta": variant.beta,
        "finalised_only": variant.finalised_only,
        "selector": summary["selector"],
        "model": summary["model"],
        "probe": summary["probe"],
        "note": summary["note"],
        "uavs": summary["uavs"],
        "episodes": [
            {
                "episode": e["episode"],
                "team_return": e["team_return"],
                "rounds": e["rounds"],
                "reason": e["reason"],
                "decisions": e["decisions"],
                "holds": e["holds"],
                "holds_by_cause": e["holds_by_cause"],
                "llm_calls": e["llm_calls_total"],
                "tokens": e["tokens_total"],
                **extra.get(e["episode"], {"corrected": 0, "bound_rule": 0}),
            }
            for e in eps
        ],
        "wall_s": summary["wall_s"],
        "trace": str(trace_path),
        "complete": True,
    }
    write_json_file(run_dir / "result.json", result)
    return result


def _load(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and data.get("complete") else None


async def run_all(args: argparse.Namespace, llm: LLMConfig) -> list[dict[str, Any]]:
    out = Path(args.out)
    results = []
    for task in args.tasks:
        for seed in args.seeds:
            for v in args.variants:
                run_dir = out / "runs" / task / f"seed{seed}" / v.slug
                done = _load(run_dir / "result.json")
                if done is not None and len(done["episodes"]) == args.episodes:
                    results.append(done)
                    continue
                r = await run_one(
                    task,
                    seed,
                    v,
                    args.episodes,
                    args.uavs,
                    args.selector,
                    llm,
                    run_dir,
                    args.keep_memory,
                    args.deadline,
                )
                rets = ", ".join(f"{e['team_return']:.2f}" for e in r["episodes"])
                print(f"{task} seed {seed} {v.name}: {rets}", file=sys.stderr, flush=True)
                results.append(r)
    return results


def _fmt(x: float | None) -> str:
    return "–" if x is None or math.isnan(x) else f"{x:.2f}"


def table(results: list[dict[str, Any]], command: str) -> str:
    first = results[0]
    lines = [
        f"Selector: `{first['selector']}`; probe: {first.get('probe')}.",
        "",
        f"Command: `{command}`",
        "",
    ]
    variants = list(dict.fromkeys(r["variant"] for r in results))
    lines += [
        "| task | seed | variant | mean team return ± SD | episodes 1.. (0 excluded) mean | "
        "holds (chosen / other) | corrected picks | bound-rule fallbacks |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        rets = [e["team_return"] for e in r["episodes"] if e["team_return"] is not None]
        later = rets[1:]
        chosen = sum(e["holds_by_cause"]["chosen"] for e in r["episodes"])
        holds = sum(e["holds"] for e in r["episodes"])
        sd = statistics.stdev(rets) if len(rets) > 1 else math.nan
        lines.append(
            f"| {r['task']} | {r['seed']} | {r['variant']} | {_fmt(statistics.fmean(rets))} ± "
            f"{_fmt(sd)} | {_fmt(statistics.fmean(later) if later else math.nan)} | "
            f"{chosen} / {holds - chosen} | {sum(e['corrected'] for e in r['episodes'])} | "
            f"{sum(e['bound_rule'] for e in r['episodes'])} |"
        )
    base = variants[-1] if "beta=0" not in variants else "beta=0"
    lines += ["", f"Paired by episode against `{base}` (better / worse / equal):", ""]
    for v in variants:
        if v == base:
            continue
        b = w = eq = 0
        diffs = []
        for r in results:
            if r["variant"] != v:
                continue
            twin = next(
                (
                    x
                    for x in results
                    if x["variant"] == base and x["task"] == r["task"] and x["seed"] == r["seed"]
                ),
                None,
            )
            if twin is None:
                continue
            for e, f in zip(r["episodes"], twin["episodes"], strict=False):
                d = e["team_return"] - f["team_return"]
                diffs.append(d)
                b, w, eq = b + (d > 1e-9), w + (d < -1e-9), eq + (abs(d) <= 1e-9)
        mean = statistics.fmean(diffs) if diffs else math.nan
        lines.append(f"- `{v}`: {b} / {w} / {eq} of {len(diffs)}; mean difference {_fmt(mean)}")
    if first.get("note"):
        lines += ["", f"> {first['note']}"]
    return "\n".join(lines) + "\n"


def write_reports(results: list[dict[str, Any]], out: Path, command: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    write_json_file(out / "results.json", {"command": command, "runs": results})
    with (out / "results.csv").open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(
            [
                "task",
                "seed",
                "variant",
                "episode",
                "team_return",
                "rounds",
                "reason",
                "decisions",
                "holds",
                "holds_chosen",
                "corrected",
                "bound_rule",
                "llm_calls",
                "tokens",
            ]
        )
        for r in results:
            for e in r["episodes"]:
                w.writerow(
                    [
                        r["task"],
                        r["seed"],
                        r["variant"],
                        e["episode"],
                        e["team_return"],
                        e["rounds"],
                        e["reason"],
                        e["decisions"],
                        e["holds"],
                        e["holds_by_cause"]["chosen"],
                        e["corrected"],
                        e["bound_rule"],
                        e["llm_calls"],
                        e["tokens"],
                    ]
                )
    (out / "table.md").write_text(table(results, command), encoding="utf-8")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no plot (pip install -e '.[plot]')", file=sys.stderr)
        return
    tasks = list(dict.fromkeys(r["task"] for r in results))
    fig, axes = plt.subplots(1, len(tasks), figsize=(4.4 * len(tasks), 3.4), dpi=110, squeeze=False)
    for ax, task in zip(axes[0], tasks, strict=True):
        by_variant: dict[str, list[list[float]]] = {}
        for r in results:
            if r["task"] == task:
                by_variant.setdefault(r["variant"], []).append(
                    [e["team_return"] for e in r["episodes"]]
                )
        for v, runs in by_variant.items():
            n = min(len(x) for x in runs)
            ys = [statistics.fmean(x[i] for x in runs) for i in range(n)]
            ax.plot(range(n), ys, marker="o", label=v)
        ax.set_title(task, fontsize=9)
        ax.set_xlabel("episode (memory persists)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("team return (mean over seed sequences)")
    axes[0][-1].legend(fontsize=7)
    fig.suptitle(f"Adaptation: {results[0]['selector']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "team_return.png")
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m aeroweaver_edge.bench.adaptation")
    p.add_argument(
        "--tasks", nargs="+", type=canonical_task, choices=TASK_NAMES, default=["coverage"]
    )
    p.add_argument("--episodes", type=int, default=8)
    p.add_argument("--seeds", type=int, nargs="+", default=None, help="seed sequences")
    p.add_argument("--seed", type=int, default=1, help="one seed sequence (if no --seeds)")
    p.add_argument("--uavs", type=int, default=None, help="default: each task's team")
    p.add_argument(
        "--variants",
        type=Variant.parse,
        nargs="+",
        default=None,
        help="BETA or BETA:final (default: 0.8 0)",
    )
    p.add_argument("--betas", type=float, nargs="+", default=None, help="same as --variants")
    p.add_argument("--selector", choices=["llm", "scripted"], default="llm")
    p.add_argument("--llm", help="endpoint base URL (default: embedded SmolLM2)")
    p.add_argument("--model")
    p.add_argument("--llm-deadline", type=float, default=20.0)
    p.add_argument("--deadline", type=float, default=None, help="round deadline (s)")
    p.add_argument("--keep-memory", action="store_true", help="copy memory files to the run")
    p.add_argument("--out", default="docs/adaptation")
    args = p.parse_args(argv)
    args.seeds = args.seeds or [args.seed]
    if args.variants is None:
        args.variants = [Variant(b) for b in (args.betas or [0.8, 0.0])]
    args.deadline = args.deadline or (
        10.0 if args.selector == "scripted" else args.llm_deadline + 15
    )
    llm = LLMConfig(
        base_url=args.llm,
        deadline_s=args.llm_deadline,
        **({"model": args.model} if args.model else {}),
    )
    results = asyncio.run(run_all(args, llm))
    command = "python -m aeroweaver_edge.bench.adaptation " + " ".join(argv or sys.argv[1:])
    write_reports(results, Path(args.out), command)
    print((Path(args.out) / "table.md").read_text(encoding="utf-8"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
