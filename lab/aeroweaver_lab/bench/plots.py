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
    from aeroweaver_lab.bench.cells import CellStats


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
        print("matplotlib not installed: no plots (pip install matplotlib)", file=sys.stderr)
        return []
    from aeroweaver_lab.bench.conditions import CONDITIONS

    tasks = [t for t in tasks if any((t, c) in stats for c in conditions)]
    conds = [c for c in conditions if any((t, c) in stats for t in tasks)]
    if not tasks:
        return []
    colours = plt.get_cmap("tab10")
    written = []
    about = _about(stats, tasks, conds)

    cols = 3
    rows = (len(tasks) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.0 * rows), dpi=110, squeeze=False)
    for ax, task in zip(axes.flat, tasks, strict=False):
        for i, c in enumerate(conds):
            s = stats.get((task, c))
            if s is None or not s.returns:
                continue
            n = len(s.returns)
            xs = [i - 0.25 + 0.5 * (k + 0.5) / n for k in range(n)]  # spread, not random
            ax.scatter(xs, s.returns, s=7, color=colours(i % 10), alpha=0.55, linewidths=0)
            mean = statistics.fmean(s.returns)
            ci = s.ci
            err = [[mean - ci[0]], [ci[1] - mean]] if ci else None
            ax.errorbar(i, mean, yerr=err, fmt="D", ms=4, color="black", capsize=3, lw=1)
        ax.set_title(task, fontsize=9)
        ax.set_xticks(range(len(conds)))
        ax.set_xticklabels(
            [CONDITIONS[c].title for c in conds], rotation=45, ha="right", fontsize=7
        )
        ax.axhline(0, color="black", linewidth=0.5)
        ax.grid(axis="y", alpha=0.3)
    for ax in list(axes.flat)[len(tasks) :]:
        ax.set_visible(False)
    fig.suptitle(
        "Episode return: each episode (dots), mean and 95 % bootstrap interval (black)\n" + about,
        fontsize=9,
    )
    fig.tight_layout()
    path = out / "returns.png"
    fig.savefig(path, metadata={"Software": None}, bbox_inches="tight")  # same in, same bytes
    plt.close(fig)
    written.append(path)

    llm_conds = [c for c in conds if CONDITIONS[c].selector == "llm"]
    if llm_conds:
        fig, ax = plt.subplots(figsize=(max(6.0, 0.9 * len(tasks) + 2), 3.8), dpi=110)
        width = 0.8 / len(llm_conds)
        for i, c in enumerate(llm_conds):
            colour = colours(conds.index(c) % 10)
            xs, ys = [], []
            for j, task in enumerate(tasks):
                s = stats.get((task, c))
                if s is None or not s.tokens or statistics.fmean(s.tokens) <= 0:
                    continue
                x = j + (i - (len(llm_conds) - 1) / 2) * width
                xs.append(x)
                ys.append(statistics.fmean(s.tokens))
                pts = [v for v in s.tokens if v > 0]
                ax.scatter([x] * len(pts), pts, s=5, color="black", alpha=0.5, linewidths=0)
            ax.bar(xs, ys, width=width, label=CONDITIONS[c].title, color=colour)
        ax.set_yscale("log")
        ax.set_xticks(range(len(tasks)))
        ax.set_xticklabels(tasks, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel("tokens per episode (log)")
        ax.set_title(
            "Tokens per episode: mean (bars) and each episode (dots); UAVs' + central node's "
            "calls + Commander setup\n" + about,
            fontsize=8,
        )
        ax.grid(axis="y", alpha=0.3, which="both")
        # outside the axes: a legend inside covered the tallest bars
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
        fig.tight_layout()
        path = out / "tokens.png"
        fig.savefig(path, metadata={"Software": None}, bbox_inches="tight")  # same in, same bytes
        plt.close(fig)
        written.append(path)
    return written


NOT_EVIDENCE = "smollm2"


def _about(
    stats: dict[tuple[str, str], CellStats], tasks: Sequence[str], conds: Sequence[str]
) -> str:
    """n, model and dates of what is plotted, and a warning for the embedded demo model."""
    shown = [s for (t, c), s in stats.items() if t in tasks and c in conds]
    models = sorted({s.model for s in shown if s.model})
    dates = sorted({d for s in shown for d in s.finished if d})
    ns = sorted({s.n for s in shown})
    n_text = (f"n = {ns[0]}" if len(ns) == 1 else f"n = {ns[0]}–{ns[-1]}") + " episodes per cell"
    when = (dates[0] if len(dates) == 1 else f"{dates[0]} to {dates[-1]}") if dates else "?"
    text = f"{n_text}; model {', '.join(models) or 'none'}; run {when}"
    if any(NOT_EVIDENCE in m.lower() for m in models):
        text += " (embedded 135M demo model: not evidence about the methods)"
    return text


__all__ = ["write_plots"]
