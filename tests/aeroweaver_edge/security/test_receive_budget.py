"""Budgets before crypto (issue 22), over real TLS + ACL sessions: a compromised but
enrolled UAV flooding its own broadcast key with random signatures costs a receiver at most
its verification budget, every sample is counted, and an honest peer's message still
arrives; unsigned samples never reach the loop."""

from __future__ import annotations

import os

from aeroweaver_edge.contracts.wire import Codec, Header, HeaderFactory, InboxMessage, Keys
from aeroweaver_edge.mesh.intake import BudgetLimits, VerifyBudget
from aeroweaver_edge.mesh.peers import PeerLink
from aeroweaver_edge.security.signing import VERSION
from tests.helpers.secure_net import SecureNet
from tests.helpers.zenoh_net import eventually

K = Keys("s")
HERE = (0.0, 0.0, -5.0)
STILL = (0.0, 0.0, 0.0)
FLOOD = 600
BURST = 20


async def test_a_signature_flood_costs_at_most_the_budget(secure_net: SecureNet) -> None:
    meshes = {u: await secure_net.open(u) for u in ("uav0", "uav1", "uav2")}
    rx = meshes["uav1"]
    rx.budget = VerifyBudget(BudgetLimits(per_round=0, per_s=0, burst=BURST))
    links = {}
    for uav in ("uav0", "uav1"):
        link = PeerLink(meshes[uav], K, uav, HeaderFactory(uav, epoch=1), 55.0)
        await link.start()
        links[uav] = link
    evil = meshes["uav2"]
    token = evil.declare_token(K.alive_uav("uav2"))  # enrolled: it joins the roster
    assert await links["uav1"].wait_for_peers({"uav0", "uav2"}, 5.0)
    assert await links["uav0"].wait_for_peers({"uav1"}, 5.0)
    for link in links.values():
        link.publish_beacon(1, HERE, STILL)
    assert evil.security is not None
    assert evil.security.auth is not None
    assert evil.security.auth.signer is not None
    kid = evil.security.auth.signer._key_id
    codec = Codec()
    for seq in range(1, FLOOD + 1):
        msg = InboxMessage(h=Header(sender="uav2", epoch=1, seq=seq, stamp=0.0), to="*",
                           round=1, kind="status", body={"i": seq}, sender_pos=HERE)  # fmt: skip
        forged = bytes((VERSION,)) + kid + os.urandom(64)
        evil.session.put(K.broadcast("uav2"), codec.encode(msg), attachment=forged)
        if seq % 100 == 0:
            evil.session.put(K.broadcast("uav2"), codec.encode(msg))  # and unsigned ones
    stats = rx.codec.stats.rejected
    counted = ("bad_signature", "over_budget", "intake_full", "replay", "inbox_full_sender")
    assert await eventually(lambda: sum(stats.get(r, 0) for r in counted)
                            + links["uav1"].stats.rejected.total() >= FLOOD, 15.0)  # fmt: skip
    assert stats["bad_signature"] <= BURST  # the verifications it cost: its budget
    assert stats["over_budget"] > 0
    assert stats["unsigned"] == FLOOD // 100  # refused in the callback
    rx.budget = VerifyBudget()  # a fresh budget: uav0 is not the flooder anyway
    ref = await links["uav0"].send("*", "status", {"ok": True}, round=1)
    assert ref is not None
    got = await links["uav1"].collect_inbox([ref], timeout_s=5.0)
    assert [m.body for m in got if m.h.sender == "uav0"] == [{"ok": True}]
    await token.aclose()


async def test_an_honest_peer_keeps_its_own_budget(secure_net: SecureNet) -> None:
    """The budget is per signer: the flooder's empty bucket refuses nobody else."""
    meshes = {u: await secure_net.open(u) for u in ("uav0", "uav1", "uav2")}
    rx = meshes["uav1"]
    rx.budget = VerifyBudget(BudgetLimits(per_round=0, per_s=0, burst=BURST))
    links = {}
    for uav in ("uav0", "uav1", "uav2"):
        link = PeerLink(meshes[uav], K, uav, HeaderFactory(uav, epoch=1), 55.0)
        await link.start()
        links[uav] = link
    for uav, link in links.items():
        assert await link.wait_for_peers({"uav0", "uav1", "uav2"} - {uav}, 5.0)
        link.publish_beacon(1, HERE, STILL)
    for i in range(BURST * 5):  # valid, signed: the flooder spends its budget at uav1
        await links["uav2"].send("uav1", "status", {"i": i}, round=1)
    stats = rx.codec.stats.rejected
    assert await eventually(lambda: stats.get("over_budget", 0) > 0, 10.0)
    refs = [await links["uav0"].send("uav1", "status", {"n": n}, round=1) for n in range(5)]
    got = await links["uav1"].collect_inbox([r for r in refs if r], timeout_s=5.0)
    assert [m.body["n"] for m in got if m.h.sender == "uav0"] == [0, 1, 2, 3, 4]
