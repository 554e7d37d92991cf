"""PeerLink's receive-side bounds, over real zenoh sessions on loopback (no TLS here: these
are the application's own defences, which must hold even when the transport lets a forgery
through, e.g. an ``--insecure`` swarm or a compromised relay)."""

from __future__ import annotations

import asyncio
import math

from aeroweaver_edge.contracts.wire import (
    Header,
    HeaderFactory,
    InboxMessage,
    Keys,
    StateBeacon,
    Vec3,
)
from aeroweaver_edge.mesh.peers import PeerLimits, PeerLink
from aeroweaver_edge.mesh.session import Mesh
from tests.helpers.zenoh_net import ZenohNet, eventually

KEYS = Keys("test")
STILL: Vec3 = (0.0, 0.0, 0.0)
HERE: Vec3 = (0.0, 0.0, -5.0)


async def pair(
    net: ZenohNet, limits: PeerLimits | None = None, *, epoch: int = 1
) -> tuple[PeerLink, PeerLink, Mesh]:
    """Links ``a`` and ``b`` (b with ``limits``) plus a third session ``m`` (mallory, the
    net's seed, so ``a`` can leave and come back)."""
    mallory = await net.open("m")
    out = []
    for uav in ("a", "b"):
        mesh = await net.open(uav)
        link = PeerLink(mesh, KEYS, uav, HeaderFactory(uav, epoch=epoch), 55.0,
                        limits=limits if uav == "b" else None, track_neighbours=True)  # fmt: skip
        await link.start()
        out.append(link)
    a, b = out
    assert await a.wait_for_peers({"b"}, 3.0)
    assert await b.wait_for_peers({"a"}, 3.0)
    a.publish_beacon(1, HERE, STILL)
    b.publish_beacon(1, HERE, STILL)
    assert await eventually(lambda: "a" in b.neighbours and "b" in a.neighbours)
    watch = mallory.watch_liveliness(KEYS.alive_uav("b"))
    await watch.get()  # b's inbox is known to mallory
    return a, b, mallory


def msg(sender: str, epoch: int, seq: int, *, round_: int = 1, body: str = "") -> InboxMessage:
    h = Header(sender=sender, epoch=epoch, seq=seq, stamp=0.0)
    return InboxMessage(
        h=h, to="b", round=round_, kind="status", body={"t": body} if body else {}, sender_pos=HERE
    )


async def settled(link: PeerLink, n: int) -> None:
    assert await eventually(lambda: link.stats.received + link.stats.rejected.total() >= n, 5.0)


async def test_forged_future_epoch_does_not_lock_the_sender_out(zenoh_net: ZenohNet) -> None:
    """Issue 10, row 1: one forged message with a future epoch made every later genuine
    message a replay (rounds/s fell from ~70 to ~1)."""
    a, b, mallory = await pair(zenoh_net)
    mallory.put(KEYS.inbox("b", "a"), msg("a", 2**62, 1), block=True)
    await settled(b, 1)
    refs = [await a.send("b", "status", {"i": i}, round=1) for i in range(5)]
    got = await b.collect_inbox([r for r in refs if r], timeout_s=3.0)
    assert [m.body["i"] for m in got] == [0, 1, 2, 3, 4]
    assert b.stats.rejected == {"epoch_contested": 1}


async def test_restart_after_leaving_is_accepted_and_old_epoch_refused(zenoh_net: ZenohNet) -> None:
    a, b, mallory = await pair(zenoh_net)
    ref = await a.send("b", "status", {}, round=1)
    assert ref is not None
    await b.collect_inbox([ref], timeout_s=3.0)
    await a.aclose()  # the session ends: b sees the token go
    assert await eventually(lambda: "a" not in b.roster)
    mesh = await zenoh_net.open("a")
    a2 = PeerLink(mesh, KEYS, "a", HeaderFactory("a", epoch=2), 55.0, track_neighbours=True)
    await a2.start()
    assert await b.wait_for_peers({"a"}, 3.0)
    assert await a2.wait_for_peers({"b"}, 3.0)
    a2.publish_beacon(1, HERE, STILL)
    assert await eventually(lambda: "a" in b.neighbours, 5.0)
    b.publish_beacon(1, HERE, STILL)  # again, now that a2 listens
    assert await eventually(lambda: "b" in a2.neighbours, 5.0)
    mallory.put(KEYS.inbox("b", "a"), msg("a", 1, 999), block=True)  # the old epoch, replayed
    # b waits for the restarted a's message with the same seq as a's first one, before it
    # is sent: that old arrival must not count (b forgot it when a's session ended).
    waiting = asyncio.create_task(b.collect_inbox([ref], timeout_s=3.0))
    await asyncio.sleep(0)
    ref2 = await a2.send("b", "status", {"again": True}, round=1)
    assert ref2 == ref
    got = await waiting
    assert [m.body for m in got] == [{"again": True}]
    await settled(b, 3)
    assert b.stats.rejected == {"old_epoch": 1}


