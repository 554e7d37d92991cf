"""The receive path under a flood (issue 22): per-sender bounded FIFOs, the verification
budget, and, over real zenoh sessions on loopback, a flooding sender that can neither starve
another sender nor delay a liveliness change, with every callback only enqueueing."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

from aeroweaver_edge.contracts.wire import Header, InboxMessage, Keys, traffic_lane, writer_of
from aeroweaver_edge.mesh.intake import BudgetLimits, SenderQueues, VerifyBudget
from aeroweaver_edge.mesh.session import Mesh
from tests.helpers.zenoh_net import ZenohNet, eventually

K = Keys("test")


def test_sender_queues_are_bounded_per_sender_and_served_round_robin() -> None:
    q: SenderQueues[str] = SenderQueues(per_sender=3, max_senders=2, max_bytes=100)
    for i in range(5):
        why = q.push("flood", f"f{i}", 1)
        assert why == (None if i < 3 else "intake_full")
    assert q.push("honest", "h0") is None
    assert q.push("third", "t0") == "intake_senders"  # the table is bounded too
    assert q.push("honest", "big", 101) == "intake_full"  # bytes per sender
    order = [q.pop() for _ in range(4)]
    assert order == ["f0", "h0", "f1", "f2"]  # the honest one is not behind the backlog
    assert q.pop() is None
    assert len(q) == 0


def test_a_sender_beyond_its_sample_rate_is_refused_before_any_copy() -> None:
    now = [0.0]
    q: SenderQueues[str] = SenderQueues(8, rate=10.0, burst=3.0, clock=lambda: now[0])
    assert [q.admit("flood") for _ in range(5)] == [True, True, True, False, False]
    assert q.admit("honest")  # its own bucket
    now[0] += 0.2  # two samples' worth
    assert [q.admit("flood") for _ in range(3)] == [True, True, False]
    assert SenderQueues[str](8).admit("anyone")  # no rate: always


def test_budget_refills_per_round_and_per_second_up_to_the_burst() -> None:
    now = [0.0]
    b = VerifyBudget(BudgetLimits(per_round=2, per_s=1, burst=3), clock=lambda: now[0])
    assert [b.take("evil") for _ in range(4)] == [True, True, True, False]
    assert b.take("honest")  # every signer has its own bucket
    b.note_round()
    assert [b.take("evil") for _ in range(3)] == [True, True, False]
    now[0] += 2.0
    assert [b.take("evil") for _ in range(3)] == [True, True, False]
    for _ in range(100):
        b.note_round()
    assert sum(b.take("evil") for _ in range(10)) == 3  # never more than the burst
    assert b.refused == 4 + 6
    assert b.spent == 3 + 1 + 2 + 2 + 3


def test_lanes_and_writers_follow_the_key_layout() -> None:
    assert traffic_lane(K.broadcast("uav1")) == "bulk"
    assert traffic_lane(K.inbox("uav0", "uav1")) == "bulk"
    assert traffic_lane(K.experience("uav1")) == "bulk"
    assert traffic_lane(K.alive_uav("uav1")) == "control"
    assert traffic_lane(K.sim_command("uav1")) == "control"
    assert traffic_lane(K.assign("uav1")) == "control"
    assert writer_of(K.inbox("uav0", "uav1")) == "uav1"
    assert writer_of(K.broadcast("uav2")) == "uav2"
    assert writer_of(K.alive_uav("uav2")) == "uav2"
    assert writer_of(K.alive_cmdr) == writer_of(K.context) == "cmdr"
    assert writer_of(K.sim_episode) == "world"


def _msg(sender: str, seq: int) -> InboxMessage:
    return InboxMessage(h=Header(sender=sender, epoch=1, seq=seq, stamp=0.0), to="*", round=1,
                        kind="status", body={"i": seq})  # fmt: skip


async def heard(mesh: Mesh, done: Callable[[], bool], timeout_s: float = 15.0) -> bool:
    """Probe ``mesh``'s broadcast key until ``done()``: the receiver's subscription is known."""
    deadline = time.monotonic() + timeout_s
    while not done():
        if time.monotonic() > deadline:
            return False
        mesh.put(K.broadcast(mesh.node_id), _msg(mesh.node_id, 0))
        await asyncio.sleep(0.05)
    return True


async def test_a_flooding_sender_starves_no_other_sender(zenoh_net: ZenohNet) -> None:
    rx = await zenoh_net.open("rx")
    flood, honest = await zenoh_net.open("flood"), await zenoh_net.open("honest")
    got: list[tuple[str, float]] = []

    def on_item(item: tuple[str, InboxMessage]) -> None:
        got.append((item[1].h.sender, time.monotonic()))

    sub = rx.subscribe(K.broadcast("*"), InboxMessage, on_item=on_item)
    watch = rx.watch_liveliness(K.alive_uav("*"))
    for mesh in (flood, honest):  # rx's subscription is known to both before the flood
        assert await heard(mesh, lambda n=mesh.node_id: any(s == n for s, _ in got))
    got.clear()
    for i in range(1, 20_001):  # a burst far beyond any FIFO, all at once
        flood.put(K.broadcast("flood"), _msg("flood", i))
    sent_at = time.monotonic()
    honest.put(K.broadcast("honest"), _msg("honest", 1))
    token = honest.declare_token(K.alive_uav("honest"))
    # Hold the loop: zenoh's threads deliver everything into rx's FIFOs meanwhile (the
    # flood's is full long before), so the order the loop takes them in is all that counts.
    deadline = time.monotonic() + 15.0
    raw = sub._raw
    assert raw is not None
    while "honest" not in raw._queues and time.monotonic() < deadline:
        time.sleep(0.01)  # noqa: ASYNC251 - blocking the loop on purpose
    assert "honest" in raw._queues
    assert len(raw._queues["flood"]) > 100  # the flood's backlog is queued before it
    assert await eventually(lambda: sum(s == "flood" for s, _ in got) > 100, 15.0)
    order = [s for s, _ in got]
    # Round robin over senders: the honest message is the second one taken, not behind
    # the 1,024 the flood has queued.
    assert order.index("honest") <= 1, order.index("honest")
    event = await asyncio.wait_for(watch.get(), 10.0)
    assert event == (K.alive_uav("honest"), True)
    assert time.monotonic() - sent_at < 10.0
    # Bounded: what the FIFO could not hold was dropped and counted, nothing raised.
    # (zenoh's DROP congestion control may also drop some at the sender: not counted here)
    assert await eventually(lambda: sub.intake_dropped > 0, 10.0)
    refused = rx.codec.stats.rejected
    assert refused.get("intake_full", 0) + refused.get("over_rate", 0) == sub.intake_dropped
    assert refused["over_rate"] > 0  # beyond its sample rate, dropped before any copy
    await token.aclose()


async def test_a_full_intake_never_blocks_the_session(zenoh_net: ZenohNet) -> None:
    """While the loop is busy, callbacks keep returning: the other subscription's sample is
    taken as soon as the loop is free again, and the drops were counted."""
    rx = await zenoh_net.open("rx")
    tx = await zenoh_net.open("tx")
    sub = rx.subscribe(K.broadcast("*"), InboxMessage, maxsize=4)
    cmd = rx.subscribe(K.context, InboxMessage, maxsize=4)
    assert await heard(tx, lambda: sub.received > 0)
    for i in range(1, 2001):
        tx.put(K.broadcast("tx"), _msg("tx", i))
    tx.put(K.context, _msg("cmdr", 1))
    # The loop is held: zenoh's threads keep enqueueing (or dropping), never waiting for it.
    time.sleep(0.5)  # noqa: ASYNC251 - blocking the loop on purpose
    assert await eventually(lambda: cmd.received == 1, 5.0)
    assert sub.intake_dropped > 0 or sub.dropped > 0


def test_the_size_filter_is_a_config_zenoh_accepts() -> None:
    """``intake.low_pass_filter`` is meant for the rendered configs: zenoh 1.10 takes it."""
    import json

    import zenoh

    from aeroweaver_edge.mesh.intake import SIZE_LIMIT_BYTES, low_pass_filter

    conf = zenoh.Config()
    conf.insert_json5("low_pass_filter", json.dumps(low_pass_filter()))
    [entry] = json.loads(conf.get_json("low_pass_filter"))
    assert entry["size_limit"] == SIZE_LIMIT_BYTES
