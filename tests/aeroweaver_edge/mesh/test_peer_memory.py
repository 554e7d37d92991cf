"""The in-memory PeerChannel keeps PeerLink's semantics: roster, broadcast and directed
sends, acceptance at the receiver (routing rule on the sending round's positions), replay
and foreign-sender refusal, ordering and next-round delivery."""

from __future__ import annotations

import pytest

from aeroweaver_edge.contracts.wire import Header, InboxMessage, MsgRef, Vec3
from aeroweaver_edge.mesh.inbox import within
from aeroweaver_edge.mesh.peer_memory import MemoryPeerHub

STILL: Vec3 = (0.0, 0.0, 0.0)


def at(n: float, e: float = 0.0) -> Vec3:
    return (n, e, -5.0)


async def test_roster_broadcast_and_directed() -> None:
    hub = MemoryPeerHub()
    a, b, c = hub.channel("a"), hub.channel("b"), hub.channel("c")
    eve = hub.channel("eve", announce=False)  # listen-only: hears, is in nobody's roster
    assert a.roster == {"b", "c"}
    assert "eve" not in b.roster
    for ch, pos in ((a, at(0)), (b, at(30)), (c, at(60)), (eve, at(1))):
        ch.publish_beacon(0, pos, STILL)
    assert set(a.neighbours) == {"b", "c"}
    ref = await a.send("*", "intent", {"k": 1}, round=0)
    assert ref == MsgRef(sender="a", seq=ref.seq if ref else 0, to="*")
    direct = await a.send("b", "status", {}, round=0)
    assert direct is not None
    assert await a.send("eve", "status", {}, round=0) is None  # not announced: unknown
    assert await a.send("ghost", "status", {}, round=0) is None
    assert a.stats.dropped == {"unknown_peer": 2}
    got_b = await b.collect_inbox([ref, direct], timeout_s=0.5, max_round=0)  # type: ignore[list-item]
    assert [m.kind for m in got_b] == ["intent", "status"]
    assert await c.collect_inbox(timeout_s=0.0, max_round=0) == []  # 60 m: out of range
    assert c.stats.rejected == {"out_of_range": 1}
    [heard] = await eve.collect_inbox(timeout_s=0.0, max_round=0)
    assert heard.body == {"k": 1}


async def test_next_round_delivery_ordering_and_missing() -> None:
    hub = MemoryPeerHub()
    a, b, c = hub.channel("a"), hub.channel("b"), hub.channel("c")
    for ch in (a, b, c):
        ch.publish_beacon(1, at(0), STILL)
        ch.publish_beacon(2, at(0), STILL)
    r1 = await c.send("b", "x", {}, round=1)
    r2 = await a.send("b", "x", {}, round=1)
    r3 = await a.send("b", "x", {}, round=2)
    assert r1 is not None
    assert r2 is not None
    assert r3 is not None
    got = await b.collect_inbox([r1, r2, MsgRef(sender="a", seq=999)], 0.05, max_round=1)
    assert [(m.h.sender, m.round) for m in got] == [("a", 1), ("c", 1)]
    assert b.stats.missing == 1
    [later] = await b.collect_inbox(timeout_s=0.0)
    assert later.round == 2


async def test_routing_rule_and_own_position() -> None:
    hub = MemoryPeerHub()
    s, listener = hub.channel("s"), hub.channel("l")

    def reach(sender: str, receiver: str, d: float) -> bool:
        return (sender, receiver) == ("speaker", "listener") or d <= 55.0

    s.set_routing("speaker", reach)
    listener.set_routing("listener", reach)
    s.publish_beacon(0, at(-60), STILL)
    listener.publish_beacon(0, at(60), STILL)
    assert await s.send("*", "goal", {}, round=0) is not None
    [msg] = await listener.collect_inbox(timeout_s=0.0, max_round=0)
    assert msg.sender_role == "speaker"
    listener.set_routing("listener", within(55.0))  # no route: 120 m is too far
    assert await s.send("*", "goal", {}, round=0) is not None
    assert await listener.collect_inbox(timeout_s=0.0, max_round=0) == []
    # A message of a round this UAV has no position for cannot be judged.
    assert await s.send("*", "goal", {}, round=5) is not None
    assert await listener.collect_inbox(timeout_s=0.0) == []
    assert listener.stats.rejected == {"out_of_range": 1, "no_own_position": 1}


async def test_replays_foreign_senders_and_leaving() -> None:
    hub = MemoryPeerHub()
    a, b = hub.channel("a"), hub.channel("b")
    b.publish_beacon(1, at(0), STILL)
    msg = InboxMessage(
        h=Header(sender="a", epoch=1, seq=5, stamp=0.0), to="b", round=1, kind="x",
        sender_pos=at(1),
    )  # fmt: skip
    b.inject(msg)
    b.inject(msg)
    b.inject(InboxMessage(h=Header(sender="z", epoch=1, seq=1, stamp=0.0), to="b", round=1,
                          kind="x", sender_pos=at(1)))  # fmt: skip
    assert b.stats.rejected == {"replay": 1, "unknown_sender": 1}
    assert await b.collect_inbox(timeout_s=0.0) == [msg]
    await a.aclose()
    assert b.roster == frozenset()
    assert await a.send("*", "x", {}, round=1) is None
    assert a.stats.dropped == {"closed": 1}
    with pytest.raises(ValueError, match="already has a channel"):
        hub.channel("b")
