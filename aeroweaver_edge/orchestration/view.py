"""The live per-round view of a simulated run and its final summary, for a terminal."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from aeroweaver_edge.contracts.hold_reasons import format_counts
from aeroweaver_edge.contracts.wire import ProgressReport
from aeroweaver_edge.orchestration.planning import natural
from aeroweaver_edge.sim.runner import RoundLog
from commander.progress import ProgressBoard

LEGEND = (
    "each round: UAV [role] what it did (HOLD[cause]: it held; 'no report': none came this "
    "round; absent: its daemon is gone), r = its reward this round, tok = its LLM tokens this "
    "round; 'goal held N' = consecutive rounds the task's goal has held (the episode completes "
    "at the task's count); the last figure is the round's wall time"
)


class LiveView:
    """Prints one compact block per round; works on a TTY and in a log file alike. When
    anything was refused since the last round (a forged, malformed or foreign payload or
    command, by the world or a daemon), one more line says what, where and why. A legend
    line comes first."""

    def __init__(self, console: Console | None = None) -> None:
        self.console = console or Console(stderr=False, highlight=False)
        self._refused_seen: dict[str, dict[str, int]] = {}  # uav -> cumulative counts seen
        self._tokens_seen: dict[str, int] = {}  # uav -> cumulative decision tokens seen
        self._legend = False

    async def on_round(self, log: RoundLog, board: ProgressBoard) -> None:
        if not self._legend:
            self._legend = True
            self.console.print(LEGEND, soft_wrap=True, markup=False)
        res = log.result
        parts = []
        for uav in sorted(res.rewards, key=natural):
            rep = board.uavs.get(uav)
            last = rep.last if rep else None
            what = "absent" if uav in log.absent else ("missed" if uav in log.missed else "")
            if uav not in log.commands and not what and rep is None:
                what = "(world)"  # an opponent the world flies
            if (
                not what
                and last is not None
                and (last.episode, last.round) == (log.episode, log.round)
            ):
                held = f"HOLD[{last.hold_cause or 'hold'}] " if last.held else ""
                what = held + last.invocation
            total = rep.prompt_tokens + rep.completion_tokens if rep else 0
            tokens = total - self._tokens_seen.get(uav, 0)
            self._tokens_seen[uav] = total
            role = f"[{rep.role}] " if rep and rep.role else ""
            tok = f" tok {tokens}" if tokens else ""
            parts.append(f"{uav} {role}{what or 'no report'} r={res.rewards[uav]:+.2f}{tok}")
        status = f" [{res.reason}]" if res.done else ""
        self.console.print(
            f"ep {log.episode} round {log.round + 1:2d} | "
            + " | ".join(parts)
            + f" | goal held {res.stable_rounds}{status} ({log.wait_s:.2f} s)",
            soft_wrap=True,
            markup=False,
        )
        refused = self._new_refusals(log, board)
        if refused:
            self.console.print(f"  refused: {refused}", soft_wrap=True, markup=False)

    def _new_refusals(self, log: RoundLog, board: ProgressBoard) -> str:
        """``world non_finite x1; uav1 bad_signature x3`` for what is new since last round."""
        parts = []
        if log.refused:
            parts.append(f"world {_counts(log.refused)}")
        for uav in sorted(board.uavs, key=natural):
            now = board.uavs[uav].rejected
            before = self._refused_seen.get(uav, {})
            new = {k: n - before.get(k, 0) for k, n in now.items() if n > before.get(k, 0)}
            self._refused_seen[uav] = dict(now)
            if new:
                parts.append(f"{uav} {_counts(new)}")
        return "; ".join(parts)


class FieldView:
    """``mission start`` without a simulated world: a line per round of the swarm -- once
    every UAV in the mission reported a new round, or one reported twice (the others'
    places then say ``no report``) -- and a line per phase (ready, final). In the field
    each daemon counts rounds on its own clock, so each UAV's entry carries its round."""

    def __init__(self, participants: list[str], console: Console | None = None) -> None:
        self.console = console or Console(stderr=False, highlight=False)
        self.participants = sorted(participants, key=natural)
        self._pending: dict[str, ProgressReport] = {}
        self.lines = 0

    def on_report(self, rep: ProgressReport) -> None:
        if rep.uav not in self.participants:
            return
        if rep.phase == "ready":
            wait = f"; {rep.hold_reason}" if rep.hold_reason else ""
            self._say(f"{rep.uav} ready as {rep.role or '-'}{wait}")
            return
        if rep.phase == "final":
            self._say(f"{rep.uav} stopped (its last report)")
            return
        if rep.phase != "round":
            return
        if rep.uav in self._pending:
            self._flush()
        self._pending[rep.uav] = rep
        if len(self._pending) == len(self.participants):
            self._flush()

    def _flush(self) -> None:
        parts = []
        for uav in self.participants:
            r = self._pending.get(uav)
            if r is None:
                parts.append(f"{uav} no report")
                continue
            held = f"HOLD[{r.hold_cause or 'hold'}] " if r.held else ""
            tok = r.prompt_tokens + r.completion_tokens
            line = f"{uav} r{r.round + 1} {held}{r.invocation or '-'}"
            parts.append(line + (f" tok {tok}" if tok else ""))
        self._pending.clear()
        self.lines += 1
        self._say(f"round {self.lines:3d} | " + " | ".join(parts))

    def _say(self, line: str) -> None:
        self.console.print(line, soft_wrap=True, markup=False)


