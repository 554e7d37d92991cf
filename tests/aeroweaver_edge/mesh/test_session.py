"""Mesh over real zenoh sessions on loopback (no mocks)."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import textwrap
import time

import pytest
import zenoh

from aeroweaver_edge.config import ConfigError, MeshConfig
from aeroweaver_edge.contracts.wire import HeaderFactory, Keys, StateBeacon
from aeroweaver_edge.mesh.session import RX_WORKERS, Mesh, MeshClosed, build_zenoh_config
from tests.helpers.zenoh_net import ZenohNet, eventually

KEYS = Keys("test")


def beacon(uav: str, round_: int = 1, headers: HeaderFactory | None = None) -> StateBeacon:
    h = (headers or HeaderFactory(uav)).next()
    return StateBeacon(h=h, uav=uav, round=round_, pos=(1.0, 2.0, -5.0), vel=(0.0, 0.0, 0.0))


async def ready(watcher: Mesh, target: Mesh) -> None:
    """Barrier: ``target`` declares a token after its other declarations; once ``watcher``
    sees it, ``watcher``'s puts and queries reach what ``target`` declared before."""
    key = KEYS.alive_uav(target.node_id)
    watch = watcher.watch_liveliness(key)
    target.declare_token(key)
    assert await asyncio.wait_for(watch.get(), 2.0) == (key, True)
    await watch.aclose()


def test_build_config_sets_ci_defaults_and_overrides() -> None:
    cfg = MeshConfig(
        namespace="ns-1", lease_ms=2000, zenoh_overrides={"transport/unicast/max_links": "2"}
    )
    conf = build_zenoh_config(cfg)
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    assert json.loads(conf.get_json("scouting/gossip/enabled")) is True
    assert json.loads(conf.get_json("scouting/delay")) == 100
    assert json.loads(conf.get_json("transport/link/tx/lease")) == 2000
    assert json.loads(conf.get_json("transport/shared_memory/enabled")) is False
    assert json.loads(conf.get_json("connect/retry"))["period_init_ms"] == 100
    assert json.loads(conf.get_json("namespace")) == "ns-1"
    assert json.loads(conf.get_json("transport/unicast/max_links")) == 2


@pytest.mark.parametrize(
    ("path", "value"),
    [("scouting/multicast/enabld", "false"), ("scouting/delay", "{oops")],
)
def test_bad_override_names_the_key(path: str, value: str) -> None:
    with pytest.raises(ConfigError, match=path):
        build_zenoh_config(MeshConfig(zenoh_overrides={path: value}))


async def test_pub_sub_round_trip(zenoh_net: ZenohNet) -> None:
    a = await zenoh_net.open("a")
    b = await zenoh_net.open("b")
    sub = b.subscribe(KEYS.state("*"), StateBeacon)
    await ready(a, b)

    sent = beacon("a")
    a.put(KEYS.state("a"), sent)
    key, got = await asyncio.wait_for(sub.get(), 2.0)
    assert (key, got) == (KEYS.state("a"), sent)

    a.put(KEYS.state("a"), beacon("a", 2), block=True)
    assert await eventually(lambda: sub.received == 2)
    assert [m.round for _, m in sub.drain()] == [2]
    assert sub.drain() == []


async def test_garbage_is_counted_and_skipped(zenoh_net: ZenohNet) -> None:
    a = await zenoh_net.open("a")
    b = await zenoh_net.open("b")
    sub = b.subscribe(KEYS.state("*"), StateBeacon)
    await ready(a, b)

    a.session.put(KEYS.state("a"), b"\xc1 definitely not msgpack")  # raw zenoh put
    a.put(KEYS.state("a"), beacon("a"))
    _, got = await asyncio.wait_for(sub.get(), 2.0)
    assert got.uav == "a"
    assert sub.undecodable == 1
    assert b.codec.stats.total == 1


async def test_full_subscription_drops_oldest(zenoh_net: ZenohNet) -> None:
    a = await zenoh_net.open("a")
    sub = a.subscribe(KEYS.state("a"), StateBeacon, maxsize=2)
    headers = HeaderFactory("a")
    for r in range(5):
        a.put(KEYS.state("a"), beacon("a", r, headers))  # delivered locally
    assert await eventually(lambda: sub.received == 5)
    assert [m.round for _, m in sub.drain()] == [3, 4]
    assert sub.dropped == 3


async def test_async_iteration_ends_when_mesh_closes(zenoh_net: ZenohNet) -> None:
    a = await zenoh_net.open("a")
    sub = a.subscribe(KEYS.state("a"), StateBeacon)
    seen: list[int] = []

    async def consume() -> None:
        async for _, msg in sub:
            seen.append(msg.round)

    task = asyncio.create_task(consume())
    a.put(KEYS.state("a"), beacon("a", 7))
    assert await eventually(lambda: seen == [7])
    await a.aclose()
    await asyncio.wait_for(task, 1.0)  # woken by the close, not left hanging
    with pytest.raises(MeshClosed):
        await sub.get()


async def test_queryable_and_get(zenoh_net: ZenohNet) -> None:
    a = await zenoh_net.open("a")
    b = await zenoh_net.open("b")
    latest: list[StateBeacon] = []
    a.declare_queryable(KEYS.state("a"), lambda: latest[-1] if latest else None)
    await ready(b, a)

    t0 = time.monotonic()
    assert await b.get(KEYS.state("*"), StateBeacon, timeout_s=2.0) == []
    latest.append(beacon("a", 3))
    replies = await b.get(KEYS.state("*"), StateBeacon, timeout_s=2.0)
    assert replies == [(KEYS.state("a"), latest[-1])]
    assert time.monotonic() - t0 < 1.0  # the replier drops the query: no waiting for timeout