async def test_unknown_identity_never_joins_the_roster(zenoh_net: ZenohNet) -> None:
    """Issue 10, row 2: a fake token for an unknown id joined every roster and each
    broadcast waited for its beacon."""
    a, b, mallory = await pair(zenoh_net, PeerLimits(known_peers={"a", "b"}))
    mallory.declare_token(KEYS.alive_uav("ghost"))
    ghost = StateBeacon(h=HeaderFactory("ghost").next(), uav="ghost", round=1, pos=HERE, vel=STILL)
    mallory.put(KEYS.state("ghost"), ghost, block=True)
    assert await eventually(lambda: b.stats.rejected.total() == 2)
    assert b.roster == {"a"}
    assert "ghost" not in b.neighbours
    assert b.stats.rejected == {"unknown_peer_token": 1, "unknown_peer": 1}
    assert "ghost" in a.roster  # without known_peers (the old behaviour) it joins


async def test_pending_inbox_is_bounded(zenoh_net: ZenohNet) -> None:
    """Issue 10, row 3: 10,000 future-round messages stayed in memory forever."""
    _, b, mallory = await pair(zenoh_net, PeerLimits(max_pending_per_sender=32))
    n = 2_000
    for seq in range(1, n + 1):  # every round from 2 to 2001: only 2 and 3 are near
        mallory.put(KEYS.inbox("b", "a"), msg("a", 1, seq, round_=1 + seq), block=True)
        if seq % 128 == 0:  # the puts block this loop: let b's intake (256 per sender) drain
            await settled(b, seq)
    await settled(b, n)
    assert b.stats.received == 2
    assert b.stats.rejected == {"future_round": n - 2}
    for seq in range(n + 1, n + 101):  # a flood inside the window: capped per sender
        mallory.put(KEYS.inbox("b", "a"), msg("a", 1, seq, round_=2), block=True)
    await settled(b, n + 100)
    assert b.inbox.pending == 32
    assert len(b.inbox._pending_bytes) == 32
    assert b.stats.rejected["inbox_full_sender"] == 100 - 30
    assert await b.collect_inbox(timeout_s=0.0, max_round=1) == []  # all for later rounds
    b.publish_beacon(2, HERE, STILL)
    assert len(await b.collect_inbox(timeout_s=0.0, max_round=2)) == 31
    b.publish_beacon(3, HERE, STILL)
    [last] = await b.collect_inbox(timeout_s=0.0, max_round=3)
    assert last.round == 3
    assert b.inbox.pending == 0
    assert b.inbox._pending_bytes == {}


async def test_pending_bytes_are_bounded_and_episode_leftovers_dropped(zenoh_net: ZenohNet) -> None:
    _, b, mallory = await pair(zenoh_net, PeerLimits(max_pending_bytes=20_000))
    b.publish_beacon(20, HERE, STILL)  # late in an episode
    for seq in range(1, 11):
        mallory.put(KEYS.inbox("b", "a"), msg("a", 1, seq, round_=21, body="x" * 3000), block=True)
    await settled(b, 10)
    assert b.stats.received == 6  # 6 x ~3.1 kB fit in 20 kB, the 7th does not
    assert b.stats.rejected == {"inbox_full_bytes": 4}
    assert sum(b.inbox._pending_bytes.values()) <= 20_000
    # A new episode restarts rounds at 0: last episode's round-2 leftovers are not kept.
    b.publish_beacon(0, HERE, STILL)
    assert await b.collect_inbox(timeout_s=0.0, max_round=-1) == []
    assert b.stats.rejected["future_round"] == 6
    assert b.inbox.pending == 0


async def test_beacon_must_be_physically_plausible(zenoh_net: ZenohNet) -> None:
    """Issue 10, last row: a forged beacon 1e6 m away made every message to that UAV
    'out of range' for the rest of the run."""
    limits = PeerLimits(max_speed_mps=11.0, round_s=0.5, motion_margin_m=5.0, max_abs_m=500.0)
    _, b, mallory = await pair(zenoh_net, limits)
    hf = HeaderFactory("a", epoch=1)
    hf._seq = 1000  # after a's own beacons

    def forge(round_: int, pos: Vec3) -> None:
        mallory.put(KEYS.state("a"), StateBeacon(h=hf.next(), uav="a", round=round_, pos=pos,
                                                 vel=STILL), block=True)  # fmt: skip

    b.publish_beacon(2, HERE, STILL)
    forge(2, (1e6, 0.0, -5.0))  # far outside any arena
    forge(2, (30.0, 0.0, -5.0))  # 30 m in one round at 11 m/s (+5 m margin)
    forge(2, (math.nan, 0.0, -5.0))
    forge(1_000_000, (5.0, 0.0, -5.0))  # a far-future round to widen the allowance
    forge(2, (10.0, 0.0, -5.0))  # 10 m in one round: plausible
    assert await eventually(lambda: b.neighbours["a"].pos == (10.0, 0.0, -5.0))
    assert b.stats.rejected == {
        "implausible_position": 1,
        "implausible_motion": 1,
        "non_finite_beacon": 1,
        "future_round": 1,
    }
    assert await b.send("a", "status", {}, round=2) is not None  # still in range
    forge(0, (60.0, 60.0, -5.0))  # a new episode: rounds restart, layouts teleport
    assert await eventually(lambda: b.neighbours["a"].pos == (60.0, 60.0, -5.0))


