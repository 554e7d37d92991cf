"""Adaptation experiment: consecutive episodes with persistent, swarm-shared experience
memory, comparing experience-correction variants on the same layouts, on one endpoint.

``python -m aeroweaver_lab.bench.adaptation --tasks coverage goal_concealment \\
    --episodes 10 --seeds 1 --variants 0.8 0 0.8:final --selector scripted --out DIR``

A variant is ``<beta>`` or ``<beta>:final`` (retrieval uses only finalised returns, i.e.
experience of episodes that ended: ``agent.finalised_only``). Episode e of every variant
uses layout seed ``seed + e``, so variants differ only in the correction. Every
(task, seed, variant) run keeps its trace (and, with ``--keep-memory``, its memory files)
under ``DIR/runs/`` and is skipped when its result exists (resumable). Writes
``results.json``, ``results.csv``, ``table.md`` and ``team_return.png`` into ``DIR``;
``bench.adaptation_why`` explains the runs from their traces.

Paired mode (issue 24), the statistics a reviewer accepts::

    aeroweaver bench adaptation --base hold-biased --estimator horizon:3 --tasks all \
        --sequences 10 --episodes 10 --json OUT.json [--out DIR]

runs beta = 0 and beta = ``--beta`` (0.8) on the same seed sequences (sequence s uses layout
seeds ``1 + 1000 s + e``, e = 0..K-1) for every task, and writes ``{"base", "estimator",
"tasks": {task: {"mean_diff", "ci95", "better", "worse", "equal", "p_wilcoxon", ...}}}``:
``mean_diff`` is the mean over sequences of (beta run's mean return - beta 0 run's mean
return), ``ci95`` a seeded percentile bootstrap of it over sequences, better / worse /
equal count sequences, ``p_wilcoxon`` the two-sided signed-rank test over the per-sequence
differences (``bench.paired_stats``). One cell per (base, task, sequence, beta[,
estimator]) under ``DIR/runs/``, skipped when done (resumable; the beta = 0 cells do not
depend on the estimator and are shared); a progress line per cell; a learning-curve PNG
per task (mean return by episode index with a 95 % band) in
``DIR/curves/<base>/<estimator>/``. ``--base`` is a scripted base (``agent.scripted``:
reference, hold-biased, position-biased, noisy[:SD]) or ``llm`` (the ``--llm`` endpoint,
default the embedded model); ``--estimator`` one of ``agent.estimators`` (paper,
horizon:H, support:M, centre, mixed with commas).
"""

from __future__ import annotations

import argparse
import asyncio
import csv
import json
import math
import os
import shutil
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from aeroweaver_edge.agent import choices
from aeroweaver_edge.agent.estimators import Estimator
from aeroweaver_edge.agent.scripted import Base
from aeroweaver_edge.cli.errors import ArgumentParser
from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.contracts import defaults
from aeroweaver_edge.contracts.errors import RunFailed, UserError
from aeroweaver_edge.llm.embedded import THREADS_ENV
from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm
from aeroweaver_edge.runtime.json_out import write_json_file
from aeroweaver_edge.tasks import TASK_NAMES, canonical_task
from aeroweaver_lab.bench.episodes import episode_metrics, read_trace
from aeroweaver_lab.bench.paired_stats import paired_summary
from aeroweaver_lab.bench.runner import llm_failure_problem, preflight


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
    *,
    base: str = "reference",
    estimator: str = "paper",
    max_rounds: int | None = None,
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
            max_rounds=max_rounds or defaults.MAX_ROUNDS,
            estimator=estimator,
            scripted_base=base,
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
        "base": base if selector == "scripted" else selector,  # the scripted base is unused
        "estimator": estimator,
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
    unusable = llm_failure_problem(eps) if selector == "llm" else None
    if unusable is not None:  # kept to read, rerun on resume; hours of holds are no evidence
        result.update(complete=False, unusable=unusable)
    write_json_file(run_dir / "result.json", result)
    if unusable is not None:
        raise RunFailed(
            f"{task} seed {seed} beta={variant.beta:g}: {unusable}; fix the endpoint (or "
            "raise --llm-deadline), then rerun the same command to resume"
        )
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
    if args.selector == "llm" and llm.base_url:  # the embedded server is probed as it starts
        await preflight(llm)
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
        print("matplotlib not installed: no plot (pip install matplotlib)", file=sys.stderr)
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


