"""Returns bookkeeping of experience memory: G_t from delivered rewards (agent.memory).

``G_t = sum over delivered rewards r_u with u >= t of gamma^(u-t) * r_u`` per trajectory
(run, uav, episode); ``None`` until a reward at or after round t arrives. The same
arithmetic serves a record appended after its rewards (``return_at``), a reward arriving
after its records (``credited``), a peer's in-flight record crediting the peer's earlier
ones (``peer_credit``) and a changed gamma (``recompute_returns``), in the order and with
the float operations the memory has always used, so every stored return recomputes bit for
bit. Which value a neighbourhood then averages (returns or H-step returns) is the
estimator's business (``agent.estimators``).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable, Sequence


def return_at(gamma: float, rewards: Iterable[tuple[int, float]], rnd: int) -> float | None:
    """G_rnd over ``rewards`` ((round, reward) of one trajectory), ``None`` if none counts."""
    total: float | None = None
    for u, r in sorted(rewards):
        if u >= rnd:
            total = (total or 0.0) + gamma ** (u - rnd) * r
    return total


def credited(gamma: float, ret: float | None, t: int, rnd: int, delta: float) -> float:
    """G_t after the reward of round ``rnd`` >= t changed by ``delta``."""
    return (ret or 0.0) + gamma ** (rnd - t) * delta


def install_functions(db: sqlite3.Connection) -> None:
    """``aw_credited(gamma, ret, t, round, delta)`` = ``credited`` inside SQL, so a reward
    credits its trajectory in one UPDATE with exactly this module's float arithmetic."""
    db.create_function("aw_credited", 5, credited, deterministic=True)


def peer_credit(
    gamma: float, ret: float | None, s: int, rewards: Sequence[tuple[int, float]]
) -> float | None:
    """A peer's stored G_s after crediting ``rewards`` (round order) of rounds after s."""
    for u, r in rewards:
        if s < u:
            ret = (ret or 0.0) + gamma ** (u - s) * r
    return ret


def recompute_returns(db: sqlite3.Connection, gamma: float) -> None:
    """Every own record's return from the stored rewards (inside the caller's transaction),
    after gamma changed."""
    rewards: dict[tuple[str, str, int], list[tuple[int, float]]] = {}
    for run, uav, episode, rnd, reward in db.execute(
        "SELECT run, uav, episode, round, reward FROM rewards"
    ):
        rewards.setdefault((run, uav, episode), []).append((rnd, reward))
    rows = db.execute(
        "SELECT seq, run, uav, episode, round FROM records WHERE origin = ''"
    ).fetchall()
    db.executemany(
        "UPDATE records SET ret = ? WHERE seq = ?",
        [(return_at(gamma, rewards.get((n, u, e), []), r), s) for s, n, u, e, r in rows],
    )


__all__ = ["credited", "install_functions", "peer_credit", "recompute_returns", "return_at"]