async def test_a_round_stands_for_half_a_second_by_default(zenoh_net: ZenohNet) -> None:
    """With the default round time (the world's 0.5 s), one round at 11 m/s plus the 5 m
    margin allows 10.5 m between beacons: exactly that is plausible, 10.6 m is not."""
    limits = PeerLimits(max_speed_mps=11.0, motion_margin_m=5.0)
    _, b, mallory = await pair(zenoh_net, limits)
    hf = HeaderFactory("a", epoch=1)
    hf._seq = 1000  # after a's own beacons

    def forge(round_: int, north: float) -> None:
        beacon = StateBeacon(h=hf.next(), uav="a", round=round_, pos=(north, 0.0, -5.0), vel=STILL)
        mallory.put(KEYS.state("a"), beacon, block=True)

    forge(2, 10.6)  # one round after a's own beacon at the origin: too far
    forge(2, 10.5)
    assert await eventually(lambda: b.neighbours["a"].pos == (10.5, 0.0, -5.0))
    assert b.stats.rejected == {"implausible_motion": 1}


async def test_a_link_without_its_own_position_sends_nothing(zenoh_net: ZenohNet) -> None:
    """Before its first beacon a UAV cannot say where it sent from: nothing goes out, and
    the drop is counted under its own reason (receivers judge range by sender_pos)."""
    meshes = [await zenoh_net.open(u) for u in ("a", "b")]
    a, b = (
        PeerLink(m, KEYS, u, HeaderFactory(u, epoch=1), 55.0)
        for m, u in zip(meshes, "ab", strict=True)
    )
    for link in (a, b):
        await link.start()
    assert await a.wait_for_peers({"b"}, 3.0)
    assert await a.send("b", "status", {"n": 1}, round=1) is None
    assert await a.send("*", "status", {"n": 2}, round=1) is None
    assert a.stats.dropped == {"no_own_position": 2}
    assert a.stats.sent == 0
    for link in (a, b):
        await link.aclose()


async def test_a_closed_link_sends_nothing(zenoh_net: ZenohNet) -> None:
    """After ``aclose`` the session may live on (the daemon owns it); the link must not."""
    a, _b, _ = await pair(zenoh_net)
    await a.aclose()
    assert await a.send("b", "status", {"n": 1}, round=1) is None
    assert a.stats.dropped["closed"] == 1
    assert a.stats.sent == 0


async def test_cheap_refusals_come_before_the_queue(zenoh_net: ZenohNet) -> None:
    """Issue 22: a message that could never be accepted (wrong recipient, too old to judge,
    a replay) is refused by the subscription's precheck, before the transport would verify
    a signature, and never queued."""
    a, b, mallory = await pair(zenoh_net)
    for r in range(2, 40):
        b.publish_beacon(r, HERE, STILL)
    # round 10: older than every position b keeps (24..39), and not one of the first rounds
    # a next episode may send in before b's own first beacon of it (those wait for collect)
    old = msg("a", 1, 1, round_=10)
    mallory.put(KEYS.inbox("b", "a"), old, block=True)
    wrong = InboxMessage(h=Header(sender="a", epoch=1, seq=2, stamp=0.0), to="c", round=39,
                         kind="status", sender_pos=HERE)  # fmt: skip
    mallory.put(KEYS.inbox("b", "a"), wrong, block=True)
    await settled(b, 2)
    assert b.stats.rejected == {"no_own_position": 1, "wrong_recipient": 1}
    assert b.inbox.pending == 0
    ref = await a.send("b", "status", {"ok": 1}, round=39)
    assert ref is not None
    got = await b.collect_inbox([ref], timeout_s=3.0, max_round=39)
    assert [m.body for m in got] == [{"ok": 1}]
    mallory.put(KEYS.inbox("b", "a"), msg("a", 1, ref.seq, round_=39), block=True)  # replay
    await settled(b, 4)
    assert b.inbox.pending == 0
    assert b.stats.rejected["replay"] == 1
