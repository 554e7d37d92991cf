"""Advantage estimators: what a neighbourhood's records say about each skill (issue 24).

The paper's rule (``paper``, the default, DESIGN §5): a record's value is its return
``G_t`` so far (any record with at least one reward is eligible; ``finalised_only`` keeps
only ended trajectories), and ``A(skill) = mean value of the skill's records - mean value of
the neighbourhood``; a skill the neighbourhood has not seen gets 0. In-flight returns are
truncated, so a young record and an old one are not comparable (the age bias of
docs/adaptation.md).

``horizon:H`` compares like with like: a record's value is the H-step return
``G^H_t = sum_{u=t}^{t+H-1} gamma^(u-t) r_u``, and a record is eligible once H rewards at or
after its round are known, or its trajectory ended (then with the rewards it has, if any).

``centre`` (with a horizon: ``horizon:3,centre``) is against time confounding under team
rewards: a record's value is its H-step return minus the mean H-step return of every
eligible record of the role at the same round (this memory's whole group, all bodies and
episodes), so "late in the episode, when the team was already close" no longer looks like
a good skill.

``shrink:K`` pulls a skill's advantage towards 0 by its evidence, ``A * n / (n + K)`` (n
its eligible records in the neighbourhood): a skill seen twice no longer outvotes one seen
twenty times. ``scale`` expresses advantages in units of the neighbourhood's spread (its
values' standard deviation, at least ``SCALE_FLOOR``), so the push ``beta * A`` does not
depend on a task's reward scale: raw H-step returns differ by hundredths in one task and
by tens in another, against base gaps of a few nats in both. ``tscore`` (instead of
``scale``) counts in standard errors of the skill's mean, ``A * sqrt(n) / sd``: the push
grows with the evidence behind it, so a difference seen in twenty records outweighs the
same difference seen in one.

``support:M`` (a remedy of this project, combinable: ``horizon:3,support:4``) is against
thin evidence: a skill with fewer than M eligible records in the neighbourhood gets no
promotion -- its A is the lowest advantage of the supported skills (0 if none is
supported). Under the paper's rule an unseen skill gets the neighbourhood mean, which beats
a base winner with a below-average record: the way ``hold_position`` locked in.

The bookkeeping a horizon needs lives in ``HorizonBook`` (one per retrieval group of
``agent.memory``): each trajectory's known rewards and, per record, how many rewards
followed it and its H-step return, updated as rewards arrive, so retrieval stays one pass.

A daemon runs the estimator its config names (``[agent] estimator``); ``AEROWEAVER_ESTIMATOR``
overrides the file and ``--estimator`` both (``agent.choices``, docs/configuration.md).
"""

from __future__ import annotations

import math
import os
from array import array
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Final

from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.contracts.selector_specs import EstimatorSpec

ENV_ESTIMATOR: Final = "AEROWEAVER_ESTIMATOR"
Traj = tuple[str, str, int]  # (run, uav, episode)
RunKey = tuple[str, str, int, int]  # (run, uav, episode, round)

SCALE_FLOOR: Final = 1e-3  # ``scale``: a neighbourhood whose values spread less is "no evidence"


@dataclass(frozen=True)
class Estimator(EstimatorSpec):
    """Which value a record has and how a neighbourhood's values become advantages."""

    @property
    def is_paper(self) -> bool:
        return self == PAPER

    def book(self, gamma: float) -> HorizonBook | None:
        """The per-group bookkeeping this estimator needs (``None``: the stored return)."""
        if self.horizon is None:
            return None
        return HorizonBook(self.horizon, gamma, centre=self.centre)

    def advantages(
        self,
        values: Sequence[float],
        skills: Sequence[int],
        wanted: Mapping[str, int],
    ) -> dict[str, float]:
        """A per wanted name (name -> skill id, -1 unknown) from the neighbourhood's values
        and skill ids (same order). The paper's arithmetic is kept bit for bit."""
        baseline = math.fsum(values) / len(values)
        by_skill: dict[int, list[float]] = {}
        for sid, r in zip(skills, values, strict=True):
            by_skill.setdefault(sid, []).append(r)
        out: dict[str, float] = {}
        if self.support <= 1 and not self.shrink and not self.scale and not self.tscore:
            for name, sid in wanted.items():
                mine = by_skill.get(sid)
                out[name] = 0.0 if not mine else math.fsum(mine) / len(mine) - baseline
            return out
        unit = 1.0
        if self.scale or self.tscore:
            sd = math.sqrt(math.fsum((v - baseline) ** 2 for v in values) / len(values))
            unit = max(sd, SCALE_FLOOR)

        def adv(v: list[float]) -> float:
            a = (math.fsum(v) / len(v) - baseline) * len(v) / (len(v) + self.shrink) / unit
            return a * math.sqrt(len(v)) if self.tscore else a

        supported = {sid: adv(v) for sid, v in by_skill.items() if len(v) >= self.support}
        floor = min(supported.values(), default=0.0) if self.support > 1 else 0.0
        for name, sid in wanted.items():
            out[name] = supported.get(sid, floor)
        return out


