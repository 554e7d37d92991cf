"""Through a router: the per-hop ACL holds at the router, and signatures hold end to end
even when the router itself is hostile (it is allowed to relay anything, so only the
signature check can tell its forgeries from genuine traffic)."""

from __future__ import annotations

import asyncio

import zenoh

from aeroweaver_edge.contracts.wire import Codec, Header, HeaderFactory, InboxMessage, Keys
from aeroweaver_edge.mesh.peers import PeerLink
from aeroweaver_edge.security.identity import SwarmPki
from aeroweaver_edge.security.pki import load_signing_key
from aeroweaver_edge.security.signing import Signer
from tests.helpers.secure_net import SecureNet, Tap, until_delivered
from tests.helpers.zenoh_net import eventually, free_port

K = Keys("s")
HERE = (0.0, 0.0, -5.0)
STILL = (0.0, 0.0, 0.0)


async def links(net: SecureNet, *uavs: str) -> dict[str, PeerLink]:
    """Client-mode UAVs with PeerLinks, attached to the net's seed (a router)."""
    out = {}
    for uav in uavs:
        mesh = await net.open(uav, mode="client")
        link = PeerLink(mesh, K, uav, HeaderFactory(uav, epoch=1), 55.0)
        await link.start()
        out[uav] = link
    for uav, link in out.items():
        assert await link.wait_for_peers(set(uavs) - {uav}, 5.0)
        link.publish_beacon(1, HERE, STILL)
    for link in out.values():
        while len(link.neighbours) < len(uavs) - 1:  # beacons travel via the router
            await link.refresh_neighbours(0.2)
    return out


async def test_router_enforces_the_acl_for_its_clients(secure_net: SecureNet) -> None:
    await secure_net.open("router", mode="router")
    uav1 = await secure_net.open("uav1", mode="client")
    tap = Tap(uav1.session, K.state("*"))
    evil = await secure_net.raw("uav0", overrides={"mode": "client"})
    hello = (K.state("uav0"), b"hello")
    assert await until_delivered(tap, lambda: evil.put(*hello), hello)
    evil.put(K.state("uav2"), b"forbidden")  # refused at the router's ingress
    evil.put(K.state("uav0"), b"control")
    assert await tap.wait_for((K.state("uav0"), b"control"))
    assert not [k for k, v in tap.items if v == b"forbidden"]


async def test_signed_messages_cross_a_genuine_router(secure_net: SecureNet) -> None:
    await secure_net.open("router", mode="router")
    peers = await links(secure_net, "uav0", "uav1")
    ref = await peers["uav0"].send("uav1", "status", {"ok": True}, round=1)
    assert ref is not None
    [msg] = await peers["uav1"].collect_inbox([ref], timeout_s=5.0)
    assert msg.body == {"ok": True}
    assert all(m.codec.stats.total == 0 for m in secure_net.meshes)


async def test_hostile_router_cannot_forge_or_replay(
    secure_net: SecureNet, swarm_pki: SwarmPki
) -> None:
    secure_net.seed_port = port = free_port()  # the hostile router is everyone's seed
    router = await secure_net.raw(
        "router", listen=f"tls/127.0.0.1:{port}", connect=False, overrides={"mode": "router"}
    )
    captured: list[tuple[str, bytes, bytes | None]] = []
    loop = asyncio.get_running_loop()

    def capture(s: zenoh.Sample) -> None:
        att = s.attachment.to_bytes() if s.attachment is not None else None
        loop.call_soon_threadsafe(captured.append, (str(s.key_expr), s.payload.to_bytes(), att))

    router.declare_subscriber(
        "aw/s/uav/*/inbox/*", zenoh.handlers.Callback(capture, indirect=False)
    )
    peers = await links(secure_net, "uav0", "uav1", "uav2")
    a, b = peers["uav0"], peers["uav1"]
    first = await a.send("uav1", "status", {"n": 1}, round=1)
    other = await a.send("uav2", "status", {"n": 2}, round=1)
    assert first is not None
    assert other is not None
    await b.collect_inbox([first], timeout_s=5.0)
    assert await eventually(lambda: len(captured) == 2, 5.0)
    genuine = {key: (data, att) for key, data, att in captured}
    to_b, to_c = K.inbox("uav1", "uav0"), K.inbox("uav2", "uav0")

    def forged(sender: str, seq: int) -> bytes:
        h = Header(sender=sender, epoch=1, seq=seq, stamp=0.0)
        return Codec().encode(InboxMessage(h=h, to="uav1", round=1, kind="land now"))

    router_key = load_signing_key(swarm_pki.paths("router").sign_key)
    as_uav0 = Signer("uav0", router_key)  # the router's own key, claiming to be uav0
    as_router = Signer("router", router_key)
    attacks = [
        (to_b, forged("uav0", 100), None),  # unsigned
        (to_b, forged("uav0", 101), as_uav0.sign(to_b, forged("uav0", 101))),  # wrong key
        (to_b, genuine[to_c][0], genuine[to_c][1]),  # genuine, moved to another topic
        (to_b, genuine[to_b][0], genuine[to_b][1]),  # genuine, replayed
        (
            K.inbox("uav1", "router"),
            forged("router", 1),
            as_router.sign(K.inbox("uav1", "router"), forged("router", 1)),
        ),  # its own identity, but a router authors nothing
    ]
    for key, data, att in attacks:
        router.put(key, data, attachment=att)
    control = await a.send("uav1", "status", {"n": 3}, round=1)
    assert control is not None
    got = await b.collect_inbox([control], timeout_s=5.0)
    assert [m.body for m in got] == [{"n": 3}]
    assert dict(b._mesh.codec.stats.rejected) == {
        "unsigned": 1,
        "wrong_key": 1,
        "unauthorised_signer": 1,
    }
    # The genuine message moved to uav1's inbox names uav2 as recipient: refused by the
    # cheap checks before its signature is verified (issue 22: no crypto for what cannot
    # be accepted anyway); the replay likewise.
    assert b.stats.rejected == {"replay": 1, "wrong_recipient": 1}
    assert b.stats.received == 2


async def test_signed_restart_epoch_is_taken_at_once(secure_net: SecureNet) -> None:
    """With signatures the epoch is authentic: a restarted sender (new epoch, seq from 1)
    is accepted while its old session still looks live, and its old epoch is refused."""
    await secure_net.open("router", mode="router")
    peers = await links(secure_net, "uav0", "uav1")
    a, b = peers["uav0"], peers["uav1"]
    first = await a.send("uav1", "status", {}, round=1)
    assert first is not None
    await b.collect_inbox([first], timeout_s=5.0)
    key = K.inbox("uav1", "uav0")
    for epoch, seq in ((2, 1), (1, 99)):
        h = Header(sender="uav0", epoch=epoch, seq=seq, stamp=0.0)
        forged = InboxMessage(h=h, to="uav1", round=1, kind="status", sender_pos=HERE)
        a._mesh.put(key, forged, block=True)
    control = await a.send("uav1", "status", {}, round=1)  # epoch 1 again: now too old
    h = Header(sender="uav0", epoch=2, seq=2, stamp=0.0)
    a._mesh.put(
        key, InboxMessage(h=h, to="uav1", round=1, kind="done", sender_pos=HERE), block=True
    )
    assert await eventually(lambda: b.stats.received + b.stats.rejected.total() == 5, 5.0)
    got = await b.collect_inbox(timeout_s=0.0)
    assert [(m.h.epoch, m.h.seq) for m in got] == [(2, 1), (2, 2)]
    assert control is not None
    assert b.stats.rejected == {"old_epoch": 2}
