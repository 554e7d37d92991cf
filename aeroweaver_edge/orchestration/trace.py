"""Per-round traces of a simulated run: every number in a summary, explainable.

A trace is JSON Lines, one object per line, written atomically when the run ends (the
daemons' last reports have arrived by then). ``docs/traces.md`` is the schema:

* ``{"type": "run", ...}``: task, seed, selector, model, roles, mission plan, geofence;
* ``{"type": "round", "episode": e, "round": r, ...}`` per round: every body's position,
  velocity and role after the round (ours and the world's opponents), the static entities,
  each UAV's applied command (velocity, held, guess), the messages it sent, its reward, the
  task's completion flag and metrics, and each UAV's decision as it reported it (options,
  base scores, advantages, choice and reason, hold cause, tokens, latency);
* ``{"type": "episode_end", ...}`` per episode: rounds, reason, returns.

The recorder only listens (the world's round hook, the Commander's report listener) and
buffers in memory: a 50-UAV, 24-round episode is a few MB of text at most.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import msgspec

from aeroweaver_edge.contracts.wire import Entity, ProgressReport, Vec3
from aeroweaver_edge.runtime.json_out import write_jsonl_file
from aeroweaver_edge.sim.episode import EpisodeResult
from aeroweaver_edge.sim.runner import RoundLog

TRACE_VERSION = 1


def _xy(v: Vec3) -> list[float]:
    return [round(v[0], 2), round(v[1], 2)]


def entity_dict(e: Entity) -> dict[str, Any]:
    out: dict[str, Any] = {"id": e.id, "kind": e.kind, "pos": _xy(e.pos)}
    if e.role:
        out["role"] = e.role
    if any(e.vel):
        out["vel"] = _xy(e.vel)
    return out


def _finite(x: float) -> float | None:
    return round(x, 6) if math.isfinite(x) else None


def decision_dict(rep: ProgressReport) -> dict[str, Any]:
    out: dict[str, Any] = {
        "skill": rep.skill,
        "invocation": rep.invocation,
        "label": rep.label,
        "held": rep.held,
        "hold_cause": rep.hold_cause,
        "hold_reason": rep.hold_reason,
        "tokens": {
            "prompt": rep.prompt_tokens,
            "prompt_cached": rep.prompt_cached,
            "completion": rep.completion_tokens,
        },
        "llm_calls": rep.llm_calls,
        "latency_s": round(rep.latency_s, 4),
    }
    if rep.decision is not None:
        out.update(msgspec.to_builtins(rep.decision))
    return out


class TraceRecorder:
    """Collects one run's rounds and decisions; ``write`` puts them in a JSONL file."""

    def __init__(self, path: Path, header: Mapping[str, Any]) -> None:
        self.path = path
        self._header = {"type": "run", "version": TRACE_VERSION, **header}
        self._rounds: list[dict[str, Any]] = []
        self._episodes: list[dict[str, Any]] = []
        self._decisions: dict[tuple[int, int, str], dict[str, Any]] = {}
        self._central: dict[tuple[int, int], dict[str, Any]] = {}

    def on_round(self, log: RoundLog) -> None:
        cmds = {
            u: {"vel": _xy(c.vel), "held": c.held, "guess": c.guess, "sent": len(c.sent)}
            for u, c in sorted(log.commands.items())
        }
        res = log.result
        self._rounds.append(
            {
                "type": "round",
                "episode": log.episode,
                "round": log.round,
                "bodies": [entity_dict(b) for b in log.bodies],
                "entities": [entity_dict(e) for e in log.entities],
                "commands": cmds,
                "messages": [
                    {"from": u, "to": ref.to, "seq": ref.seq}
                    for u, c in sorted(log.commands.items())
                    for ref in c.sent
                ],
                "missed": list(log.missed),
                "absent": list(log.absent),
                "rewards": {u: _finite(r) for u, r in sorted(res.rewards.items())},
                "complete": res.complete,
                "stable_rounds": res.stable_rounds,
                "metrics": {k: _finite(v) for k, v in res.metrics.items()},
                "done": res.done,
                "reason": res.reason,
            }
        )

    def on_report(self, rep: ProgressReport) -> None:
        if rep.phase == "round":
            self._decisions[(rep.episode, rep.round, rep.uav)] = decision_dict(rep)

    def on_central(self, record: Any) -> None:
        """A baseline's central node finished a round (``baselines.central.CentralRound``):
        its calls, tokens, proposals, reviews and final letters join that round's line."""
        self._central[(record.episode, record.round)] = record.as_dict()

    def on_episode(self, episode: int, result: EpisodeResult) -> None:
        self._episodes.append(
            {
                "type": "episode_end",
                "episode": episode,
                "rounds": result.rounds,
                "reason": result.reason,
                "team_return": _finite(result.team_mean_return),
                "returns": {u: _finite(r) for u, r in sorted(result.returns.items())},
            }
        )

    def lines(self) -> list[dict[str, Any]]:
        """The trace, in order: run header, then per episode its rounds and its end."""
        out: list[dict[str, Any]] = [self._header]
        ends = {e["episode"]: e for e in self._episodes}
        by_round: dict[tuple[int, int], dict[str, dict[str, Any]]] = {}
        for (e, r, u), d in sorted(self._decisions.items()):
            by_round.setdefault((e, r), {})[u] = d
        episode: int | None = None
        for row in self._rounds:
            if episode is not None and row["episode"] != episode and episode in ends:
                out.append(ends.pop(episode))
            episode = row["episode"]
            where = (row["episode"], row["round"])
            line = {**row, "decisions": by_round.get(where, {})}
            if where in self._central:
                line["central"] = self._central[where]
            out.append(line)
        out.extend(ends[e] for e in sorted(ends))
        return out

    def write(self) -> Path:
        write_jsonl_file(self.path, self.lines())
        return self.path


__all__ = ["TRACE_VERSION", "TraceRecorder", "decision_dict", "entity_dict"]
