"""The state description ``s`` that experience memory stores and retrieves by (paper §3.3:
"the state summarizes local observations, received peer messages, execution progress, and
relevant mission context").

Lines, in order: the round (execution progress), the observation (``describe_state``), then with
``context=True`` the mission context (role, local goal, this UAV's private facts) and one
line per received peer message. Messages are summarised for matching, not quoted: a
position in a body becomes distance and compass point from this UAV (5 m steps, like
entities), other numbers are rounded, strings are cut to identifiers, lines are sorted. So
two alike situations share tokens even when the senders' coordinates differ by a metre.

The text is bounded (it travels in experience records) and built only from sanitised pieces,
so a hostile body can at worst add a few meaningless tokens to its recipient's state.
"""

from __future__ import annotations

import math
import re

from aeroweaver_edge.agent.describe import HUGE, describe_state, pop_place
from aeroweaver_edge.contracts.observation import MissionView, Observation
from aeroweaver_edge.contracts.wire import InboxMessage

MAX_MESSAGES = 8  # newest messages summarised
MAX_FIELDS = 6  # body fields per message
MAX_FACTS = 8
MAX_WORD = 24
MAX_GOAL = 200
_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]+")


def _word(value: object) -> str:
    return _UNSAFE.sub("_", str(value))[:MAX_WORD].strip("_") or "_"


def _scalar(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        x = float(value)
        if not math.isfinite(x):
            return "nan"
        return str(round(x)) if abs(x) < HUGE else ("huge" if x > 0 else "-huge")
    return _word(value)


def message_summary(msg: InboxMessage, own: tuple[float, float]) -> str:
    """One received message as retrieval text: ``msg <from> <kind>: k v ... at D m B``."""
    body = dict(msg.body)
    seen = pop_place(body, own)  # where a body's position lies, seen from this UAV
    where = f" at {seen}" if seen is not None else ""
    fields = [f"{_word(k)} {_scalar(v)}" for k, v in sorted(body.items())[:MAX_FIELDS]]
    text = " ".join([f"msg {_word(msg.h.sender)} {_word(msg.kind)}:", *fields])
    return text + where


def state_text(obs: Observation, view: MissionView | None, *, context: bool) -> str:
    """The retrieval state of this round; ``context=False`` gives pose and entities only."""
    lines = [f"round {obs.round}", describe_state(obs)]
    if not context:
        return "\n".join(lines)
    if view is not None:
        goal = " ".join(view.local_goal.split())[:MAX_GOAL]
        lines.append(f"role {_word(view.role)}; goal {goal}".rstrip())
    for key, value in sorted(obs.memo.items())[:MAX_FACTS]:
        lines.append(f"fact {_word(key)} {_word(value)}")
    own = (obs.own.pos[0], obs.own.pos[1])
    newest = sorted(obs.messages, key=lambda m: (-m.round, m.h.sender, m.h.seq))[:MAX_MESSAGES]
    lines += sorted(message_summary(m, own) for m in newest)
    return "\n".join(lines)
