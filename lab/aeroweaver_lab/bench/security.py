"""Security overhead benchmark: what TLS, the ACL and signatures cost a swarm.

``python -m aeroweaver_lab.bench.security`` measures, on loopback and with real sessions:

- ``pki``: making a throw-away swarm PKI (CA + every identity), as ``sim`` would per run;
- ``open``: opening a session that dials a listening seed, until the link is up;
- ``rtt``: round trips of a ~100-byte directed message between two daemons' meshes
  (asyncio on both ends), for plain TCP, TLS (mutual), TLS + ACL, TLS + ACL + signatures;
- ``crypto``: Ed25519 sign and verify (with the authorisation check) per payload type;
- ``per_round``: the signature CPU one simulated round adds to the swarm, from the messages
  a lockstep round sends (an estimate built from ``crypto``, not a full run);
- ``runs`` (``--runs 3 10``): whole ``aeroweaver sim`` runs (scripted selector), secured vs
  ``--insecure``, alternating: the world's wall time per round and per run, and whether the
  returns are identical (they must be: security changes nothing a UAV decides).

Prints one JSON document. Figures on a loaded machine are noisy: compare modes from the
same run, and re-run on an idle machine for absolute numbers.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import statistics
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import msgspec

from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.contracts.wire import (
    Codec,
    Entity,
    ExperienceRecord,
    HeaderFactory,
    InboxMessage,
    Keys,
    SimCommand,
    SimPerception,
    StateBeacon,
)
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.security.identity import SwarmPki, default_members
from aeroweaver_edge.security.pki import load_signing_key
from aeroweaver_edge.security.signing import Signer, Verifier

SWARM = "bench"
K = Keys(SWARM)
MODES = ("plain", "tls", "tls+acl", "tls+acl+signed")


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _configs(pki: SwarmPki, mode: str, port: int) -> tuple[MeshConfig, MeshConfig]:
    """Seed (uav1, listening) and dialler (uav0) configs for one security mode."""
    ns = f"bench-{port}"
    if mode == "plain":
        seed = MeshConfig(listen=[f"tcp/127.0.0.1:{port}"], namespace=ns)
        peer = MeshConfig(listen=[], connect=[f"tcp/127.0.0.1:{port}"], namespace=ns)
        return seed, peer
    acl, sign = mode != "tls", mode == "tls+acl+signed"
    out = []
    for name, seed_node in (("uav1", True), ("uav0", False)):
        sec = pki.security_for(name, acl=acl, sign=sign)
        out.append(
            MeshConfig(
                listen=[f"tls/127.0.0.1:{port}"] if seed_node else [],
                connect=[] if seed_node else [f"tls/127.0.0.1:{port}"],
                namespace=ns,
                security=sec,
            )
        )
    return out[0], out[1]


async def _open_pair(pki: SwarmPki, mode: str) -> tuple[Mesh, Mesh, float]:
    port = _free_port()
    seed_cfg, peer_cfg = _configs(pki, mode, port)
    seed = await Mesh.open(seed_cfg, node_id="uav1")
    t0 = time.perf_counter()
    peer = await Mesh.open(peer_cfg, node_id="uav0")
    await asyncio.to_thread(_wait_link, peer)
    return seed, peer, time.perf_counter() - t0


def _wait_link(mesh: Mesh, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not mesh.session.info.transports():
        if time.monotonic() > deadline:
            raise RuntimeError(f"{mesh.node_id}: no link within {timeout_s} s")
        time.sleep(0.0005)


async def bench_open(pki: SwarmPki, repeats: int) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for mode in MODES:
        times = []
        for _ in range(repeats):
            seed, peer, dt = await _open_pair(pki, mode)
            times.append(dt)
            await asyncio.gather(seed.aclose(), peer.aclose())
        out[mode] = _ms(times)
    return out


async def bench_rtt(pki: SwarmPki, n: int) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for mode in MODES:
        a, b, _ = await _open_pair(pki, mode)  # a = uav1 (seed), b = uav0
        try:
            out[mode] = _us(await _ping_pong(a, b, n))
        finally:
            await asyncio.gather(a.aclose(), b.aclose())
    return out


async def _ping_pong(a: Mesh, b: Mesh, n: int) -> list[float]:
    """uav0 (b) sends to uav1's inbox; uav1 answers into uav0's inbox; timed at uav0."""
    ha, hb = HeaderFactory("uav1"), HeaderFactory("uav0")
    got: asyncio.Queue[float] = asyncio.Queue()

    def echo(item: tuple[str, InboxMessage]) -> None:
        a.put(K.inbox("uav0", "uav1"), InboxMessage(h=ha.next(), to="uav0", round=1, kind="pong",
                                                     body=item[1].body))  # fmt: skip

    a.subscribe(K.inbox("uav1", "uav0"), InboxMessage, on_item=echo)
    b.subscribe(K.inbox("uav0", "uav1"), InboxMessage, on_item=lambda _: got.put_nowait(0.0))

    def ping(i: int) -> None:
        body: dict[str, str | int | float | bool] = {"i": i, "pad": "x" * 40}
        b.put(K.inbox("uav1", "uav0"), InboxMessage(h=hb.next(), to="uav1", round=1, kind="ping",
                                                     body=body))  # fmt: skip

    for _ in range(200):  # warm up until the subscriptions are known both ways
        ping(-1)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(0.05):
                await got.get()
            break
    while not got.empty():
        got.get_nowait()
    times = []
    for i in range(n):
        t0 = time.perf_counter()
        ping(i)
        async with asyncio.timeout(5.0):
            await got.get()
        times.append(time.perf_counter() - t0)
    return times


def _payloads() -> dict[str, tuple[str, str, msgspec.Struct]]:
    """(author, key, payload) of the kinds a round carries, at realistic sizes."""
    h = HeaderFactory
    ents = [Entity(id=f"L{i}", kind="landmark", pos=(float(i), 2.0, -5.0)) for i in range(6)]
    return {
        "beacon": ("uav0", K.state("uav0"), StateBeacon(h=h("uav0").next(), uav="uav0",
                   round=3, pos=(1.0, 2.0, -5.0), vel=(0.5, 0.0, 0.0), role="searcher")),
        "inbox": ("uav0", K.inbox("uav1", "uav0"), InboxMessage(h=h("uav0").next(), to="uav1",
                  round=3, kind="intent", body={"target": "L2", "eta_s": 4.5},
                  sender_pos=(1.0, 2.0, -5.0))),
        "perception": ("world", K.sim_perception("uav0"), SimPerception(h=h("world").next(),
                       uav="uav0", episode=0, round=3, deadline_s=30.0, pos=(1.0, 2.0, -5.0),
                       vel=(0.0, 0.0, 0.0), entities=ents)),
        "command": ("uav0", K.sim_command("uav0"), SimCommand(h=h("uav0").next(), uav="uav0",
                    episode=0, round=3, vel=(3.0, 1.0, 0.0))),
        "experience": ("uav0", K.experience("uav0"), ExperienceRecord(h=h("uav0").next(),
                       task="coverage", role="searcher", uav="uav0", episode=0, round=3,
                       state_text="own (1,2); L2 at 12 m NE; uav1 at 30 m E; " * 4,
                       skill="cover_landmark", invocation="cover_landmark(target_id=L2)",
                       reward=-0.4, ret=-2.1, final=True, reward_source="sim")),
    }  # fmt: skip


def bench_crypto(pki: SwarmPki, n: int) -> dict[str, dict[str, float]]:
    codec = Codec()
    verifier = Verifier(pki.identities)
    signers = {
        name: Signer(name, load_signing_key(pki.paths(name).sign_key)) for name in ("uav0", "world")
    }
    out: dict[str, dict[str, float]] = {}
    for kind, (author, key, msg) in _payloads().items():
        data = codec.encode(msg)
        s = signers[author]
        att = s.sign(key, data)
        assert verifier.check(key, data, att, author) is None
        kind_t = type(msg)

        def sign_once(s: Signer = s, key: str = key, data: bytes = data) -> object:
            return s.sign(key, data)

        def verify_once(
            key: str = key, data: bytes = data, att: bytes = att, a: str = author
        ) -> object:
            return verifier.check(key, data, att, a)

        def decode_once(
            key: str = key, data: bytes = data, t: type[msgspec.Struct] = kind_t
        ) -> object:
            return codec.decode(data, t, key)

        sign = _per_call(sign_once, n)
        verify = _per_call(verify_once, n)
        decode = _per_call(decode_once, n)
        out[kind] = {
            "bytes": len(data),
            "sign_us": round(sign * 1e6, 1),
            "verify_us": round(verify * 1e6, 1),
            "decode_us": round(decode * 1e6, 1),
        }
    return out


def per_round(crypto: dict[str, dict[str, float]], uavs: int, messages: int) -> dict[str, float]:
    """Signature CPU per lockstep round for the whole swarm (sign once, verify per receiver).

    Per UAV and round, as a simulated run sends them: one beacon (signed; in simulation no
    peer follows beacons, so nobody verifies it), one command (the world verifies it), one
    report (the Commander), ``messages`` broadcasts (each verified by the N-1 peers); the
    world signs a perception and a reward per UAV, which that UAV verifies. Experience
    records are per episode, not per round."""
    c = crypto
    n = uavs
    sign = n * (
        c["beacon"]["sign_us"] + 2 * c["command"]["sign_us"] + messages * c["inbox"]["sign_us"]
    )
    sign += 2 * n * c["perception"]["sign_us"]  # world: perception + reward
    verify = n * messages * (n - 1) * c["inbox"]["verify_us"]
    verify += n * (2 * c["command"]["verify_us"] + 2 * c["perception"]["verify_us"])
    return {
        "uavs": n,
        "messages_per_uav": messages,
        "signatures": n * (3 + messages) + 2 * n,
        "verifications": n * messages * (n - 1) + 4 * n,
        "swarm_cpu_ms": round((sign + verify) / 1e3, 2),
    }


def _per_call(fn: Callable[[], object], n: int) -> float:
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter() - t0) / n)
    return best


def _ms(xs: list[float]) -> dict[str, float]:
    ys = sorted(xs)
    return {"median_ms": round(statistics.median(ys) * 1e3, 2), "max_ms": round(ys[-1] * 1e3, 2)}


def _us(xs: list[float]) -> dict[str, float]:
    ys = sorted(xs)
    return {
        "median_us": round(statistics.median(ys) * 1e6, 1),
        "p95_us": round(ys[int(0.95 * (len(ys) - 1))] * 1e6, 1),
    }


def bench_pki(repeats: int) -> dict[str, dict[str, float]]:
    out = {}
    for n in (3, 10):
        times = []
        for _ in range(repeats):
            with tempfile.TemporaryDirectory() as d:
                t0 = time.perf_counter()
                SwarmPki.create(Path(d), SWARM, default_members(n))
                times.append(time.perf_counter() - t0)
        out[f"{n}_uavs"] = _ms(times)
    return out


async def bench_runs(
    sizes: Sequence[int], rounds: int, seed: int, task: str, repeats: int
) -> list[dict[str, Any]]:
    """Secured vs insecure whole runs, alternating so load drifts hit both alike."""
    from aeroweaver_edge.orchestration.swarm import SwarmOptions, run_swarm

    out = []
    for n in sizes:
        walls: dict[str, list[float]] = {"secured": [], "insecure": []}
        rounds_wall: dict[str, list[float]] = {"secured": [], "insecure": []}
        returns: dict[str, set[str]] = {"secured": set(), "insecure": set()}
        sent: list[float] = []
        for _ in range(repeats):
            for mode in ("insecure", "secured"):
                opts = SwarmOptions(task=task, uavs=n, seed=seed, max_rounds=rounds,
                                    selector="scripted", deadline_s=30.0,
                                    secure=mode == "secured")  # fmt: skip
                summary = await run_swarm(opts)
                walls[mode].append(summary.wall_s)
                rounds_wall[mode].extend(summary.round_wall_s)
                data = summary.as_dict()
                returns[mode].add(json.dumps(data["agent_returns"], sort_keys=True))
                sent.append(data["messages_sent"] / max(1, data["rounds"] * n))
        row: dict[str, Any] = {"uavs": n, "task": task, "rounds": rounds, "repeats": repeats}
        row["messages_per_uav_round"] = round(statistics.mean(sent), 2)
        for mode in ("insecure", "secured"):
            row[mode] = {
                "round_ms": _ms(rounds_wall[mode]) | {"p95_ms": _p95_ms(rounds_wall[mode])},
                "run_s": round(statistics.median(walls[mode]), 3),
            }
        row["round_overhead_ms"] = round(
            row["secured"]["round_ms"]["median_ms"] - row["insecure"]["round_ms"]["median_ms"], 2
        )
        row["same_returns"] = len(returns["secured"] | returns["insecure"]) == 1
        out.append(row)
    return out


def _p95_ms(xs: list[float]) -> float:
    ys = sorted(xs)
    return round(ys[int(0.95 * (len(ys) - 1))] * 1e3, 2)


async def run(
    rtt_n: int,
    open_n: int,
    crypto_n: int,
    runs: Sequence[int] = (),
    rounds: int = 24,
    seed: int = 1,
    task: str = "coverage",
    repeats: int = 2,
) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as d:
        pki = SwarmPki.create(Path(d), SWARM, default_members(2))
        crypto = bench_crypto(pki, crypto_n)
        out: dict[str, Any] = {
            "pki": bench_pki(max(3, open_n // 2)),
            "open": await bench_open(pki, open_n),
            "rtt": await bench_rtt(pki, rtt_n),
            "crypto": crypto,
            "per_round": [per_round(crypto, n, m) for n, m in ((3, 2), (10, 4))],
        }
    if runs:
        out["runs"] = await bench_runs(runs, rounds, seed, task, repeats)
        # The estimate for the traffic those runs really had, next to their measured cost.
        for row in out["runs"]:
            est = per_round(crypto, row["uavs"], max(1, round(row["messages_per_uav_round"])))
            row["signature_cpu_estimate_ms"] = est["swarm_cpu_ms"]
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m aeroweaver_lab.bench.security",
                                description=__doc__.split("\n\n")[0])  # fmt: skip
    p.add_argument("--rtt", type=int, default=1000, help="timed round trips per mode")
    p.add_argument("--opens", type=int, default=10, help="session opens per mode")
    p.add_argument("--crypto", type=int, default=2000, help="sign/verify calls per payload")
    p.add_argument("--runs", type=int, nargs="*", default=[], help="whole runs at these sizes")
    p.add_argument("--rounds", type=int, default=24, help="runs: rounds per run")
    p.add_argument("--seed", type=int, default=1, help="runs: layout seed")
    p.add_argument("--task", default="coverage", help="runs: task")
    p.add_argument("--repeats", type=int, default=2, help="runs: runs per mode and size")
    args = p.parse_args(argv)
    out = asyncio.run(
        run(args.rtt, args.opens, args.crypto, args.runs, args.rounds, args.seed, args.task,
            args.repeats)
    )  # fmt: skip
    print(json.dumps(out, indent=1))
    return 0 if all(r["same_returns"] for r in out.get("runs", [])) else 1


if __name__ == "__main__":
    raise SystemExit(main())
