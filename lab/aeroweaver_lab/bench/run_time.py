"""How long a benchmark run took, from its cells alone (so ``--report-only`` rebuilds it).

A run resumes across sittings and runs cells side by side (``--jobs``), so neither the sum
of cell times nor first-to-last finish is its wall time. Each cell records when it
finished and how long it took; the union of those intervals is the time the machine spent
on cells (setups and the gaps between sittings excluded), and a gap longer than
``SITTING_GAP_S`` separates sittings.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any, Final

SITTING_GAP_S: Final = 600.0


@dataclass
class RunTime:
    cells: int = 0  # cells with a finish time and a duration
    undated: int = 0  # cells recorded without them (older runs)
    busy_s: float = 0.0  # union of the cells' intervals
    cell_s: float = 0.0  # sum of the cells' durations
    sittings: list[tuple[str, str]] = field(default_factory=list)  # (start, end), UTC
    load: tuple[float, float] | None = None  # 1-min load average at cell starts: min, max
    by_condition: dict[str, tuple[int, float]] = field(default_factory=dict)  # n, seconds

    def figures(self) -> dict[str, Any]:
        return {
            "cells": self.cells,
            "undated_cells": self.undated,
            "busy_h": round(self.busy_s / 3600, 3),
            "cell_time_h": round(self.cell_s / 3600, 3),
            "sittings": [list(s) for s in self.sittings],
            "load_at_cell_start": None if self.load is None else list(self.load),
            "mean_cell_s": {
                c: round(s / n, 1) for c, (n, s) in sorted(self.by_condition.items()) if n
            },
        }


def _interval(bench: dict[str, Any]) -> tuple[float, float] | None:
    try:
        end = datetime.fromisoformat(str(bench["finished"])).timestamp()
        wall = float(bench["wall_s"])
    except (KeyError, TypeError, ValueError):
        return None
    return (end - wall, end) if wall >= 0 else None


def _utc(ts: float) -> str:
    return datetime.fromtimestamp(ts, tz=UTC).strftime("%Y-%m-%d %H:%M")


def _merged(spans: Iterable[tuple[float, float]], gap: float) -> list[list[float]]:
    """The intervals joined where one starts at most ``gap`` seconds after the last ended."""
    out: list[list[float]] = []
    for start, end in sorted(spans):
        if out and start - out[-1][1] <= gap:
            out[-1][1] = max(out[-1][1], end)
        else:
            out.append([start, end])
    return out


def run_time(cells: Iterable[dict[str, Any]]) -> RunTime:
    rt = RunTime()
    spans: list[tuple[float, float]] = []
    loads: list[float] = []
    for data in cells:
        bench = data["bench"]
        span = _interval(bench)
        if span is None:
            rt.undated += 1
            continue
        rt.cells += 1
        spans.append(span)
        rt.cell_s += span[1] - span[0]
        n, s = rt.by_condition.get(bench["condition"], (0, 0.0))
        rt.by_condition[bench["condition"]] = (n + 1, s + span[1] - span[0])
        before = bench.get("load_before")
        if isinstance(before, Sequence) and before and isinstance(before[0], (int, float)):
            loads.append(float(before[0]))
    if loads:
        rt.load = (min(loads), max(loads))
    rt.busy_s = sum(end - start for start, end in _merged(spans, 0.0))
    rt.sittings = [(_utc(start), _utc(end)) for start, end in _merged(spans, SITTING_GAP_S)]
    return rt


def markdown(rt: RunTime) -> list[str]:
    if not rt.cells:
        return []
    load = ""
    if rt.load is not None:
        load = f"; load average at cell starts {rt.load[0]:.1f}–{rt.load[1]:.1f}"
    sittings = ", ".join(f"{a} to {b[-5:] if a[:10] == b[:10] else b}" for a, b in rt.sittings)
    means = ", ".join(f"{c} {s / n:.0f} s" for c, (n, s) in sorted(rt.by_condition.items()) if n)
    undated = f" ({rt.undated} cells recorded without times are left out)" if rt.undated else ""
    return [
        "### Run time",
        "",
        f"{rt.cells} cells{undated}: **{rt.busy_s / 3600:.2f} h** on cells (the union of the "
        f"cells' intervals; setups and the gaps between sittings excluded), "
        f"{rt.cell_s / 3600:.2f} h of cell time, in {len(rt.sittings)} sitting(s) "
        f"({sittings}, UTC){load}. Mean seconds per cell: {means}.",
        "",
    ]


__all__ = ["SITTING_GAP_S", "RunTime", "markdown", "run_time"]