# ---------------------------------------------------------------- paired mode (issue 24)

SEQUENCE_STRIDE = 1000  # sequence s uses layout seeds 1 + 1000 s + e: never overlapping


def sequence_seed(s: int) -> int:
    return 1 + SEQUENCE_STRIDE * s


def _cell_dir(out: Path, base: str, task: str, seq: int, beta: float, estimator: str) -> Path:
    """beta = 0 never consults the estimator (``decision_round``): its cells are shared."""
    name = "b0" if beta == 0 else f"b{beta:g}-{estimator.replace(':', '').replace(',', '-')}"
    return out / "runs" / base.replace(":", "") / task / f"seq{seq}" / name


def _returns(cell: dict[str, Any]) -> list[float]:
    return [float(e["team_return"]) for e in cell["episodes"]]


async def run_paired(args: argparse.Namespace, llm: LLMConfig) -> dict[str, Any]:
    """Every (task, sequence, beta) cell, resuming the ones done; the summary."""
    out = Path(args.out)
    selector: Literal["llm", "scripted"] = "llm" if args.base == "llm" else "scripted"
    base = "reference" if args.base == "llm" else args.base
    todo = [
        (task, seq, beta)
        for task in args.tasks
        for seq in range(args.sequences)
        for beta in (0.0, args.beta)
    ]
    if selector == "llm" and llm.base_url:  # the embedded server is probed as it starts
        await preflight(llm)
    cells: dict[tuple[str, int, float], dict[str, Any]] = {}
    started = time.monotonic()
    ran = 0
    slots = asyncio.Semaphore(max(1, args.jobs))  # FIFO: cells start in plan order

    async def cell(n: int, task: str, seq: int, beta: float) -> None:
        nonlocal ran
        run_dir = _cell_dir(out, args.base, task, seq, beta, args.estimator)
        done = _load(run_dir / "result.json")
        if done is None or len(done["episodes"]) != args.episodes:
            async with slots:
                done = await run_one(
                    task, sequence_seed(seq), Variant(beta), args.episodes, args.uavs,
                    selector, llm, run_dir, args.keep_memory, args.deadline, base=base,
                    estimator=args.estimator, max_rounds=args.rounds,
                )  # fmt: skip
            ran += 1
            left = sum(
                1
                for t, q, b in todo
                if _load(_cell_dir(out, args.base, t, q, b, args.estimator) / "result.json") is None
            )
            per = (time.monotonic() - started) / ran  # wall time per cell, jobs included
            print(
                f"[{n}/{len(todo)}] {task} seq {seq} beta={beta:g}: mean return "
                f"{statistics.fmean(_returns(done)):.2f} ({done['wall_s']:.1f} s; "
                f"about {left * per / 60:.0f} min left)",
                file=sys.stderr,
                flush=True,
            )
        cells[(task, seq, beta)] = done

    tasks = [
        asyncio.create_task(cell(n, *c), name=f"adaptation-cell-{n}") for n, c in enumerate(todo, 1)
    ]
    try:  # the first failure as it is (a UserError stays one line); a rerun resumes
        await asyncio.gather(*tasks)
    finally:
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    return summarise(args, cells)


