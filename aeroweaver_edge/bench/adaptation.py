"""Adaptation experiment: consecutive episodes with persistent experience memory,
``beta`` > 0 against ``beta = 0``, the same seeds, on one endpoint.

``python -m aeroweaver_edge.bench.adaptation --episodes 8 --out docs/adaptation``

Episode e of every condition uses layout seed ``seed + e``, so the conditions differ only in
the experience correction. Writes ``results.json``, ``results.csv``, ``table.md`` and
``team_return.png`` (if matplotlib is installed) into ``--out``.
"""

from __future__ import annotations

import argparse
import asyncio
import csv
import json
import math
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any, Literal

from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm


async def run_conditions(
    betas: list[float],
    episodes: int,
    seed: int,
    uavs: int,
    selector: Literal["llm", "scripted"],
    llm: LLMConfig,
) -> dict[str, Any]:
    out: dict[str, Any] = {"seed": seed, "episodes": episodes, "uavs": uavs, "conditions": {}}
    for beta in betas:
        with tempfile.TemporaryDirectory(prefix=f"aw-adapt-b{beta}-") as mem:
            opts = SwarmOptions(
                uavs=uavs,
                seed=seed,
                episodes=episodes,
                selector=selector,
                llm=llm,
                beta=beta,
                memory_dir=Path(mem),
            )
            summary = (await run_swarm(opts)).as_dict()
        out["conditions"][f"beta={beta:g}"] = {
            "beta": beta,
            "team_return": [e["team_return"] for e in summary["episodes"]],
            "rounds": [e["rounds"] for e in summary["episodes"]],
            "reason": [e["reason"] for e in summary["episodes"]],
            "tokens": summary["tokens"],
            "llm_calls": summary["llm_calls"],
            "holds": summary["holds"],
            "wall_s": summary["wall_s"],
        }
        out.update(model=summary["model"], probe=summary["probe"], note=summary["note"])
        out["selector"] = summary["selector"]
    return out


def _fmt(x: float) -> str:
    return "nan" if math.isnan(x) else f"{x:.2f}"


def write_reports(data: dict[str, Any], out: Path, command: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    conds = data["conditions"]
    with (out / "results.csv").open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["condition", "episode", "team_return", "rounds", "reason"])
        for name, c in conds.items():
            for e, (r, n, why) in enumerate(
                zip(c["team_return"], c["rounds"], c["reason"], strict=True)
            ):
                w.writerow([name, e, r, n, why])
    names = list(conds)
    lines = [
        f"Selector: `{data['selector']}`; probe: {data.get('probe')}; {data['uavs']} UAVs; "
        f"layout seed of episode e = {data['seed']} + e.",
        "",
        f"Command: `{command}`",
        "",
        "| episode | " + " | ".join(names) + " |",
        "|---" * (len(names) + 1) + "|",
    ]
    for e in range(data["episodes"]):
        lines.append(
            f"| {e} | " + " | ".join(_fmt(conds[n]["team_return"][e]) for n in names) + " |"
        )
    means = [statistics.fmean(conds[n]["team_return"]) for n in names]
    sds = [statistics.pstdev(conds[n]["team_return"]) for n in names]
    lines.append(
        "| mean ± SD | "
        + " | ".join(f"{m:.2f} ± {s:.2f}" for m, s in zip(means, sds, strict=True))
        + " |"
    )
    lines.append(
        "| tokens | " + " | ".join(str(conds[n]["tokens"].get("total", 0)) for n in names) + " |"
    )
    if data.get("note"):
        lines += ["", f"> {data['note']}"]
    (out / "table.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no plot (pip install -e '.[plot]')", file=sys.stderr)
        return
    fig, ax = plt.subplots(figsize=(6.4, 3.8), dpi=120)
    for n in names:
        ys = conds[n]["team_return"]
        ax.plot(range(len(ys)), ys, marker="o", label=n)
    ax.set_xticks(range(data["episodes"]))
    ax.set_xlabel("episode (memory persists across episodes)")
    ax.set_ylabel("mean team return")
    ax.set_title(f"Coverage, {data['uavs']} UAVs, {data['selector']}")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "team_return.png")
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m aeroweaver_edge.bench.adaptation")
    p.add_argument("--episodes", type=int, default=8)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--uavs", type=int, default=3)
    p.add_argument("--betas", type=float, nargs="+", default=[0.8, 0.0])
    p.add_argument("--selector", choices=["llm", "scripted"], default="llm")
    p.add_argument("--llm", help="endpoint base URL (default: embedded SmolLM2)")
    p.add_argument("--model")
    p.add_argument("--out", default="docs/adaptation")
    args = p.parse_args(argv)
    llm = LLMConfig(base_url=args.llm, **({"model": args.model} if args.model else {}))
    data = asyncio.run(
        run_conditions(args.betas, args.episodes, args.seed, args.uavs, args.selector, llm)
    )
    command = "python -m aeroweaver_edge.bench.adaptation " + " ".join(argv or sys.argv[1:])
    write_reports(data, Path(args.out), command)
    print((Path(args.out) / "table.md").read_text(encoding="utf-8"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
