"""Assembles one daemon from its config: mesh, backends for each port, selector, memory.

Used both by ``aeroweaver daemon --config`` (one process per UAV) and by the simulated
swarm (several daemons in one event loop, each with its own Zenoh session).

With ``[mesh.security]`` the header epoch is the identity's persisted boot counter (so a
restart is recognised without the wall clock, and a forged leap is bounded) and the peer
link admits only the swarm's UAV identities, with beacons held to the safety envelope.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass

from aeroweaver_edge.config import UavConfig
from aeroweaver_edge.contracts.ports import DaemonPorts, Selector
from aeroweaver_edge.contracts.wire import HeaderFactory, Keys
from aeroweaver_edge.daemon.decision_round import RoundOutcome
from aeroweaver_edge.daemon.uav_daemon import DaemonStats, UavDaemon
from aeroweaver_edge.mesh.presence import TokenWatch, run_unless_lost
from aeroweaver_edge.mesh.secured import boot_headers, peer_limits
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.runtime import plugins
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_edge.skills import SkillRegistry, load_skills

log = logging.getLogger(__name__)


SelectorFactory = Callable[
    [UavConfig, Mesh, HeaderFactory], contextlib.AbstractAsyncContextManager[Selector]
]
"""An extension's selector (entry point group ``aeroweaver.selectors``): opened with the
daemon's config, mesh session and signed headers, closed with the daemon."""


@dataclass(frozen=True)
class SelectorInfo:
    name: str
    model: str | None = None
    probe: str | None = None  # the endpoint probe's one-line verdict


@contextlib.asynccontextmanager
async def open_selector(
    cfg: UavConfig,
    agent_name: str,
    *,
    mesh: Mesh | None = None,
    headers: HeaderFactory | None = None,
) -> AsyncIterator[tuple[Selector, SelectorInfo]]:
    """The selector named in config; an LLM endpoint is probed once before use. Any other
    name is an extension's (``runtime.plugins``: the lab's baselines ask their central node
    over ``mesh``)."""
    if cfg.agent.selector not in ("llm", "scripted"):
        factory: SelectorFactory = plugins.load(plugins.SELECTORS, cfg.agent.selector)
        if mesh is None or headers is None:
            raise ValueError(f"the {cfg.agent.selector} selector needs the daemon's mesh")
        async with factory(cfg, mesh, headers) as remote:
            yield remote, SelectorInfo(remote.name, cfg.llm.model)
        return
    if cfg.agent.selector == "scripted":
        from aeroweaver_edge.agent.scripted import scorer_for

        scorer = scorer_for(cfg.agent.scripted_base)  # the reference, or a degraded base
        yield scorer, SelectorInfo(scorer.name)
        return
    from aeroweaver_edge.agent.llm_selector import LLMSelector
    from aeroweaver_edge.llm.client import ChatClient
    from aeroweaver_edge.llm.embedded import EmbeddedServer
    from aeroweaver_edge.llm.probe import probe_endpoint

    async with contextlib.AsyncExitStack() as stack:
        llm = cfg.llm
        if llm.base_url is None:
            server = await stack.enter_async_context(EmbeddedServer())
            llm = llm.model_copy(update={"base_url": server.base_url, "model": server.model})
        client = await stack.enter_async_context(ChatClient.from_config(llm))
        probe = await probe_endpoint(client)
        log.info("%s: LLM endpoint %s: %s", agent_name, client.endpoint, probe.summary())
        selector = LLMSelector(client, llm, probe, agent=agent_name)
        try:
            yield selector, SelectorInfo(f"llm:{llm.model}", llm.model, probe.summary())
        finally:
            await selector.aclose()


def _ports(
    cfg: UavConfig, mesh: Mesh, headers: HeaderFactory
) -> tuple[DaemonPorts, Callable[[], Awaitable[None]], Callable[[], Awaitable[None]]]:
    if cfg.vehicle.backend == "sim":
        from aeroweaver_edge.vehicle.sim import SimLink

        link = SimLink(mesh, Keys(cfg.swarm), cfg.uav, headers)
        return DaemonPorts(link, link, link, link), link.start, link.aclose
    # flight: a real link (mavlink / mavsdk), in the field or against the simulated world.
    from aeroweaver_edge.vehicle.flight_ports import flight_ports

    return flight_ports(cfg, mesh, headers)


def _vehicle_line(cfg: UavConfig) -> str:
    v = cfg.vehicle
    if v.backend == "sim":
        return "sim (flies in a simulated world: `mission start --sim-world` runs one)"
    where = f"{v.backend} {v.url}"
    return f"{where} in a simulated world" if v.sim_world else where