def summarise(
    args: argparse.Namespace, cells: dict[tuple[str, int, float], dict[str, Any]]
) -> dict[str, Any]:
    tasks: dict[str, Any] = {}
    for task in args.tasks:
        zero = [cells[(task, s, 0.0)] for s in range(args.sequences)]
        beta = [cells[(task, s, args.beta)] for s in range(args.sequences)]
        rec = paired_summary(
            [statistics.fmean(_returns(c)) for c in beta],
            [statistics.fmean(_returns(c)) for c in zero],
        )
        eps = [
            x - y
            for b, z in zip(beta, zero, strict=True)
            for x, y in zip(_returns(b), _returns(z), strict=True)
        ]
        holds = {
            name: [sum(e["holds_by_cause"].get("chosen", 0) for e in c["episodes"]) for c in cs]
            for name, cs in (("beta0", zero), ("beta", beta))
        }
        tasks[task] = {
            **rec,
            "episodes_better": sum(d > 1e-9 for d in eps),
            "episodes_worse": sum(d < -1e-9 for d in eps),
            "episodes_equal": sum(abs(d) <= 1e-9 for d in eps),
            "beta0_mean": statistics.fmean(statistics.fmean(_returns(c)) for c in zero),
            "beta_mean": statistics.fmean(statistics.fmean(_returns(c)) for c in beta),
            "chosen_holds_per_sequence": holds,
        }
    wins = sum(t["ci95"][0] > 0 for t in tasks.values())
    losses = sum(t["ci95"][1] < 0 for t in tasks.values())
    first = cells[(args.tasks[0], 0, 0.0)]
    return {
        "base": args.base,
        "estimator": args.estimator,
        "beta": args.beta,
        "sequences": args.sequences,
        "episodes": args.episodes,
        "rounds": args.rounds,
        "seeds": [sequence_seed(s) for s in range(args.sequences)],
        "selector": first["selector"] if args.base == "llm" else f"scripted:{args.base}",
        "note": first.get("note"),
        "tasks": tasks,
        "verdict": {"ci95_lo_above_0": wins, "ci95_hi_below_0": losses},
        "command": args.command,
    }


