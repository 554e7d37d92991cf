"""PNG plots of a benchmark directory: return per task and condition, tokens per condition.

matplotlib is the optional ``plot`` extra; without it the tables are still written and one
line says how to get the plots.
"""

from __future__ import annotations

import statistics
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from aeroweaver_edge.bench.report import CellStats


def write_plots(
    out: Path,
    stats: dict[tuple[str, str], CellStats],
    tasks: Sequence[str],
    conditions: Sequence[str],
) -> list[Path]:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no plots (pip install -e '.[plot]')", file=sys.stderr)
        return []
    from aeroweaver_edge.bench.conditions import CONDITIONS

    tasks = [t for t in tasks if any((t, c) in stats for c in conditions)]
    conds = [c for c in conditions if any((t, c) in stats for t in tasks)]
    if not tasks:
        return []
    colours = plt.get_cmap("tab10")
    written = []

    cols = 3
    rows = (len(tasks) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.0 * rows), dpi=110, squeeze=False)
    for ax, task in zip(axes.flat, tasks, strict=False):
        for i, c in enumerate(conds):
            s = stats.get((task, c))
            if s is None or not s.returns:
                continue
            mean = statistics.fmean(s.returns)
            sd = statistics.stdev(s.returns) if len(s.returns) > 1 else 0.0
            ax.bar(i, mean, yerr=sd, color=colours(i % 10), capsize=3)
        ax.set_title(task, fontsize=9)
        ax.set_xticks(range(len(conds)))
        ax.set_xticklabels(
            [CONDITIONS[c].title for c in conds], rotation=45, ha="right", fontsize=7
        )
        ax.axhline(0, color="black", linewidth=0.5)
        ax.grid(axis="y", alpha=0.3)
    for ax in list(axes.flat)[len(tasks) :]:
        ax.set_visible(False)
    fig.suptitle("Episode return (mean ± SD over episodes)", fontsize=10)
    fig.tight_layout()
    path = out / "returns.png"
    fig.savefig(path)
    plt.close(fig)
    written.append(path)

    llm_conds = [c for c in conds if CONDITIONS[c].selector == "llm"]
    if llm_conds:
        fig, ax = plt.subplots(figsize=(max(6.0, 0.9 * len(tasks) + 2), 3.8), dpi=110)
        width = 0.8 / len(llm_conds)
        for i, c in enumerate(llm_conds):
            xs, ys = [], []
            for j, task in enumerate(tasks):
                s = stats.get((task, c))
                if s is not None and s.tokens and statistics.fmean(s.tokens) > 0:
                    xs.append(j + (i - (len(llm_conds) - 1) / 2) * width)
                    ys.append(statistics.fmean(s.tokens))
            ax.bar(
                xs, ys, width=width, label=CONDITIONS[c].title, color=colours(conds.index(c) % 10)
            )
        ax.set_yscale("log")
        ax.set_xticks(range(len(tasks)))
        ax.set_xticklabels(tasks, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel("tokens per episode (log)")
        ax.set_title("Tokens per episode by condition (UAVs' + central node's calls)", fontsize=10)
        ax.grid(axis="y", alpha=0.3, which="both")
        ax.legend(fontsize=7, ncol=2)
        fig.tight_layout()
        path = out / "tokens.png"
        fig.savefig(path)
        plt.close(fig)
        written.append(path)
    return written


__all__ = ["write_plots"]