async def world_guard(world: TokenWatch, grace_s: float, daemon: UavDaemon) -> None:
    """A service daemon's watch on the simulated world: hold as soon as its token goes;
    if it is not back within ``grace_s``, that world is over (``end_world``: the daemon
    lands and waits for the next one). Never stops the daemon."""
    clock = daemon.ports.clock
    end_world = getattr(clock, "end_world", None)
    who = daemon.uav
    while True:
        await world.wait_up()
        log.info("%s: the simulated world is up", who)
        await world.wait_gone()
        gone_at = world.gone_at or time.monotonic()
        if getattr(clock, "world_over", False):  # it ended (or never flew us): not a loss
            log.info("%s: the simulated world closed", who)
            continue
        if daemon.phases.flying:
            log.warning("%s: the simulated world went away mid-flight; holding", who)
        with contextlib.suppress(Exception):
            await daemon.phases.hold()
        if await world.wait_back(grace_s - (time.monotonic() - gone_at)):
            log.warning("%s: the simulated world is back within %g s; carrying on", who, grace_s)
            continue
        log.info("%s: the simulated world is gone; its mission is over", who)
        if end_world is not None:
            end_world()


async def run_daemon(
    cfg: UavConfig,
    *,
    registry: SkillRegistry | None = None,
    selector: Selector | None = None,
    on_round: Callable[[RoundOutcome], Awaitable[None]] | None = None,
    on_ready: Callable[[UavDaemon], None] | None = None,
    service: bool = False,
) -> DaemonStats:
    """Run one daemon until its clock ends the run. Every resource is closed on the way out.

    ``service`` (``aeroweaver daemon``): never end by itself. A simulated world that ends
    or goes away for good is not a failure: the daemon lands, waits for the next world and
    flies the next mission. Without it (the daemons a simulated run starts), the world's
    end is the daemon's end, and a world lost for ``vehicle.world_grace_s`` stops it."""
    registry = registry or load_skills()
    async with contextlib.AsyncExitStack() as stack:
        mesh = await Mesh.open(cfg.mesh, node_id=cfg.uav)
        stack.push_async_callback(mesh.aclose)
        headers = await asyncio.to_thread(boot_headers, cfg.mesh, cfg.uav)
        identities = mesh.security.identities if mesh.security is not None else None
        ports, start, stop = _ports(cfg, mesh, headers)
        await start()
        stack.push_async_callback(stop)
        chooser = str(getattr(selector, "name", type(selector).__name__))
        if selector is None:
            selector, info = await stack.enter_async_context(
                open_selector(cfg, cfg.uav, mesh=mesh, headers=headers)
            )
            chooser = info.name
        memory = None
        if cfg.agent.beta > 0 or cfg.agent.memory_path is not None:
            from aeroweaver_edge.agent.memory.async_memory import AsyncExperienceMemory

            memory = await AsyncExperienceMemory.from_config(cfg.agent)
            stack.push_async_callback(memory.aclose)
        log.info(
            "%s decides with %s; experience correction beta %g, estimator %s",
            cfg.uav, chooser, cfg.agent.beta, cfg.agent.estimator,
        )  # fmt: skip
        assert selector is not None
        daemon = UavDaemon(
            cfg,
            mesh=mesh,
            ports=ports,
            selector=selector,
            registry=registry,
            headers=headers,
            memory=memory,
            uav_index=cfg.uav_index,
            altitude_m=cfg.vehicle.altitude_m,
            round_s=cfg.round_s,
            on_round=on_round,
            peer_limits=peer_limits(identities, cfg.safety, cfg.round_s),
        )
        attach = getattr(ports.perception, "attach", None)
        if attach is not None:  # field perception: peers come from the daemon's beacons
            attach(lambda: daemon.neighbours)
        log.info(
            "%s up: swarm %s, vehicle %s, selector %s; waiting for a mission",
            cfg.uav, cfg.swarm, _vehicle_line(cfg), cfg.agent.selector,
        )  # fmt: skip
        if on_ready is not None:
            on_ready(daemon)
        if not (cfg.vehicle.backend == "sim" or cfg.vehicle.sim_world):
            return await daemon.run(service=service)  # never stops for a lost party
        # Flying in the simulated world: hold when it goes, stop if it stays gone.
        world = TokenWatch(mesh, Keys(cfg.swarm).alive_world)
        world.start()
        stack.push_async_callback(world.aclose)
        if service:
            guard = asyncio.create_task(
                world_guard(world, cfg.vehicle.world_grace_s, daemon), name=f"{cfg.uav}-world"
            )
            try:
                return await daemon.run(service=True)
            finally:
                await cancel_all([guard])
        return await run_unless_lost(
            daemon.run(), world, cfg.vehicle.world_grace_s, hold=daemon.phases.hold, who=cfg.uav
        )
    raise AssertionError("unreachable")  # pragma: no cover