async def test_queryable_needs_concrete_key(zenoh_net: ZenohNet) -> None:
    a = await zenoh_net.open("a")
    with pytest.raises(ValueError, match="concrete"):
        a.declare_queryable(KEYS.state("*"), lambda: None)


async def test_liveliness_join_and_leave(zenoh_net: ZenohNet) -> None:
    a = await zenoh_net.open("a")
    b = await zenoh_net.open("b")
    c = await zenoh_net.open("c")
    watch = a.watch_liveliness(KEYS.alive_uav("*"))
    token_b = b.declare_token(KEYS.alive_uav("b"))
    c.declare_token(KEYS.alive_uav("c"))

    events = {await asyncio.wait_for(watch.get(), 2.0) for _ in range(2)}
    assert events == {(KEYS.alive_uav("b"), True), (KEYS.alive_uav("c"), True)}

    await token_b.aclose()  # explicit undeclare
    assert await asyncio.wait_for(watch.get(), 2.0) == (KEYS.alive_uav("b"), False)
    await c.aclose()  # the whole session goes away
    assert await asyncio.wait_for(watch.get(), 2.0) == (KEYS.alive_uav("c"), False)

    late = a.watch_liveliness(KEYS.alive_uav("*"))  # history: nothing alive any more
    a.declare_token(KEYS.alive_uav("a"))  # a sentinel that joins after the watch started
    assert await asyncio.wait_for(late.get(), 2.0) == (KEYS.alive_uav("a"), True)
    assert late.drain() == []  # neither b nor c came back from history


async def test_aclose_is_idempotent_and_final(zenoh_net: ZenohNet) -> None:
    async with await zenoh_net.open("a") as a:
        a.subscribe(KEYS.state("*"), StateBeacon)
        a.declare_token(KEYS.alive_uav("a"))
    assert a.closed
    assert a.session.is_closed()
    await asyncio.gather(a.aclose(), a.aclose())
    with pytest.raises(MeshClosed):
        a.put(KEYS.state("a"), beacon("a"))
    with pytest.raises(MeshClosed):
        a.subscribe(KEYS.state("*"), StateBeacon)


@pytest.mark.parametrize("close", [True, False])
def test_process_with_every_entity_exits_promptly(close: bool) -> None:
    """Pitfall 1 in docs/notes/zenoh.md: a callback entity's thread can hang interpreter exit.
    Our callbacks run on zenoh's own threads, so even a leaked session must not hang."""
    script = textwrap.dedent(
        f"""
        import asyncio
        from aeroweaver_edge.config import MeshConfig
        from aeroweaver_edge.mesh.session import Mesh
        from aeroweaver_edge.contracts.wire import StateBeacon

        async def main():
            mesh = await Mesh.open(MeshConfig(namespace="exit-test"), node_id="x")
            mesh.subscribe("aw/x/**", StateBeacon)
            mesh.declare_queryable("aw/x/q", lambda: None)
            mesh.watch_liveliness("aw/x/alive/**")
            mesh.declare_token("aw/x/alive/x")
            await mesh.get("aw/x/q", StateBeacon, timeout_s=0.2)
            if {close}:
                await mesh.aclose()

        asyncio.run(main())
        print("done")
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=20, check=True
    )
    assert out.stdout.strip().endswith("done")


async def test_session_is_closed_by_aclose(zenoh_net: ZenohNet) -> None:
    a = await zenoh_net.open("a")
    assert isinstance(a.session, zenoh.Session)
    await a.aclose()
    assert a.session.is_closed()


RX_SCRIPT = """
import asyncio, glob, os
from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.orchestration.network import free_port

async def main():
    ep = f"tcp/127.0.0.1:{free_port()}"
    router = await Mesh.open(MeshConfig(mode="router", listen=[ep], namespace="rx"), node_id="r")
    client = await Mesh.open(
        MeshConfig(mode="client", listen=[], connect=[ep], namespace="rx"), node_id="c"
    )
    want, count = int(os.environ["EXPECT_RX"]), 0
    for _ in range(200):  # tokio starts its workers asynchronously: wait, bounded (10 s)
        names = []
        for t in glob.glob("/proc/self/task/*"):
            try:
                names.append(open(t + "/comm").read().strip())
            except OSError:
                pass  # a thread that ended meanwhile
        count = sum(n.startswith("rx-") for n in names)
        if count >= want:
            break
        await asyncio.sleep(0.05)
    print(count, os.environ["ZENOH_RUNTIME"])
    await client.aclose()
    await router.aclose()

asyncio.run(main())
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="counts threads in /proc")
@pytest.mark.parametrize("preset", [None, "(rx: (worker_threads: 3))"])
def test_the_first_session_gets_spare_rx_workers(preset: str | None) -> None:
    """A silently dead link blocks one zenoh RX worker for up to 10 s when it is closed
    (SO_LINGER); with zenoh's two, two dead links made a router deaf for 10 s. The process's
    first Mesh asks for RX_WORKERS of them, unless the operator set ZENOH_RUNTIME."""
    env = {k: v for k, v in os.environ.items() if k != "ZENOH_RUNTIME"}
    env["EXPECT_RX"] = str(RX_WORKERS if preset is None else 3)
    if preset is not None:
        env["ZENOH_RUNTIME"] = preset
    out = subprocess.run(
        [sys.executable, "-c", RX_SCRIPT], capture_output=True, text=True, timeout=30,
        check=True, env=env,
    )  # fmt: skip
    count, runtime = out.stdout.split(maxsplit=1)
    if preset is None:
        assert int(count) >= RX_WORKERS > 2
        assert runtime.strip() == f"(rx: (worker_threads: {RX_WORKERS}))"
    else:
        assert 3 <= int(count) < RX_WORKERS
        assert runtime.strip() == preset