def _counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{k} x{n}" for k, n in sorted(counts.items(), key=lambda kv: -kv[1]))


def print_mission(mission: dict[str, Any], console: Console) -> None:
    t = Table(title=f"mission {mission['mission_id']}: {mission['task']}")
    for col in ("uav", "role", "local goal", "active skills"):
        t.add_column(col)
    for uav, a in mission["assignments"].items():
        t.add_row(uav, a["role"], a["local_goal"], ", ".join(a["skills"]))
    console.print(t)
    console.print(
        f"parsed by {mission['parse_source']}, roles by {mission['roles_source']}; "
        f"setup tokens {mission['setup_tokens']} (counted once, apart from decision tokens)"
    )
    for note in mission.get("notes") or []:
        console.print(f"  · {escape(note)}")


def _num(value: object) -> str:
    return f"{value:.3f}" if isinstance(value, int | float) else "n/a"


def print_summary(summary: dict[str, Any], console: Console | None = None) -> None:
    console = console or Console()
    if summary.get("mission"):
        print_mission(summary["mission"], console)
    s = summary
    t = Table(title=f"{s['task']} · seed {s['seed']} · {s['mode']} · {s['selector']}")
    t.add_column("episode")
    t.add_column("rounds")
    t.add_column("end")
    t.add_column("team return")
    for uav in summary["agent_returns"]:
        t.add_column(uav)
    for ep in summary["episodes"]:
        t.add_row(
            str(ep["episode"]),
            str(ep["rounds"]),
            ep["reason"],
            _num(ep["team_return"]),
            *(_num(ep["agent_returns"].get(u)) for u in summary["agent_returns"]),
        )
    console.print(t)
    tok = summary.get("tokens") or {}
    console.print(
        f"team mean return {_num(s['team_return'])} over {len(s['episodes'])} episode(s); "
        f"rounds {s['rounds']}; messages sent {s['messages_sent']}, "
        f"dropped {s['messages_dropped']}; decode errors {s['decode_errors']}; "
        f"holds {s['holds']}; deadline misses {s['deadline_misses']}; wall {s['wall_s']:.2f} s"
    )
    if s.get("scripted_returns"):
        theirs = ", ".join(f"{b} {r:.3f}" for b, r in s["scripted_returns"].items())
        console.print(f"flown by the world (not in the team mean): {theirs}")
    if s.get("holds"):
        console.print(f"holds by cause: {format_counts(s.get('holds_by_cause') or {})}")
    env = s.get("envelope_violations") or {}
    if env.get("total"):  # the world saw a command outside the envelope: a gate failed
        console.print(
            f"[bold red]envelope violations {env['total']}[/]: "
            f"{format_counts(env.get('by_kind') or {})} (of {env.get('checked', 0)} commands)"
        )
    sides = s.get("deadline_misses_by_side") or {}
    if s.get("deadline_misses") and sides:
        console.print(
            f"deadline misses: {sides.get('daemon', 0)} in the daemons (held in time), "
            f"{sides.get('world', 0)} at the world (no command in time)"
        )
    lat = s.get("decision_latency_s") or {}
    if lat:
        console.print(
            f"decision latency p50 {lat['p50']:.3f} s, p95 {lat['p95']:.3f} s, "
            f"max {lat['max']:.3f} s"
        )
    if s.get("model"):
        console.print(
            f"model {s['model']}; probe: {escape(str(s['probe']))}; LLM calls {s['llm_calls']}; "
            f"tokens {tok.get('total', 0)} (prompt {tok.get('prompt', 0)} of which cached "
            f"{tok.get('prompt_cached', 0)}, completion {tok.get('completion', 0)})"
        )
        per = s.get("tokens_per_decision") or {}
        if per:
            console.print(
                f"per decision: prompt {per['prompt']:.0f} tokens, uncached "
                f"{per['prompt_uncached']:.0f}, cached {per['prompt_cached']:.0f}"
            )
    if summary.get("lost_uavs"):
        lost = ", ".join(
            f"{u} (episode {w[0]}, round {w[1] + 1})" for u, w in summary["lost_uavs"].items()
        )
        console.print(f"[bold red]lost daemons[/]: {lost}; the world held them from then on")
    sec = summary.get("security") or {}
    if sec:
        on = [k for k in ("tls", "acl", "signed") if sec.get(k)]
        what = "secured: " + ", ".join(on) if on else "INSECURE (no TLS, ACL or signatures)"
        line = f"{what}; refused {sec.get('rejected_total', 0)}"
        if sec.get("rejected"):
            line += f" ({escape(_counts(sec['rejected']))})"
        if sec.get("missing_messages"):
            line += f"; expected messages that never came {sec['missing_messages']}"
        console.print(line)
    if summary.get("note"):
        console.print(f"[yellow]note[/]: {escape(summary['note'])}")
