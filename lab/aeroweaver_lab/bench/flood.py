"""Flood benchmark: what one enrolled but compromised UAV can do to a secured swarm's
availability (issue 22).

``python -m aeroweaver_lab.bench.flood`` (or ``aeroweaver bench flood``) runs a secured
``sim --processes`` swarm (scripted selector) untouched, then once per flood with an
attacker process flooding from its own enrolled identity (an extra UAV of the run's PKI,
``uav<N>``, with its own liveliness token, so it is in every roster):

- ``random_sig``: well-formed peer messages on its broadcast key with random signatures
  (free for the attacker, a verification for every receiver that does not refuse first);
- ``signed``: valid signed peer messages (every one signed afresh);
- ``unsigned``: peer messages without a signature;
- ``experience``: ``--records`` signed experience records in its own name, for the role the
  UAVs fly (their peers store them).

For every run it reports the wall time and its ratio to the untouched runs (one first, one
last, averaged), whether the
returns are the same, whether every process stayed alive (no UAV lost, every daemon's exit
code 0), the attacker's send rate, what the receivers refused (by cause), the peak RSS of
every daemon and the experience records each daemon stored per sender. Figures, not a
timed test: ``tests/aeroweaver_lab/bench/test_flood.py`` runs it at tiny scale and checks
the invariants. Exit status 1 if a flood broke an invariant or took more than ``--max-ratio``
times the untouched wall time.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import signal
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

ATTACKS = ("random_sig", "signed", "unsigned", "experience")
FAR = (1.0e4, 1.0e4, -5.0)  # the attacker claims to be far away: its messages reach nobody


@contextlib.contextmanager
def enrolled(extra: str, holder: dict[str, Any]) -> Iterator[None]:
    """Every run's throw-away PKI also enrols ``extra`` (the compromised UAV); the PKI is
    kept in ``holder["pki"]`` so the attacker can be given its files."""
    from aeroweaver_edge.orchestration import network
    from aeroweaver_edge.security.identity import SwarmPki

    original = getattr(network, "ephemeral_swarm")  # noqa: B009 - not re-exported

    def with_extra(root: Path, swarm: str, uav_ids: Sequence[str]) -> SwarmPki:
        pki: SwarmPki = original(root, swarm, [*uav_ids, extra])
        holder["pki"] = pki
        return pki

    setattr(network, "ephemeral_swarm", with_extra)  # noqa: B010
    try:
        yield
    finally:
        setattr(network, "ephemeral_swarm", original)  # noqa: B010


async def one_run(
    *,
    uavs: int,
    rounds: int,
    seed: int,
    task: str,
    attack: str | None,
    rate: float,
    records: int,
    role: str,
    workdir: Path,
) -> dict[str, Any]:
    """One secured ``--processes`` run, with ``attack`` flooding from the extra identity."""
    from aeroweaver_edge.agent.memory import tools as memory_tools
    from aeroweaver_edge.contracts.errors import RunFailed
    from aeroweaver_edge.orchestration.daemons import DaemonSet
    from aeroweaver_edge.orchestration.swarm import SwarmHandle, SwarmOptions, run_swarm
    from aeroweaver_edge.sim.runner import RoundLog

    attacker = f"uav{uavs}"
    holder: dict[str, Any] = {}
    daemons: dict[str, DaemonSet] = {}
    procs: list[asyncio.subprocess.Process] = []
    memory_dir = workdir / f"memory-{attack or 'untouched'}"
    opts = SwarmOptions(task=task, uavs=uavs, seed=seed, max_rounds=rounds, processes=True,
                        selector="scripted", deadline_s=30.0, memory_dir=memory_dir,
                        measure_rss=True)  # fmt: skip

    async def on_started(handle: SwarmHandle) -> None:
        if attack is None:
            return
        cfg = handle.mesh_for("uav0").model_copy(
            update={"security": holder["pki"].security_for(attacker)}
        )
        path = workdir / f"{attacker}-{attack}.json"
        path.write_text(cfg.model_dump_json())
        argv = ["-m", "aeroweaver_lab.bench.flood", "--attacker", attack, "--config", str(path),
                "--swarm", handle.swarm, "--name", attacker, "--rate", str(rate),
                "--records", str(records), "--role", role, "--task", task]  # fmt: skip
        procs.append(
            await asyncio.create_subprocess_exec(
                sys.executable,
                *argv,
                stdin=asyncio.subprocess.PIPE,
                stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.DEVNULL,
            )
        )

    async def fault(_log: RoundLog, ds: DaemonSet) -> None:
        """After the first round: the swarm flies, so the flood starts now."""
        if "set" not in daemons and procs and procs[0].stdin is not None:
            procs[0].stdin.write(b"go\n")
            with contextlib.suppress(ConnectionError):
                await procs[0].stdin.drain()
        daemons["set"] = ds

    row: dict[str, Any] = {"attack": attack or "untouched"}
    started = time.monotonic()
    try:
        with enrolled(attacker, holder):
            summary = await run_swarm(opts, on_started=on_started, fault=fault)
        data = summary.as_dict()
        row["completed"] = True
        row["wall_s"] = round(summary.wall_s, 3)
        row["returns"] = data["agent_returns"]
        row["lost_uavs"] = data["lost_uavs"]
        row["peak_rss_mb"] = {u: round(kb / 1024, 1) for u, kb in summary.peak_rss_kb.items()}
        row["refused"] = dict(data["security"].get("rejected", {}))
        row["roles"] = dict(data.get("roles", {}))
    except RunFailed as exc:
        row["completed"] = False
        row["wall_s"] = round(time.monotonic() - started, 3)
        row["error"] = str(exc).splitlines()[0][:300]
    finally:
        row["attacker"] = await _stop_attacker(procs)
    ds = daemons.get("set")
    row["exit_codes"] = {u: p.returncode for u, p in ds.procs.items()} if ds else {}
    row["alive"] = bool(
        row["completed"]
        and not row.get("lost_uavs")
        and row["exit_codes"]
        and all(code == 0 for code in row["exit_codes"].values())
    )
    stats = memory_tools.stats(memory_tools.memory_files(memory_dir))
    row["stored_by_sender"] = {
        Path(f["path"]).stem: {who: c["records"] for who, c in f["by_sender"].items()}
        for f in stats["files"]
    }
    return row


async def _stop_attacker(procs: list[asyncio.subprocess.Process]) -> dict[str, Any]:
    """SIGTERM the attacker; it prints what it sent. Killed if it does not stop."""
    if not procs:
        return {}
    proc = procs[0]
    if proc.stdin is not None:
        proc.stdin.close()  # an attacker still waiting for "go" reads EOF
    if proc.returncode is None:
        proc.send_signal(signal.SIGTERM)
    try:
        async with asyncio.timeout(15.0):
            out, _ = await proc.communicate()
    except TimeoutError:
        proc.kill()
        out, _ = await proc.communicate()
    try:
        report: dict[str, Any] = json.loads(out.decode().strip().splitlines()[-1])
    except (ValueError, IndexError):
        report = {}
    report["exit_code"] = proc.returncode
    return report


async def bench(
    *,
    uavs: int,
    rounds: int,
    seed: int,
    task: str,
    attacks: Sequence[str],
    rate: float,
    records: int,
    max_ratio: float,
) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="aw-flood-") as tmp:
        work = Path(tmp)
        common = {"uavs": uavs, "rounds": rounds, "seed": seed, "task": task, "rate": rate,
                  "records": records, "workdir": work}  # fmt: skip
        base = await one_run(attack=None, role="", **common)  # type: ignore[arg-type]
        role = _role_of(base)
        rows = [base]
        for attack in attacks:
            rows.append(await one_run(attack=attack, role=role, **common))  # type: ignore[arg-type]
        # Untouched again at the end: load drifts on a shared machine hit both references.
        rows.append(await one_run(attack=None, role="", **common))  # type: ignore[arg-type]
    bases = [rows[0], rows[-1]]
    reference = sum(b["wall_s"] for b in bases) / len(bases)
    for row in rows[1:-1]:
        row["wall_ratio"] = round(row["wall_s"] / reference, 2) if reference else None
        row["same_returns"] = all(row.get("returns") == b.get("returns") for b in bases)
        row["whole"] = bool(
            row["same_returns"]
            and row["alive"]
            and row["wall_ratio"] is not None
            and row["wall_ratio"] <= max_ratio
        )
    return {
        "uavs": uavs,
        "rounds": rounds,
        "seed": seed,
        "task": task,
        "rate_per_s": rate,
        "records": records,
        "max_ratio": max_ratio,
        "untouched_wall_s": round(reference, 3),
        "untouched_same_returns": bases[0].get("returns") == bases[1].get("returns"),
        "runs": rows,
    }


def _role_of(base: dict[str, Any]) -> str:
    """The role uav0 flew untouched (the attacker's records claim it, so peers take them)."""
    return str(base.get("roles", {}).get("uav0", "agent"))


# -- the attacker process ---------------------------------------------------------------


async def attack_main(args: argparse.Namespace) -> dict[str, Any]:
    """Flood from the compromised identity from "go" on stdin until SIGTERM; returns what
    was sent and at what rate."""
    import msgspec

    from aeroweaver_edge.config import MeshConfig
    from aeroweaver_edge.contracts.wire import ExperienceRecord, HeaderFactory, InboxMessage, Keys
    from aeroweaver_edge.mesh.session import Mesh
    from aeroweaver_edge.security.signing import VERSION

    text = await asyncio.to_thread(Path(args.config).read_text)
    cfg = MeshConfig.model_validate_json(text)
    keys = Keys(args.swarm)
    mesh = await Mesh.open(cfg, node_id=args.name)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGTERM, stop.set)
    headers = HeaderFactory(args.name)
    sent = 0
    started = time.monotonic()
    auth = mesh.security.auth if mesh.security is not None else None
    kid = b"\0" * 8
    if auth is not None and auth.signer is not None:
        kid = auth.signer._key_id
    try:
        mesh.declare_token(keys.alive_uav(args.name))  # it joins every roster
        # The benchmark says "go" once the swarm flies its first round (or closes stdin).
        go = asyncio.ensure_future(asyncio.to_thread(sys.stdin.readline))
        halt = asyncio.ensure_future(stop.wait())
        await asyncio.wait({go, halt}, return_when=asyncio.FIRST_COMPLETED)
        halt.cancel()
        started = time.monotonic()
        key = keys.broadcast(args.name)
        session = mesh.session
        step = max(1, int(args.rate / 100))  # puts per 10 ms tick
        while not stop.is_set():
            tick = time.monotonic()
            for _ in range(step):
                if args.attacker == "experience":
                    if sent >= args.records:
                        break
                    rec = ExperienceRecord(
                        h=headers.next(), task=args.task, role=args.role, uav=args.name,
                        episode=0, round=sent, state_text=f"attacker state {sent} " * 8,
                        skill="hold_position", invocation="hold_position()", reward=100.0,
                        ret=1000.0, final=True, run=f"evil-{sent // 1000}",
                    )  # fmt: skip
                    mesh.put(keys.experience(args.name), rec)
                else:
                    msg = InboxMessage(h=headers.next(), to="*", round=0, kind="status",
                                       body={"flood": sent}, sender_pos=FAR)  # fmt: skip
                    if args.attacker == "signed":
                        mesh.put(key, msg)
                    else:
                        data = msgspec.msgpack.encode(msg)
                        if args.attacker == "random_sig":
                            att = bytes((VERSION,)) + kid + os.urandom(64)
                            session.put(key, data, attachment=att)
                        else:
                            session.put(key, data)
                sent += 1
            await asyncio.sleep(max(0.0, 0.01 - (time.monotonic() - tick)))
    finally:
        elapsed = time.monotonic() - started
        await mesh.aclose()
    return {"sent": sent, "rate_per_s": round(sent / elapsed, 1) if elapsed else 0.0}


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m aeroweaver_lab.bench.flood",
                                description=__doc__.split("\n\n")[0])  # fmt: skip
    p.add_argument("--uavs", type=int, default=3, help="UAVs flying (default 3)")
    p.add_argument("--rounds", type=int, default=24, help="rounds per run (default 24)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--task", default="coverage")
    p.add_argument("--attacks", nargs="+", choices=ATTACKS, default=list(ATTACKS))
    p.add_argument("--rate", type=float, default=5000.0, help="attacker messages per second")
    p.add_argument("--records", type=int, default=30_000, help="experience: records sent")
    p.add_argument("--max-ratio", type=float, default=2.0, help="wall-time ratio allowed")
    # the attacker process (started by the benchmark itself)
    p.add_argument("--attacker", choices=ATTACKS, help=argparse.SUPPRESS)
    p.add_argument("--config", help=argparse.SUPPRESS)
    p.add_argument("--swarm", default="sim", help=argparse.SUPPRESS)
    p.add_argument("--name", help=argparse.SUPPRESS)
    p.add_argument("--role", default="", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.attacker:
        print(json.dumps(asyncio.run(attack_main(args))), flush=True)
        return 0
    out = asyncio.run(
        bench(uavs=args.uavs, rounds=args.rounds, seed=args.seed, task=args.task,
              attacks=args.attacks, rate=args.rate, records=args.records,
              max_ratio=args.max_ratio)
    )  # fmt: skip
    print(json.dumps(out, indent=1))
    return 0 if all(r["whole"] for r in out["runs"][1:-1]) else 1


if __name__ == "__main__":
    raise SystemExit(main())
