"""A run's wall time from its cells: side-by-side cells count once, sittings split on gaps."""

from __future__ import annotations

from typing import Any

from aeroweaver_lab.bench.run_time import markdown, run_time


def cell(condition: str, finished: str, wall_s: float, load: float = 1.0) -> dict[str, Any]:
    return {
        "bench": {
            "condition": condition,
            "finished": finished,
            "wall_s": wall_s,
            "load_before": [load, load, load],
        }
    }


def test_overlapping_cells_count_once_and_a_long_gap_starts_a_sitting() -> None:
    cells = [
        cell("aeroweaver", "2026-12-03T10:10:00+00:00", 600.0, 2.0),  # 10:00-10:10
        cell("hmas2", "2026-12-03T10:15:00+00:00", 900.0, 3.5),  # 10:00-10:15, beside it
        cell("aeroweaver", "2026-12-03T10:20:00+00:00", 120.0),  # 10:18-10:20 (short gap)
        cell("scripted", "2026-12-03T12:01:00+00:00", 60.0, 0.5),  # next sitting
        {"bench": {"condition": "beta0", "finished": "2026-12-03T09:00:00+00:00"}},  # no wall_s
    ]
    rt = run_time(cells)
    assert (rt.cells, rt.undated) == (4, 1)
    assert rt.busy_s == 900 + 120 + 60
    assert rt.cell_s == 600 + 900 + 120 + 60
    assert rt.sittings == [
        ("2026-12-03 10:00", "2026-12-03 10:20"),
        ("2026-12-03 12:00", "2026-12-03 12:01"),
    ]
    assert rt.load == (0.5, 3.5)
    assert rt.figures()["mean_cell_s"] == {"aeroweaver": 360.0, "hmas2": 900.0, "scripted": 60.0}
    text = "\n".join(markdown(rt))
    assert "**0.30 h** on cells" in text
    assert "2 sitting(s) (2026-12-03 10:00 to 10:20, 2026-12-03 12:00 to 12:01, UTC)" in text
    assert "1 cells recorded without times are left out" in text


def test_no_dated_cell_means_no_section() -> None:
    assert markdown(run_time([])) == []
