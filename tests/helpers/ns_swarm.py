"""A simulated swarm whose daemons live in other network namespaces (``netlab``): the world
(a zenoh router) and the Commander in the test process, one ``aeroweaver daemon`` process per
UAV inside its segment's namespace, dialling the router across that segment's link. The
same wiring as ``orchestration/swarm.py``, with the links made cuttable and lossy."""

from __future__ import annotations

import asyncio
import contextlib
import os
import subprocess
import sys
import time
import uuid
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path

from aeroweaver_edge.config import (
    AgentConfig,
    MeshConfig,
    SimConfig,
    UavConfig,
    VehicleConfig,
)
from aeroweaver_edge.contracts.wire import ProgressReport
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.orchestration.swarm import world_task
from aeroweaver_edge.runtime.run_dir import ENV_PARENT
from aeroweaver_edge.sim.episode import EpisodeResult
from aeroweaver_edge.sim.runner import RoundLog, WorldRunner
from commander.commander import Commander
from commander.harness import plan_for_task
from tests.helpers.netlab import Segment
from tests.helpers.zenoh_net import free_port

SWARM = "ns"


@dataclass
class NsRun:
    runner: WorldRunner
    commander: Commander
    procs: dict[str, subprocess.Popen[bytes]]
    logs: dict[str, Path]
    memory: dict[str, Path]
    run_id: str
    rounds: list[RoundLog] = field(default_factory=list)
    reports: list[ProgressReport] = field(default_factory=list)
    results: list[EpisodeResult] = field(default_factory=list)
    exit_codes: dict[str, int | None] = field(default_factory=dict)  # after the shutdown
    early_exits: dict[str, int | None] = field(default_factory=dict)  # died during the run

    def alive(self) -> set[str]:
        return set(self.runner.alive)

    def log(self, uav: str) -> str:
        return self.logs[uav].read_text(errors="replace")


async def wait_until(predicate: Callable[[], bool], timeout_s: float) -> bool:
    """Bounded wait on a condition the world's liveliness events change."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        await asyncio.sleep(0.05)
    return True


async def run_ns_swarm(
    placement: dict[str, Segment],
    workdir: Path,
    *,
    task: str,
    episodes: int,
    deadline_s: float,
    lease_ms: int = 10_000,
    world_grace_s: float = 10.0,
    max_rounds: int = 24,
    seed: int = 1,
    on_round: Callable[[RoundLog, NsRun], Awaitable[None]] | None = None,
) -> NsRun:
    uavs = sorted(placement)
    namespace, port = f"ns-{uuid.uuid4().hex[:8]}", free_port()
    hosts = sorted({seg.host_ip for seg in placement.values()})
    world_mesh = await Mesh.open(
        MeshConfig(
            mode="router", listen=[f"tcp/127.0.0.1:{port}", *(f"tcp/{h}:{port}" for h in hosts)],
            namespace=namespace, lease_ms=lease_ms, insecure=True,
        ),
        node_id="world",
    )  # fmt: skip
    stack = contextlib.AsyncExitStack()
    stack.push_async_callback(world_mesh.aclose)
    async with stack:
        cmdr_mesh = await Mesh.open(
            MeshConfig(mode="client", listen=[], connect=[f"tcp/127.0.0.1:{port}"],
                       namespace=namespace, lease_ms=lease_ms, insecure=True),
            node_id="cmdr",
        )  # fmt: skip
        stack.push_async_callback(cmdr_mesh.aclose)
        plan = plan_for_task(task, uavs, mission_id=f"{task}-ns")
        wtask = world_task(plan, max_rounds)
        cfg = SimConfig(
            task=plan.task, uavs=len(uavs), seed=seed, max_rounds=max_rounds, deadline_s=deadline_s
        )
        run_ref: list[NsRun] = []

        async def hook(log: RoundLog) -> None:
            run_ref[0].rounds.append(log)
            if on_round is not None:
                await on_round(log, run_ref[0])

        runner = WorldRunner(world_mesh, SWARM, wtask, cfg, on_round=hook)
        await runner.start()
        stack.push_async_callback(runner.aclose)
        commander = Commander(cmdr_mesh, SWARM)
        await commander.start()
        stack.push_async_callback(commander.aclose)
        run = NsRun(runner, commander, {}, {}, {}, run_id=f"ns-{uuid.uuid4().hex[:8]}")
        run_ref.append(run)
        commander.report_listeners.append(run.reports.append)
        for uav in uavs:
            seg = placement[uav]
            run.memory[uav] = workdir / f"{uav}.sqlite3"
            ucfg = UavConfig(
                uav=uav, swarm=SWARM,
                mesh=MeshConfig(mode="client", listen=[], connect=[f"tcp/{seg.host_ip}:{port}"],
                                namespace=namespace, lease_ms=lease_ms, insecure=True),
                agent=AgentConfig(selector="scripted", beta=0.8, memory_path=str(run.memory[uav]),
                                  run_id=run.run_id),
                vehicle=VehicleConfig(world_grace_s=world_grace_s),
            )  # fmt: skip
            path = workdir / f"{uav}.json"
            path.write_text(ucfg.model_dump_json(), encoding="utf-8")
            run.logs[uav] = workdir / f"{uav}.log"
            # Started by this run (as ``sim --processes`` starts them): each daemon ends with
            # the run's world and dies with this process. Without it a daemon is a service
            # that lands and waits for the next mission, and the run never ends.
            env = {**os.environ, ENV_PARENT: str(os.getpid())}
            with run.logs[uav].open("wb") as log:
                run.procs[uav] = subprocess.Popen(  # noqa: ASYNC220 - spawn only, no wait
                    [*seg.prefix(), sys.executable, "-m", "aeroweaver_edge", "daemon",
                     "--config", str(path)],
                    stdin=subprocess.DEVNULL, stdout=log, stderr=log, env=env,
                )  # fmt: skip
        try:
            missing = await runner.wait_alive(uavs, 120.0)
            assert not missing, f"not up: {missing}: {[run.log(u)[-500:] for u in missing]}"
            commander.publish(plan)
            missing = await commander.wait_ready(plan.participants, 120.0)
            assert not missing, f"not ready: {missing}"
            for ep in range(episodes):
                run.results.append(await runner.run_episode(ep))
            run.early_exits = {
                u: p.returncode for u, p in run.procs.items() if p.poll() is not None
            }
            runner.shutdown()
            for uav, proc in run.procs.items():
                with contextlib.suppress(subprocess.TimeoutExpired):
                    await asyncio.to_thread(proc.wait, 60)
                run.exit_codes[uav] = proc.returncode
        finally:
            for proc in run.procs.values():
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
        await asyncio.sleep(0.2)  # the last reports
    return run
