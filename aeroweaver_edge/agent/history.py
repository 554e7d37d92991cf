"""The agent's own interaction history (paper §3.2: each local agent's context holds "an
isolated interaction history").

Every decision this UAV took in the current episode becomes one line of its context, e.g.
``r4 cover_landmark(L1) -1.2`` (round, action, reward). The line is new prompt text every
round, so it is as terse as the options: a one-parameter invocation names its value only
(``cover_landmark(target_id=L1)`` reads ``cover_landmark(L1)``, as the option did) and the
reward carries one decimal. Two rules keep the prompt cache-friendly:

* **Frozen lines.** A line is written the first time it is shown (the round after the
  decision, when lockstep has delivered its reward) and never changes afterwards, so from
  round to round the history only grows at its end and the server reuses every token before.
  A line whose action repeats the line before reads ``r5 same -1.1``: it depends only on
  lines already frozen, and the first line of a window always names its action.
* **Block window.** Showing the last ``block`` lines would shift the text every round (a
  cache miss every round). Instead the shown lines start at a multiple of ``2 * block``:
  between ``block`` and ``3 * block - 1`` of the most recent lines are visible, and the text
  changes other than by appending once every ``2 * block`` rounds (one miss then, which
  re-processes the ``block`` lines kept). With the default block of 8 that is round 24: a
  24-round episode's history is an append-only tail (with turnover every ``block`` rounds,
  as before 2026-12-03, round 16 cost each UAV ~60 tokens, ~2.5 per decision).

The history is per UAV and per episode (a new episode starts empty): nothing here is shared
with peers, which is what "isolated" means in the paper.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

MAX_INVOCATION = 80  # characters of an invocation shown in a line
SAME = "same"  # the action of the line before, repeated (cover_landmark(L0) round after round)
_ONE_PARAM = re.compile(r"([A-Za-z0-9_]+)\([A-Za-z0-9_]+=([A-Za-z0-9_.-]{1,64})\)")


@dataclass(frozen=True)
class _Decision:
    round: int
    invocation: str
    chosen: bool  # False: a fallback hold (error, timeout, no usable label)


def _reward_text(reward: float) -> str:
    value = round(reward, 1)
    if not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if value == int(value):
        return str(int(value))  # "-1", "0": never "-0" or a trailing ".0"
    return f"{value:.1f}"


def short_invocation(invocation: str) -> str:
    """``skill(key=value)`` with one plain value as ``skill(value)`` (``prompt.option_text``'s
    form); anything else unchanged."""
    match = _ONE_PARAM.fullmatch(invocation)
    return f"{match.group(1)}({match.group(2)})" if match else invocation


def history_line(
    round_: int,
    invocation: str,
    chosen: bool,
    reward: float | None,
    previous: str | None = None,
) -> str:
    """One frozen history line (compact: digits are one token each for small models);
    ``same`` when the shown line before it (``previous``, its invocation) did the same."""
    action = short_invocation(invocation)[:MAX_INVOCATION]
    if previous is not None and short_invocation(previous)[:MAX_INVOCATION] == action:
        action = SAME
    text = f"r{round_} {action}"
    if not chosen:
        text += " [no choice]"
    if reward is not None:
        text += f" {_reward_text(reward)}"
    return text


class InteractionHistory:
    """Recent decisions and rewards of one UAV, rendered append-only in blocks."""

    def __init__(self, block: int) -> None:
        if block < 1:
            raise ValueError("history block must be at least 1 round")
        self.block = block
        self._episode: int | None = None
        self._pending: list[_Decision] = []
        self._rewards: dict[int, float] = {}
        self._lines: list[tuple[_Decision, float | None]] = []  # frozen: decision, reward
        self._dropped = 0  # lines before _lines[0] that can never be shown again

    def _enter(self, episode: int) -> None:
        if episode != self._episode:
            self._episode = episode
            self._pending.clear()
            self._rewards.clear()
            self._lines.clear()
            self._dropped = 0

    def record_decision(self, episode: int, round_: int, invocation: str, chosen: bool) -> None:
        self._enter(episode)
        self._pending.append(_Decision(round_, invocation, chosen))

    def record_reward(self, episode: int, round_: int, reward: float) -> None:
        """A reward of this episode; one for another episode is ignored (it cannot be shown)."""
        if episode == self._episode:
            self._rewards[round_] = reward

    def lines(self, episode: int, round_: int) -> tuple[str, ...]:
        """The history to show in round ``round_``: decisions of earlier rounds only."""
        self._enter(episode)
        due = sorted((d for d in self._pending if d.round < round_), key=lambda d: d.round)
        if due:
            self._pending = [d for d in self._pending if d.round >= round_]
            self._lines += [(d, self._rewards.get(d.round)) for d in due]
        # A reward of an earlier round can no longer change a frozen line: forget it.
        self._rewards = {r: v for r, v in self._rewards.items() if r >= round_}
        total = self._dropped + len(self._lines)
        step = 2 * self.block  # the window starts at a multiple of step, >= block lines back
        start = (total - self.block) // step * step if total >= self.block else 0
        if start > self._dropped:  # the window moved on: forget what it left behind
            del self._lines[: start - self._dropped]
            self._dropped = start
        shown = []
        for i, (d, reward) in enumerate(self._lines):
            before = self._lines[i - 1][0].invocation if i else None
            shown.append(history_line(d.round, d.invocation, d.chosen, reward, before))
        return tuple(shown)
