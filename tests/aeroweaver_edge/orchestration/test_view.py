"""What the operator's terminal shows: the field view's line per round of the swarm (each
UAV with its own round), phases, and the live view's legend and per-round tokens."""

from __future__ import annotations

import io

from rich.console import Console

from aeroweaver_edge.contracts.wire import HeaderFactory, ProgressReport
from aeroweaver_edge.orchestration.view import FieldView


def report(uav: str, rnd: int, **kw: object) -> ProgressReport:
    fields: dict[str, object] = {
        "uav": uav, "mission_id": "m", "episode": 0, "round": rnd, "role": "searcher",
        "skill": "cover_landmark", "invocation": "cover_landmark(L0)", "label": "A",
        "held": False, **kw,
    }  # fmt: skip
    return ProgressReport(h=HeaderFactory(uav).next(), **fields)  # type: ignore[arg-type]


def test_field_view_prints_a_line_per_round_of_the_swarm() -> None:
    buf = io.StringIO()
    view = FieldView(["uav1", "uav0"], Console(file=buf, width=300))
    view.on_report(report("uav0", -1, phase="ready", hold_reason="waiting for a world"))
    view.on_report(report("uav0", 4))
    view.on_report(report("uav1", 9, held=True, hold_cause="deadline", prompt_tokens=120))
    view.on_report(report("uav0", 5))
    view.on_report(report("uav0", 6))  # uav1 silent: the line goes out without it
    view.on_report(report("uav1", -1, phase="final"))
    assert buf.getvalue().splitlines() == [
        "uav0 ready as searcher; waiting for a world",
        "round   1 | uav0 r5 cover_landmark(L0) | uav1 r10 HOLD[deadline] cover_landmark(L0) "
        "tok 120",
        "round   2 | uav0 r6 cover_landmark(L0) | uav1 no report",
        "uav1 stopped (its last report)",
    ]
