"""The transport refuses what an identity may not do: real zenoh sessions, TLS + mTLS + ACL.

The attacker is a hostile process with a *valid* certificate (a compromised uav1) that
loads no ACL and signs nothing, so only the receiving node's own checks stand in the way.
Each negative check is ordered: the forbidden operation goes first, an allowed control
goes after it on the same link, and the test waits for the control (links deliver in
order, so a forbidden sample that got through would have arrived before it).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable

import msgspec
import pytest
import zenoh

from aeroweaver_edge.contracts.wire import (
    Assignment,
    HeaderFactory,
    InboxMessage,
    Keys,
    SimCommand,
    SimEpisode,
    SimPerception,
    StateBeacon,
)
from aeroweaver_edge.mesh.session import Mesh, MeshError
from aeroweaver_edge.security.identity import SwarmPki
from tests.helpers.secure_net import SecureNet, Tap, until_delivered
from tests.helpers.zenoh_net import free_port

K = Keys("s")
ROOT = "aw/s/**"


async def attacker_on(net: SecureNet, tap: Tap, name: str = "uav1") -> zenoh.Session:
    """``name``'s hostile session, connected, with the tap's subscription known to it."""
    evil = await net.raw(name)
    hello = (K.state(name), b"hello")
    assert await until_delivered(tap, lambda: evil.put(*hello), hello)
    return evil


FORBIDDEN_FOR_UAV1 = [
    pytest.param(K.state("uav2"), id="another-uav-state"),
    pytest.param(K.report("uav2"), id="another-uav-report"),
    pytest.param(K.experience("uav2"), id="another-uav-experience"),
    pytest.param(K.inbox("uav2", "uav0"), id="another-senders-inbox-slot"),
    pytest.param(K.sim_command("uav2"), id="another-uavs-sim-command"),
    pytest.param(K.context, id="commander-context"),
    pytest.param(K.assign("uav1"), id="commander-assignment"),
    pytest.param(K.sim_perception("uav1"), id="sim-perception"),
    pytest.param(K.sim_reward("uav1"), id="sim-reward"),
    pytest.param(K.sim_episode, id="sim-episode"),
    pytest.param("aw/s/central/decide/uav1", id="central"),
    pytest.param("aw/s/uav/*/state", id="wildcard-over-others"),
]


@pytest.mark.parametrize("key", FORBIDDEN_FOR_UAV1)
async def test_uav_put_outside_its_keys_is_refused(secure_net: SecureNet, key: str) -> None:
    observer = await secure_net.open("observer")  # reads everything in the swarm
    tap = Tap(observer.session, ROOT)
    evil = await attacker_on(secure_net, tap)
    evil.put(key, b"forbidden")
    control = (K.state("uav1"), b"control")
    evil.put(*control)
    assert await tap.wait_for(control)
    assert (key, b"forbidden") not in tap.items
    assert not [k for k, v in tap.items if v == b"forbidden"]


@pytest.mark.parametrize(
    "key",
    [
        K.state("uav1"),
        K.report("uav1"),
        K.experience("uav1"),
        K.inbox("uav2", "uav1"),
        K.sim_command("uav1"),
    ],
)
async def test_uav_put_on_its_own_keys_is_delivered(secure_net: SecureNet, key: str) -> None:
    observer = await secure_net.open("observer")
    tap = Tap(observer.session, ROOT)
    evil = await attacker_on(secure_net, tap)
    evil.put(key, b"mine")
    assert await tap.wait_for((key, b"mine"))


async def test_forged_liveliness_tokens_are_refused(secure_net: SecureNet) -> None:
    observer = await secure_net.open("observer")
    tap = Tap(observer.session, ROOT)
    alive = Tap(observer.session, K.alive_all, liveliness=True)
    evil = await attacker_on(secure_net, tap)
    forged = [K.alive_uav("uav99"), K.alive_uav("uav2"), K.alive_cmdr, "aw/s/alive/world"]
    tokens = [evil.liveliness().declare_token(k) for k in forged]
    own = evil.liveliness().declare_token(K.alive_uav("uav1"))
    assert await alive.wait_for((K.alive_uav("uav1"), b"+"))
    assert alive.items == [(K.alive_uav("uav1"), b"+")]
    for t in [*tokens, own]:
        t.undeclare()


async def test_observer_can_publish_nothing(secure_net: SecureNet) -> None:
    """The observer may read and query but not write. Its one allowed effect on the world
    is a query, used as the in-order control after its forbidden puts."""
    world = await secure_net.open("world")
    tap = Tap(world.session, ROOT)
    asked = asyncio.Event()
    probe = K.sim("probe")

    def answer() -> SimEpisode:
        asked.set()
        return SimEpisode(h=HeaderFactory("world").next(), episode=0, task="t", phase="start")

    world.declare_queryable(probe, answer)
    spy = await secure_net.raw("observer")

    def ask() -> list[str]:
        return [str(r.ok.key_expr) for r in spy.get(probe, timeout=2.0) if r.ok is not None]

    loop = asyncio.get_running_loop()
    deadline = loop.time() + 5.0
    while not await asyncio.to_thread(ask):  # the spy's link and the queryable are known
        assert loop.time() < deadline
    for key in (K.state("uav0"), K.sim_episode, K.context, K.sim_command("uav0"), probe):
        spy.put(key, b"observer")
    asked.clear()
    assert await asyncio.to_thread(ask) == [probe]
    assert asked.is_set()
    assert not [k for k, v in tap.items if v == b"observer"]


async def test_queryable_on_someone_elses_key_is_not_asked(secure_net: SecureNet) -> None:
    """Reply spoofing: uav1 declares a queryable on uav2's state and on the context; the
    declarations are refused, so queries never reach them and no forged reply comes back."""
    observer = await secure_net.open("observer")
    tap = Tap(observer.session, ROOT)
    evil = await attacker_on(secure_net, tap)
    qs = [
        evil.declare_queryable(key, lambda q, k=key: q.reply(k, b"forged"))
        for key in (K.state("uav2"), K.context)
    ]
    qs.append(evil.declare_queryable(K.state("uav1"), lambda q: q.reply(K.state("uav1"), b"own")))
    control = (K.state("uav1"), b"declared")
    evil.put(*control)  # after the declarations, on the same link
    assert await tap.wait_for(control)
    replies = await asyncio.to_thread(
        lambda: [
            (str(r.ok.key_expr), r.ok.payload.to_bytes())
            for key in ("aw/s/uav/*/state", K.context)
            for r in observer.session.get(key, timeout=2.0)
            if r.ok is not None
        ]
    )
    assert replies == [(K.state("uav1"), b"own")]
    for q in qs:
        q.undeclare()


async def test_uav_cannot_read_another_uavs_private_keys(secure_net: SecureNet) -> None:
    """Least privilege on reads: a UAV's subscription on another UAV's inbox or simulator
    perception is refused, so nothing addressed to uav2 is ever sent to uav1."""
    world = await secure_net.open("world")
    uav1 = await secure_net.open("uav1")
    uav2 = await secure_net.open("uav2")
    spy_inbox = Tap(uav1.session, K.inbox("uav2"))
    spy_sim = Tap(uav1.session, K.sim_perception("uav2"))
    own = Tap(uav1.session, K.sim_perception("uav1"))
    legit = Tap(uav2.session, K.sim_perception("uav2"))
    ready = (K.sim_perception("uav2"), b"p0")
    assert await until_delivered(legit, lambda: world.put_bytes(ready[0], b"p0"), ready)
    control = (K.sim_perception("uav1"), b"p1")
    assert await until_delivered(own, lambda: world.put_bytes(control[0], b"p1"), control)
    world.put_bytes(K.sim_perception("uav2"), b"secret")
    world.put_bytes(K.sim_perception("uav1"), b"p2")
    assert await own.wait_for((K.sim_perception("uav1"), b"p2"))
    assert await legit.wait_for((K.sim_perception("uav2"), b"secret"))
    assert spy_sim.items == []
    assert spy_inbox.items == []


MUST_CONNECT = {"connect/exit_on_failure": True, "connect/timeout_ms": 1000}


@pytest.mark.parametrize(
    "how", ["rogue-ca-cert", "rogue-ca-cert-trusting-rogue", "no-client-cert", "plain-tcp"]
)
async def test_session_without_a_valid_certificate_cannot_connect(
    secure_net: SecureNet, rogue_pki: SwarmPki, how: str
) -> None:
    """With exit_on_failure the dialler's open fails iff no link could be made: a refused
    handshake is a deterministic error, not an absence waited for."""
    observer = await secure_net.open("observer")
    kwargs = {
        "rogue-ca-cert": {"cert_from": rogue_pki},
        "rogue-ca-cert-trusting-rogue": {"cert_from": rogue_pki, "trust": rogue_pki},
        "no-client-cert": {"client_cert": False},
        "plain-tcp": {"plain_tcp": True},
    }[how]
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        await secure_net.raw("uav1", overrides=MUST_CONNECT, **kwargs)  # type: ignore[arg-type]
    legit = await secure_net.raw("uav0", overrides=MUST_CONNECT)  # the positive control
    assert legit.info.transports() != []
    assert [str(lk.auth_identifier) for lk in observer.session.info.links()] == ["uav0"]


async def test_listener_with_a_rogue_certificate_is_not_joined(
    secure_net: SecureNet, rogue_pki: SwarmPki
) -> None:
    """A genuine node dialling a listener whose certificate is not from the swarm CA (here
    even with the right CN) refuses it."""
    await secure_net.open("observer")
    port = free_port()
    await secure_net.raw(
        "world", cert_from=rogue_pki, listen=f"tls/127.0.0.1:{port}", connect=False
    )
    cfg = secure_net.config("uav0")
    cfg = cfg.model_copy(
        update={
            "connect": [f"tls/127.0.0.1:{port}"],
            "listen": [],
            "zenoh_overrides": {"connect/exit_on_failure": "true", "connect/timeout_ms": "1000"},
        }
    )
    with pytest.raises(MeshError, match="cannot open zenoh session"):
        await Mesh.open(cfg, node_id="uav0")


async def test_no_namespace_acl_also_holds(swarm_pki: SwarmPki) -> None:
    """The ACL sees keys with the namespace in front; without one the rules are bare."""
    net = SecureNet(swarm_pki, namespace="")
    try:
        observer = await net.open("observer")
        tap = Tap(observer.session, ROOT)
        evil = await attacker_on(net, tap)
        evil.put(K.state("uav2"), b"forbidden")
        evil.put(K.state("uav1"), b"control")
        assert await tap.wait_for((K.state("uav1"), b"control"))
        assert not [k for k, v in tap.items if v == b"forbidden"]
    finally:
        await net.aclose()


async def test_secured_swarm_delivers_every_allowed_flow(secure_net: SecureNet) -> None:
    """World, Commander and UAVs on TLS + ACL + signatures: each flow of a simulated round
    arrives decoded and verified, and nothing was refused on the way."""
    world = await secure_net.open("world")
    cmdr = await secure_net.open("cmdr")
    uav0 = await secure_net.open("uav0")
    uav1 = await secure_net.open("uav1")
    hw, hc, h0 = HeaderFactory("world"), HeaderFactory("cmdr"), HeaderFactory("uav0")
    still = (0.0, 0.0, 0.0)
    flows: list[tuple[Mesh, Mesh, str, type[msgspec.Struct], Callable[[], msgspec.Struct]]] = [
        (world, uav0, K.sim_perception("uav0"), SimPerception,
         lambda: SimPerception(h=hw.next(), uav="uav0", episode=0, round=0, deadline_s=1.0,
                               pos=still, vel=still)),
        (cmdr, uav0, K.assign("uav0"), Assignment,
         lambda: Assignment(h=hc.next(), mission_id="m", uav="uav0", role="r", local_goal="g",
                            skills=["hold_position"])),
        (uav0, uav1, K.inbox("uav1", "uav0"), InboxMessage,
         lambda: InboxMessage(h=h0.next(), to="uav1", round=0, kind="s")),
        (uav0, uav1, K.state("uav0"), StateBeacon,
         lambda: StateBeacon(h=h0.next(), uav="uav0", round=0, pos=still, vel=still)),
        (uav0, world, K.sim_command("uav0"), SimCommand,
         lambda: SimCommand(h=h0.next(), uav="uav0", episode=0, round=0, vel=(1.0, 0.0, 0.0))),
    ]  # fmt: skip
    for sender, receiver, key, kind, make in flows:
        sub = receiver.subscribe(key if kind is not SimCommand else K.sim_command(), kind)
        got = None
        for _ in range(50):  # until the links and the subscription are up
            sender.put(key, make())
            with contextlib.suppress(TimeoutError):
                got = await asyncio.wait_for(sub.get(), 0.1)
                break
        assert got is not None, key
        assert got[0] == key
        assert got[1].h.sender == sender.node_id
    for m in (world, cmdr, uav0, uav1):
        assert m.codec.stats.total == 0
        assert m.security_summary() | {"identity": "-", "role": "-", "identities_version": 1} == {
            "tls": True, "mtls": True, "acl": True, "signed": True,
            "identity": "-", "role": "-", "identities_version": 1,
        }  # fmt: skip
