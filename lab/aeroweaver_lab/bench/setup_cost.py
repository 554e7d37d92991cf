"""The setup tokens of one LLM Commander activation per task, for AeroWeaver's totals.

The benchmark flies the template plan (roles from the task's template, top-K activation by
retrieval: no tokens), so its decisions do not depend on how well a model parses a mission.
The paper's totals include one skill-activation setup per mission (parse + roles, ~2.5k
tokens with the LLM Commander). This module measures that cost once per task on the same
endpoint: the task's template mission text through ``plan_run`` with the LLM, as
``aeroweaver sim --mission TEXT`` plans it. The report adds it once per run to the
conditions that use the Commander's activation (``SETUP_CONDITIONS``) and shows it in a
column of its own. ``setup/<task>.json`` keeps the figure, the endpoint and the plan the
LLM made; a file of the same endpoint and model is reused on resume.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Final

from aeroweaver_edge.config import LLMConfig
from aeroweaver_edge.runtime.json_out import write_json_file

SETUP_CONDITIONS: Final = ("aeroweaver", "no_coordination", "beta0")
"""Conditions whose UAVs fly the Commander's per-role top-K activation (the baselines and
"w/o activation" get the whole catalogue without it; the scripted reference has no LLM)."""


def setup_path(out: Path, task: str) -> Path:
    return out / "setup" / f"{task}.json"


def load_setup(out: Path, task: str) -> dict[str, Any] | None:
    try:
        data = json.loads(setup_path(out, task).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


async def measure_one(task: str, llm: LLMConfig) -> dict[str, Any]:
    """One LLM Commander activation of ``task``'s template mission text on ``llm`` (a
    running endpoint). A failed call is recorded, not raised: the run goes on without it."""
    from aeroweaver_edge.orchestration.planning import plan_run
    from aeroweaver_edge.tasks import get_spec

    spec = get_spec(task)
    started = time.monotonic()
    entry: dict[str, Any] = {"task": task, "mission_text": spec.mission_text, "model": llm.model}
    try:
        plan = await plan_run(
            task=task, uavs=spec.team_size, mission_text=spec.mission_text, llm=llm
        )
    except Exception as exc:  # a parse the Commander refuses is a finding, not a crash
        entry.update(setup_tokens=None, error=f"{type(exc).__name__}: {exc}"[:300])
    else:
        # A parse call that failed at the endpoint (timeout, 5xx) reports no tokens and skips
        # the roles call: no measurement, retried on resume. An answer the parser rejected
        # still spent (and reported) its tokens: that is the cost of this model's setup.
        measured = plan.parse_source == "llm" or plan.setup_tokens > 0
        entry.update(
            setup_tokens=plan.setup_tokens if measured else None,
            error=None
            if measured
            else "the LLM Commander's parse call failed (no tokens reported): "
            + ("; ".join(plan.notes) or "no reason given")[:300],
            parse_source=plan.parse_source,
            roles_source=plan.roles_source,
            assignments={u: list(a.skills) for u, a in sorted(plan.assignments.items())},
        )
    entry["wall_s"] = round(time.monotonic() - started, 2)
    return entry


async def measure_setups(out: Path, tasks: Sequence[str], llm: LLMConfig, source: str) -> None:
    """``setup/<task>.json`` for every task that lacks one of this endpoint and model."""
    from aeroweaver_edge.orchestration.llm import shared_llm

    todo = [
        t
        for t in tasks
        if (old := load_setup(out, t)) is None
        or (old.get("llm"), old.get("model")) != (source, llm.model)
        or (old.get("setup_tokens") is None)
    ]
    if not todo:
        return
    async with shared_llm(llm, needed=True) as (live, _):
        for task in todo:
            entry = await measure_one(task, live)
            entry["llm"] = source
            entry["model"] = llm.model
            write_json_file(setup_path(out, task), entry)
            shown = entry["setup_tokens"] if entry["error"] is None else entry["error"]
            print(f"bench: setup of {task} (LLM Commander): {shown}", file=sys.stderr, flush=True)


__all__ = ["SETUP_CONDITIONS", "load_setup", "measure_one", "measure_setups", "setup_path"]
