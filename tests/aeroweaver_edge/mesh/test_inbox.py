"""The shared receive side: the reach rule across an episode boundary."""

from __future__ import annotations

import asyncio

from aeroweaver_edge.contracts.wire import Header, InboxMessage, Vec3
from aeroweaver_edge.mesh.inbox import POSITION_MEMORY, Inbox

HERE: Vec3 = (0.0, 0.0, 10.0)


def msg(seq: int, round_: int) -> InboxMessage:
    return InboxMessage(
        h=Header(sender="uav1", epoch=1, seq=seq, stamp=0.0),
        to="uav0",
        round=round_,
        kind="intent",
        sender_pos=HERE,
    )


def collect(inbox: Inbox, max_round: int) -> list[InboxMessage]:
    return asyncio.run(inbox.collect(timeout_s=0.0, max_round=max_round))


def test_messages_of_the_next_episode_reach_after_a_full_episode() -> None:
    """Rounds restart at 0 each episode. The first rounds of the second episode used to lose
    every message: the old episode's positions evicted the new ones."""
    inbox = Inbox("uav0")
    seq = 0
    for episode in range(3):
        for rnd in range(POSITION_MEMORY + 8):
            inbox.note_position(rnd, HERE)
            got = collect(inbox, rnd - 1)
            if rnd > 0:
                assert [m.round for m in got] == [rnd - 1], (episode, rnd, inbox.stats.rejected)
            seq += 1
            inbox.offer(msg(seq, rnd))
        collect(inbox, POSITION_MEMORY + 8)  # the last round's message: no next round
    assert "no_own_position" not in inbox.stats.rejected, inbox.stats.rejected


def test_positions_stay_bounded_within_an_episode() -> None:
    inbox = Inbox("uav0")
    for rnd in range(3 * POSITION_MEMORY):
        inbox.note_position(rnd, HERE)
    assert inbox.round == 3 * POSITION_MEMORY - 1
    inbox.offer(msg(1, 0))  # far older than the memory: cannot be judged
    assert collect(inbox, 3 * POSITION_MEMORY) == []
    assert inbox.stats.rejected["no_own_position"] == 1


def test_the_last_rounds_messages_are_an_ended_episode_not_a_refusal() -> None:
    inbox = Inbox("uav0")
    for rnd in range(24):
        inbox.note_position(rnd, HERE)
    inbox.offer(msg(1, 23))  # sent in the last round: no next round to enter
    inbox.offer(msg(2, 40))  # beyond the episode's rounds: forged or stale
    inbox.note_position(0, HERE)  # the next episode
    assert collect(inbox, -1) == []
    assert inbox.stats.rejected == {"episode_ended": 1, "future_round": 1}


def test_a_late_message_of_the_ended_episode_is_not_a_refusal_either() -> None:
    inbox = Inbox("uav0")
    for rnd in range(24):
        inbox.note_position(rnd, HERE)
    inbox.note_position(0, HERE)
    assert inbox.admit(msg(1, 23)) == "episode_ended"
    assert inbox.admit(msg(2, 22)) == "episode_ended"
    assert inbox.admit(msg(3, 40)) == "future_round"
    assert inbox.admit(msg(4, 10)) == "future_round"  # not the episode's end: a refusal
    assert inbox.admit(msg(5, 1)) is None


def test_a_round_older_than_every_kept_position_is_too_old() -> None:
    """Peer links refuse such a message before its signature (issue 22): collect could only
    say ``no_own_position`` about it."""
    inbox = Inbox("b")
    assert not inbox.too_old(0)  # no position yet: nothing to judge by
    for r in range(POSITION_MEMORY + 4):
        inbox.note_position(r, (0.0, 0.0, -5.0))
    oldest = min(range(POSITION_MEMORY + 4)[-POSITION_MEMORY:])
    assert inbox.too_old(oldest - 1)
    assert not inbox.too_old(oldest)
    assert not inbox.too_old(POSITION_MEMORY + 10)


def test_the_next_episodes_first_rounds_are_not_too_old_before_our_own_beacon() -> None:
    """A peer may start the next episode (rounds restart at 0) and send in it before this
    UAV publishes its own first beacon of it. Refused as too old on arrival, whether the
    message counted depended on which daemon ran first: repeated lockstep runs of one seed
    diverged at episode starts (pursuit_evasion seed 3: a ``follow_peer`` option offered or
    not). Such a message is early, not old: it waits for collect, which judges its reach on
    our position in its round. A round that cannot be an episode start stays too old."""
    inbox = Inbox("uav0")
    for rnd in range(24):  # the episode that just ended
        inbox.note_position(rnd, HERE)
    ahead = inbox.limits.future_rounds
    assert ahead is not None
    for rnd in range(ahead + 1):
        assert not inbox.too_old(rnd), rnd
    assert inbox.too_old(ahead + 1)
    assert inbox.too_old(24 - POSITION_MEMORY - 1)
    assert inbox.admit(msg(1, 0)) is None
    inbox.offer(msg(1, 0))  # the peer's round 0 of the next episode
    inbox.note_position(0, HERE)  # our own first beacon of it, after the message
    assert collect(inbox, -1) == []
    inbox.note_position(1, HERE)
    assert [m.h.seq for m in collect(inbox, 0)] == [1]
    assert inbox.stats.rejected == {}