PAPER: Final = Estimator()


def estimator_from_env() -> Estimator:
    """The estimator ``AEROWEAVER_ESTIMATOR`` alone names (unset or empty: the paper's rule;
    a daemon resolves it against its config with ``agent.choices``); a bad value is the
    user's to fix (``UserError``: one line, exit 2, before any flight)."""
    try:
        return Estimator.parse(os.environ.get(ENV_ESTIMATOR, "") or "paper")
    except ValueError as exc:
        raise UserError(
            f"{ENV_ESTIMATOR}: {exc}", f"unset it or set e.g. {ENV_ESTIMATOR}=paper"
        ) from None


class HorizonBook:
    """H-step returns of one retrieval group, kept current as records and rewards arrive.

    Position i is the group's i-th record. ``added`` must be called for every record in
    the group's order; ``reward`` for every reward of a trajectory with records here (a
    changed value replaces the old one, as ``add_reward`` does)."""

    __slots__ = ("centre", "count", "gamma", "h", "hret", "members", "rewards", "rounds")

    def __init__(self, h: int, gamma: float, *, centre: bool = False) -> None:
        self.h = h
        self.gamma = gamma
        self.centre = centre
        self.rewards: dict[Traj, dict[int, float]] = {}
        self.members: dict[Traj, list[int]] = {}
        self.rounds = array("i")
        self.count = array("i")  # rewards known at or after the record's round
        self.hret = array("d")  # G^H over the rewards known so far

    def _hret(self, rewards: Mapping[int, float], t: int) -> float:
        g, end = self.gamma, t + self.h
        return math.fsum(g ** (u - t) * r for u, r in sorted(rewards.items()) if t <= u < end)

    def added(self, i: int, key: RunKey, rewards: Iterable[tuple[int, float]] = ()) -> None:
        """Record i (key) joined the group, with rewards of its trajectory known now."""
        assert i == len(self.rounds), "records must be added in the group's order"
        run, uav, episode, t = key
        traj = (run, uav, episode)
        rw = self.rewards.setdefault(traj, {})
        for u, r in rewards:
            self.reward((run, uav, episode, u), r)
        self.members.setdefault(traj, []).append(i)
        self.rounds.append(t)
        self.count.append(sum(1 for u in rw if u >= t))
        self.hret.append(self._hret(rw, t))

    def reward(self, key: RunKey, value: float) -> None:
        """The reward of round ``key[3]`` of a trajectory is ``value`` (new or replaced)."""
        run, uav, episode, u = key
        traj = (run, uav, episode)
        rw = self.rewards.setdefault(traj, {})
        old = rw.get(u)
        if old == value:
            return
        rw[u] = value
        for i in self.members.get(traj, ()):
            t = self.rounds[i]
            if t > u:
                continue
            if old is None:
                self.count[i] += 1
            if u < t + self.h:
                self.hret[i] = self._hret(rw, t)

    def eligible(self, i: int, final: bool) -> bool:
        c = self.count[i]
        return c >= self.h or (final and c > 0)

    def value(self, i: int) -> float:
        return self.hret[i]

    def values(self, positions: Sequence[int], final: array[int]) -> list[float]:
        """The values of ``positions`` (eligible ones): H-step returns, centred per round
        over the group's eligible records when ``centre``."""
        if not self.centre:
            return [self.hret[i] for i in positions]
        import numpy as np

        count = np.frombuffer(self.count, dtype=np.int32)
        ok = (count >= self.h) | ((np.frombuffer(final, dtype=np.int8) != 0) & (count > 0))
        rounds = np.frombuffer(self.rounds, dtype=np.int32)[ok]
        sums = np.bincount(rounds, weights=np.frombuffer(self.hret, dtype=np.float64)[ok])
        ns = np.bincount(rounds)
        return [self.hret[i] - float(sums[self.rounds[i]] / ns[self.rounds[i]]) for i in positions]


__all__ = [
    "ENV_ESTIMATOR",
    "PAPER",
    "Estimator",
    "HorizonBook",
    "estimator_from_env",
]