def curves(
    args: argparse.Namespace, cells: dict[tuple[str, int, float], dict[str, Any]], out: Path
) -> list[Path]:
    """Learning curves per task: mean return by episode index over sequences, 95 % band
    (normal approximation, mean +- 1.96 SE)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no curves (pip install matplotlib)", file=sys.stderr)
        return []
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for task in args.tasks:
        fig, ax = plt.subplots(figsize=(5.0, 3.4), dpi=110)
        for beta, label in ((0.0, "beta=0"), (args.beta, f"beta={args.beta:g} {args.estimator}")):
            runs = [_returns(cells[(task, s, beta)]) for s in range(args.sequences)]
            xs = list(range(args.episodes))
            ys = [statistics.fmean(r[i] for r in runs) for i in xs]
            se = [
                statistics.stdev(r[i] for r in runs) / math.sqrt(len(runs)) if len(runs) > 1 else 0
                for i in xs
            ]
            ax.plot(xs, ys, marker="o", label=label)
            ax.fill_between(
                xs, [y - 1.96 * e for y, e in zip(ys, se, strict=True)],
                [y + 1.96 * e for y, e in zip(ys, se, strict=True)], alpha=0.2,
            )  # fmt: skip
        ax.set_title(f"{task}: base {args.base}, {args.sequences} sequences", fontsize=9)
        ax.set_xlabel("episode (memory persists)")
        ax.set_ylabel("team return")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        path = out / f"{task}.png"
        fig.savefig(path)
        plt.close(fig)
        paths.append(path)
    return paths


def _task_list(text: str) -> str:
    return "all" if text == "all" else canonical_task(text)


def _base(text: str) -> str:
    if text == "llm":
        return text
    try:
        return Base.parse(text).name
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{exc} (or llm)") from None


def _estimator(text: str) -> str:
    try:
        return Estimator.parse(text).name
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _positive(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a whole number >= 1")
    return n


def main_paired(args: argparse.Namespace, llm: LLMConfig) -> int:
    json_path = Path(args.json)
    if args.out is None:
        args.out = str(json_path.with_suffix("")) + "-runs"
    data = asyncio.run(run_paired(args, llm))
    cells = {
        (t, s, b): c
        for t in args.tasks
        for s in range(args.sequences)
        for b in (0.0, args.beta)
        if (c := _load(_cell_dir(Path(args.out), args.base, t, s, b, args.estimator)
                       / "result.json")) is not None
    }  # fmt: skip
    where = Path(args.out) / "curves" / args.base.replace(":", "") / args.estimator.replace(":", "")
    pngs = curves(args, cells, where)
    data["curves"] = [str(p) for p in pngs]
    write_json_file(json_path, data)
    for task, t in data["tasks"].items():
        print(
            f"{task}: mean_diff {t['mean_diff']:+.2f} ci95 [{t['ci95'][0]:+.2f}, "
            f"{t['ci95'][1]:+.2f}] better/worse/equal {t['better']}/{t['worse']}/{t['equal']} "
            f"p {t['p_wilcoxon']:.3g}"
        )
    v = data["verdict"]
    print(
        f"{args.estimator} on base {args.base}: ci95 above 0 on {v['ci95_lo_above_0']} of "
        f"{len(args.tasks)} tasks, below 0 on {v['ci95_hi_below_0']}; wrote {json_path}"
    )
    return 0


def main(argv: list[str] | None = None, *, prog: str | None = None) -> int:
    p = ArgumentParser(prog=prog or "python -m aeroweaver_lab.bench.adaptation")
    p.add_argument(
        "--tasks",
        nargs="+",
        type=_task_list,
        choices=[*TASK_NAMES, "all"],
        default=["coverage"],
        help="tasks, or all",
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
    p.add_argument("--out", default=None, help="run directory (default: docs/adaptation)")
    paired = p.add_argument_group("paired mode (beta = 0 against --beta, issue 24)")
    paired.add_argument("--json", metavar="OUT", help="paired mode: write the summary here")
    paired.add_argument(
        "--base", type=_base, default=None,
        help="reference, hold-biased, position-biased, noisy[:SD] (scripted) or llm; "
        "default: AEROWEAVER_SCRIPTED_BASE, else reference",
    )  # fmt: skip
    paired.add_argument(
        "--estimator", type=_estimator, default=None,
        help="paper, horizon:H, centre, support:M, shrink:K, scale or tscore, comma-joined "
        "(horizon:3,centre); default: AEROWEAVER_ESTIMATOR, else paper",
    )  # fmt: skip
    paired.add_argument("--sequences", type=_positive, default=None, help="seed sequences")
    paired.add_argument("--beta", type=float, default=0.8, help="the corrected run's beta")
    paired.add_argument("--rounds", type=_positive, default=None, help="rounds per episode")
    paired.add_argument(
        "--jobs", type=_positive, default=1,
        help="cells run at once (with the embedded model each cell's server then gets one "
        "thread, as in bench run)",
    )  # fmt: skip
    args = p.parse_args(argv)
    if "all" in args.tasks:
        args.tasks = list(TASK_NAMES)
    args.tasks = list(dict.fromkeys(args.tasks))
    if args.json is not None or args.sequences is not None:
        if args.json is None:
            p.error("paired mode (--sequences) needs --json OUT")
        if args.variants or args.betas or args.seeds:
            p.error("paired mode runs beta = 0 and --beta: no --variants, --betas or --seeds")
        if not (math.isfinite(args.beta) and args.beta > 0):
            p.error(f"--beta {args.beta!r}: the corrected run needs a positive finite beta")
        # flag > environment > default, as for aeroweaver sim (agent.choices)
        try:
            args.base = args.base or choices.resolve("scripted_base")
            args.estimator = choices.resolve("estimator", args.estimator)
        except UserError as exc:
            p.error(str(exc))
        args.sequences = args.sequences or 3
        if args.jobs > 1 and args.base == "llm" and not args.llm:
            os.environ.setdefault(THREADS_ENV, "1")  # one server per cell, one core each
        args.deadline = args.deadline or (10.0 if args.base != "llm" else args.llm_deadline + 15)
        args.command = f"{prog or 'python -m aeroweaver_lab.bench.adaptation'} " + " ".join(
            argv if argv is not None else sys.argv[1:]
        )
        llm = LLMConfig(
            base_url=args.llm,
            deadline_s=args.llm_deadline,
            **({"model": args.model} if args.model else {}),
        )
        return main_paired(args, llm)
    if args.base is not None or args.estimator is not None or args.rounds is not None:
        p.error("--base, --estimator and --rounds belong to paired mode (--json OUT)")
    if args.jobs != 1:
        p.error("--jobs belongs to paired mode (--json OUT)")
    args.out = args.out or "docs/adaptation"
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
    command = "python -m aeroweaver_lab.bench.adaptation " + " ".join(argv or sys.argv[1:])
    write_reports(results, Path(args.out), command)
    print((Path(args.out) / "table.md").read_text(encoding="utf-8"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
