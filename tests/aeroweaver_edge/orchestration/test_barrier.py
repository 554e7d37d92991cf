"""The barrier between episodes, fed real progress reports: it opens exactly when every
live sharer has shared and every other live daemon has received what was shared (whatever
its role), ignores dead and restarted daemons, and gives up (counted) at its bound."""

from __future__ import annotations

import asyncio

from aeroweaver_edge.contracts.wire import Header, ProgressReport
from aeroweaver_edge.orchestration.barrier import ExperienceBarrier

ROLES = {"uav0": "searcher", "uav1": "searcher", "uav2": "searcher", "uav3": "leader"}
ALL = set(ROLES)
_seq = 0


def report(
    uav: str, episode: int, *, phase: str = "experience", shared: int = -1, taken: int = 0,
    received: int | None = None, epoch: int = 1, role: str | None = None,
) -> ProgressReport:  # fmt: skip
    global _seq
    _seq += 1
    return ProgressReport(
        h=Header(sender=uav, epoch=epoch, seq=_seq, stamp=0.0), phase=phase,  # type: ignore[arg-type]
        uav=uav, mission_id="m", episode=episode, round=5 if phase == "round" else -1,
        role=role or ROLES[uav], skill="", invocation="", label=None, held=True,
        experience_shared=shared, experience_taken=taken,
        experience_received=taken if received is None else received,
    )  # fmt: skip


async def rechecked(b: ExperienceBarrier) -> None:
    """Yield until the waiter has re-evaluated after the last report (it clears the change
    event before it waits again): the negative checks read the barrier's state, not a clock."""
    for _ in range(100):
        await asyncio.sleep(0)
        if not b._changed.is_set():
            return
    raise AssertionError("the waiter never re-checked the last report")


def played(b: ExperienceBarrier, episode: int, uavs: set[str] = ALL, epoch: int = 1) -> None:
    for u in sorted(uavs):
        b.on_report(report(u, episode, phase="round", epoch=epoch))


async def test_opens_when_every_daemon_received_what_the_others_shared() -> None:
    b = ExperienceBarrier(timeout_s=10.0)
    played(b, 0)
    shares = {"uav0": 3, "uav1": 4, "uav2": 5, "uav3": 6}
    for u, n in shares.items():
        b.on_report(report(u, 0, shared=n))
    wait = asyncio.create_task(b.wait(0, ALL, lambda: ALL))
    # uav0 receives 4 + 5 + 6 and takes 4 + 5 (uav1, uav2), never uav3's (another role)
    taken = {"uav0": 9, "uav1": 8, "uav2": 7, "uav3": 0}
    received = {u: sum(shares.values()) - shares[u] for u in ALL}
    for u in sorted(ALL - {"uav2"}):
        b.on_report(report(u, 0, shared=shares[u], taken=taken[u], received=received[u]))
    b.on_report(report("uav2", 0, shared=5, taken=7, received=12))  # one short
    await rechecked(b)
    assert not wait.done()
    b.on_report(report("uav2", 0, shared=5, taken=7, received=13))
    assert await asyncio.wait_for(wait, 5.0) is True
    assert b.stats.as_dict() == {
        "episodes": 1, "confirmed": 1, "timeouts": 0, "records": 24,
        "wait_s_max": b.stats.as_dict()["wait_s_max"],
    }  # fmt: skip


async def test_a_reassignment_mid_episode_does_not_hold_the_barrier() -> None:
    """The Commander made every UAV an observer mid-episode: each published records of two
    roles and its peers took only the observer ones. Counting taken records against what
    was published, the barrier waited for records no peer would ever take, to its bound."""
    b = ExperienceBarrier(timeout_s=10.0)
    uavs = {"uav0", "uav1", "uav2"}
    played(b, 0, uavs)
    for u in sorted(uavs):  # 8 records each: 3 as searcher, then 5 as observer
        b.on_report(report(u, 0, shared=8, taken=10, received=16, role="observer"))
    assert await asyncio.wait_for(b.wait(0, uavs, lambda: uavs), 5.0) is True
    assert b.stats.records == 30


async def test_a_sharer_that_has_not_shared_holds_the_barrier() -> None:
    b = ExperienceBarrier(timeout_s=10.0)
    played(b, 0)
    b.on_report(report("uav0", 0, shared=2, taken=2, received=4))
    b.on_report(report("uav1", 0, shared=2, taken=2, received=4))
    b.on_report(report("uav3", 0, shared=2, taken=0, received=4))
    b.on_report(report("uav2", 0, taken=4, received=6))  # received all, has not shared (-1)
    wait = asyncio.create_task(b.wait(0, ALL, lambda: ALL))
    await rechecked(b)
    assert not wait.done()
    b.on_report(report("uav2", 0, shared=0, taken=4, received=6))  # nothing of its own
    assert await asyncio.wait_for(wait, 5.0) is True


async def test_dead_and_restarted_daemons_are_not_waited_for() -> None:
    b = ExperienceBarrier(timeout_s=10.0)
    played(b, 0)
    alive = set(ALL)
    b.on_report(report("uav0", 0, shared=3, taken=0))  # shared, then died before taking
    b.on_report(report("uav3", 0, shared=1, taken=0, received=5))  # uav0's 3, uav2's 2
    wait = asyncio.create_task(b.wait(0, ALL, lambda: alive))
    alive.discard("uav0")
    # uav1 restarted since it played: its new life (epoch 2) is not waited for
    b.on_report(report("uav1", 0, phase="ready", epoch=2))
    # took uav0's 3 (uav1 shared nothing), received uav3's 1 too (another role)
    b.on_report(report("uav2", 0, shared=2, taken=3, received=4))
    assert await asyncio.wait_for(wait, 5.0) is True


async def test_gives_up_at_its_bound_and_says_what_was_missing() -> None:
    b = ExperienceBarrier(timeout_s=0.3)
    played(b, 4)
    for u in ALL:
        b.on_report(report(u, 4, shared=1, taken=0))
    assert await b.wait(4, ALL, lambda: ALL) is False
    stats = b.stats.as_dict()
    assert (stats["episodes"], stats["confirmed"], stats["timeouts"]) == (1, 0, 1)
    assert stats["missing"] == [
        "episode 4: uav0 received 0 of 3; uav1 received 0 of 3; uav2 received 0 of 3; "
        "uav3 received 0 of 3"
    ]


async def test_no_sharers_opens_at_once() -> None:
    b = ExperienceBarrier(timeout_s=10.0)
    assert await asyncio.wait_for(b.wait(0, set(), lambda: ALL), 1.0) is True
