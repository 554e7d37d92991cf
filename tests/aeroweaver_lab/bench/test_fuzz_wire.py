"""The fuzz harness at CI size (the 10^5 run is ``python -m aeroweaver_lab.bench.fuzz_wire``)."""

from __future__ import annotations

import asyncio

import pytest

from aeroweaver_edge.contracts.wire import InboxMessage, Keys, StateBeacon
from aeroweaver_lab.bench.fuzz_wire import KINDS, Fuzzer, run
from tests.helpers.zenoh_net import ZenohNet, eventually


@pytest.mark.parametrize("secured", [True, False])
def test_every_fuzzed_payload_is_counted_and_nothing_raises(secured: bool) -> None:
    out = run(3000, seed=7, secured=secured)
    assert out["errors"] == 0, out["first_errors"]
    assert out["counted"] == 3000
    assert set(out["by_topic"]) == {*KINDS, "alive"}
    assert set(out["outcomes"]) == {"accepted", "rejected", "ignored"}
    reasons = set(out["rejected_by_reason"])
    assert {"oversize", "schema version"} <= reasons
    if secured:
        assert {"unsigned", "bad_attachment", "wrong_key", "unknown_signer"} <= reasons
        assert {"bad_signature", "unauthorised_signer"} <= reasons
    else:  # no signature layer: the handlers' own checks do the refusing
        assert {"spoofed_beacon", "unknown_peer_token", "mission:not_commander"} <= reasons
    assert out["pending_after"] <= 128


def test_same_seed_same_cases() -> None:
    a, b = Fuzzer(3), Fuzzer(3)
    for _ in range(200):
        ca, cb = a.case(), b.case()
        assert (ca.key, ca.data, ca.how) == (cb.key, cb.data, cb.how)


async def test_fuzzed_bytes_over_a_real_session_are_all_counted(zenoh_net: ZenohNet) -> None:
    """The same hostile bytes through zenoh: every sample reaches the subscription, each is
    either delivered decoded or counted as undecodable, and the loop stays responsive."""
    keys = Keys("fz")
    sender = await zenoh_net.open("m")
    receiver = await zenoh_net.open("uav0")
    states = receiver.subscribe(keys.state("*"), StateBeacon, maxsize=4096)
    inbox = receiver.subscribe(keys.inbox("uav0"), InboxMessage, maxsize=4096)
    watch = sender.watch_liveliness(keys.alive_uav("uav0"))
    receiver.declare_token(keys.alive_uav("uav0"))
    await asyncio.wait_for(watch.get(), 3.0)
    fz = Fuzzer(11)
    sent = {"state": 0, "inbox": 0}
    while sum(sent.values()) < 2000:
        case = fz.case()
        if case.topic in sent and len(case.data) <= 65_536:
            key = keys.state("uav1") if case.topic == "state" else keys.inbox("uav0", "uav1")
            sender.put_bytes(key, case.data, block=True)
            sent[case.topic] += 1
    for sub, topic in ((states, "state"), (inbox, "inbox")):
        done = lambda s=sub, t=topic: s.received + s.undecodable == sent[t]  # noqa: E731
        assert await eventually(done, 10.0)
        assert len(sub.drain()) + sub.dropped == sub.received
        assert sub.undecodable > 0
