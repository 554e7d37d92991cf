"""The honest parts of a run summary, computed from the Commander's progress board: holds
by cause, deadline misses on both sides, LLM requests, the logprob class the daemons
actually ended up with (which may differ from the start-up probe), and what protected the
run and what each side refused (``security``).
"""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING, Any

from aeroweaver_edge.contracts.hold_reasons import count_causes
from commander.progress import ProgressBoard

if TYPE_CHECKING:
    from aeroweaver_edge.mesh.session import Mesh
    from aeroweaver_edge.sim.runner import WorldRunner


def holds_by_cause(board: ProgressBoard) -> dict[str, int]:
    total = count_causes(())
    for p in board.uavs.values():
        for cause, n in p.holds_by_cause.items():
            total[cause] += n
    return total


def deadline_misses(board: ProgressBoard, world_misses: int) -> dict[str, int]:
    """``daemon``: rounds a daemon cut off at its own deadline (it held in time);
    ``world``: commands that never reached the world in time."""
    daemon = sum(p.deadline_misses for p in board.uavs.values())
    return {"daemon": daemon, "world": world_misses, "total": daemon + world_misses}


def llm_calls(board: ProgressBoard) -> int:
    return sum(p.llm_calls for p in board.uavs.values())


def llm_classes(board: ProgressBoard) -> dict[str, int]:
    """How many UAVs ended the run with each logprob class (from their last reports)."""
    return dict(sorted(Counter(p.llm_class for p in board.uavs.values() if p.llm_class).items()))


def probe_after_run(start_line: str | None, start_kind: str | None, board: ProgressBoard) -> str:
    """The start-up probe line, plus what the daemons settled on when that differs (an
    endpoint that was down at start-up, or a class decided from live answers)."""
    if start_line is None:
        return ""
    classes = llm_classes(board)
    if not classes or set(classes) == {start_kind}:
        return start_line
    now = ", ".join(f"{kind} ({n} UAV{'s' if n != 1 else ''})" for kind, n in classes.items())
    on = "ON" if set(classes) == {"ok"} else "OFF" if "ok" not in classes else "mixed"
    return f"{start_line} -> re-classified from live answers: {now}; correction {on}"


def health_fields(
    board: ProgressBoard, world_misses: int, probe_line: str | None, probe_kind: str | None
) -> dict[str, Any]:
    """Fields a ``RunSummary`` takes over as they are."""
    return {
        "holds_by_cause": holds_by_cause(board),
        "deadline_misses_by_side": deadline_misses(board, world_misses),
        "llm_calls": llm_calls(board),
        "llm_classes": llm_classes(board),
        "probe": probe_after_run(probe_line, probe_kind, board) or probe_line,
    }


def security_fields(
    world_mesh: Mesh, cmdr_mesh: Mesh, runner: WorldRunner, board: ProgressBoard
) -> dict[str, Any]:
    """The summary's ``security`` object: what protected the run (TLS with mutual
    authentication, the ACL, signatures; from the world's session, every session of a run
    is configured alike) and everything refused, by cause and side. Refusals by the Zenoh
    ACL happen inside Zenoh and are not countable here (docs/security.md)."""
    base = world_mesh.security_summary()
    daemons: Counter[str] = Counter()
    for p in board.uavs.values():
        daemons.update(p.rejected)
    commander: Counter[str] = Counter(cmdr_mesh.codec.stats.rejected)
    if board.foreign:
        commander["foreign_report"] += board.foreign
    world = runner.refusals()
    total = world + commander + daemons
    return {
        **{k: base[k] for k in ("tls", "mtls", "acl", "signed")},
        **({"identities_version": base["identities_version"]} if base.get("tls") else {}),
        "rejected": dict(total.most_common()),
        "rejected_total": sum(total.values()),
        "rejected_by_side": {
            "world": dict(world.most_common()),
            "commander": dict(commander.most_common()),
            "daemons": dict(daemons.most_common()),
        },
        "refused_commands": dict(runner.check.refused.most_common()),
        "clamped_commands": dict(runner.check.clamped.most_common()),
        "missing_messages": runner.missing_messages
        + sum(p.missing_messages for p in board.uavs.values()),
    }


def mission_security(
    cmdr_mesh: Mesh,
    world_mesh: Mesh,
    board: ProgressBoard,
    runner: WorldRunner | None,
    before: dict[str, dict[str, int]] | None = None,
) -> dict[str, Any]:
    """``mission start``'s ``security`` object, shaped like a ``sim`` summary's: with a world
    run here, ``security_fields``; without one (field), what protected the Commander's
    session and what the Commander and the daemons refused. A service daemon's counters
    run from its start: ``before`` (uav -> its counts when it took this mission, from its
    ready report) is taken off, so the record holds this mission's refusals only."""
    sec = (
        security_fields(world_mesh, cmdr_mesh, runner, board)
        if runner is not None
        else _field_security(cmdr_mesh, board)
    )
    if before:
        earlier: Counter[str] = Counter()
        for counts in before.values():
            earlier.update(counts)
        daemons = Counter(sec["rejected_by_side"]["daemons"]) - earlier
        total = Counter(sec["rejected"]) - earlier
        sec["rejected_by_side"]["daemons"] = dict(daemons.most_common())
        sec["rejected"] = dict(total.most_common())
        sec["rejected_total"] = sum(total.values())
    return sec


def _field_security(cmdr_mesh: Mesh, board: ProgressBoard) -> dict[str, Any]:
    base = cmdr_mesh.security_summary()
    daemons: Counter[str] = Counter()
    for p in board.uavs.values():
        daemons.update(p.rejected)
    # Not ``board.foreign``: in the field an idle daemon reports every round with no
    # mission, so reports for no (or another) mission are normal traffic here.
    commander: Counter[str] = Counter(cmdr_mesh.codec.stats.rejected)
    total = commander + daemons
    return {
        **{k: base[k] for k in ("tls", "mtls", "acl", "signed")},
        **({"identities_version": base["identities_version"]} if base.get("tls") else {}),
        "rejected": dict(total.most_common()),
        "rejected_total": sum(total.values()),
        "rejected_by_side": {
            "world": {},
            "commander": dict(commander.most_common()),
            "daemons": dict(daemons.most_common()),
        },
        "refused_commands": {},
        "clamped_commands": {},
        "missing_messages": sum(p.missing_messages for p in board.uavs.values()),
    }
