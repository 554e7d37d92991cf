"""N emulated autopilots on UDP, ticking on the event loop, flying one kinematic world.

Port convention (PX4 SITL's): vehicle i is system id ``sysid_base + i``, sends from local
port ``local_base + i`` to ``port_base + i`` (where the companion / our daemon listens,
``udpin://0.0.0.0:14540+i``) and answers every address it hears valid MAVLink from, so a
``udpout`` client, QGroundControl (``gcs_port``, usually 14550) or MAVProxy can connect.

Free-running, the host steps the world on the wall clock (times ``time_scale``). Attached
to a lockstep runner (:meth:`attach`), the runner steps the world and the host only runs
protocol, vertical motion and timers.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

from aeroweaver_edge.contracts.endpoints import UdpUrl
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_edge.sim.emulator.autopilot import EmulatedAutopilot, Faults
from aeroweaver_edge.vehicle.mavlink.geo import DEFAULT_ORIGIN, GeoOrigin
from aeroweaver_edge.vehicle.mavlink.personality import personality as make_personality
from aeroweaver_edge.vehicle.mavlink.udp import Addr, UdpEndpoint
from aeroweaver_edge.world.kinematics import KinematicWorld

log = logging.getLogger(__name__)
TICK_S = 0.01
MAX_PEERS = 8


@dataclass
class EmulatorOptions:
    uavs: int = 1
    personality: str = "px4"
    port_base: int = 14540  # where vehicle i sends: port_base + i
    local_base: int | None = None  # where vehicle i listens; None: port_base + 40 (PX4 SITL)
    host: str = "127.0.0.1"
    sysid_base: int = 1
    time_scale: float = 1.0
    gcs_port: int | None = None  # also send to HOST:gcs_port (QGroundControl listens on 14550)
    params: dict[str, float] = field(default_factory=dict)
    signing_keys: Sequence[bytes | None] = ()  # per vehicle; a key makes signing mandatory
    spacing_m: float = 5.0  # standalone layout: a row along east
    origin: GeoOrigin = DEFAULT_ORIGIN
    seed: int = 0
    prearm_s: float = 0.0  # ArduPilot: arming checks fail this long after boot (EKF, GPS)
    remote_ports: Sequence[int] | None = None  # override port_base + i per vehicle (tests)

    def __post_init__(self) -> None:
        if not 1 <= self.uavs <= 250:
            raise ValueError(f"uavs must be 1..250, got {self.uavs}")
        if not self.time_scale > 0:
            raise ValueError(f"time_scale must be > 0, got {self.time_scale}")
        make_personality(self.personality)
        top = self.port_base + self.uavs - 1
        if not self.port_base >= 1 or top > 65535:
            raise ValueError(f"ports {self.port_base}..{top} are not valid UDP ports")


def uav_id(i: int) -> str:
    return f"uav{i}"


class EmulatorHost:
    def __init__(
        self,
        opts: EmulatorOptions,
        world: KinematicWorld | None = None,
        uav_ids: Sequence[str] | None = None,
        faults: Sequence[Faults] | None = None,
    ) -> None:
        self.opts = opts
        ids = list(uav_ids) if uav_ids is not None else [uav_id(i) for i in range(opts.uavs)]
        if len(ids) != opts.uavs:
            raise ValueError(f"{len(ids)} uav ids for {opts.uavs} vehicles")
        if world is None:
            world = KinematicWorld()
            for i, u in enumerate(ids):
                world.add_uav(u, (0.0, i * opts.spacing_m))
        self.world = world
        self.free_running = True
        self.ids = ids
        pers = make_personality(opts.personality)
        self.vehicles: list[EmulatedAutopilot] = []
        self._eps: list[UdpEndpoint | None] = [None] * opts.uavs
        self._peers: list[list[Addr]] = [[] for _ in range(opts.uavs)]
        self._fixed: list[list[Addr]] = []
        for i, u in enumerate(ids):
            key = opts.signing_keys[i] if i < len(opts.signing_keys) else None
            remote = opts.remote_ports[i] if opts.remote_ports is not None else opts.port_base + i
            fixed = [(opts.host, remote)]
            if opts.gcs_port is not None:
                fixed.append((opts.host, opts.gcs_port))
            self._fixed.append(fixed)
            self.vehicles.append(
                EmulatedAutopilot(
                    sysid=opts.sysid_base + i,
                    uav=u,
                    personality=pers,
                    world=lambda: self.world,
                    transmit=functools.partial(self._transmit, i),
                    origin=opts.origin,
                    time_scale=opts.time_scale,
                    params=opts.params,
                    signing_key=key,
                    faults=faults[i] if faults is not None and i < len(faults) else None,
                    seed=opts.seed,
                    prearm_s=opts.prearm_s,
                )
            )
        self._tasks: list[asyncio.Task[None]] = []
        self.ticks = 0
        self.max_tick_gap_s = 0.0

    # -- lifecycle ------------------------------------------------------------------------

    async def start(self) -> None:
        local_base = self.opts.local_base
        if local_base is None:
            local_base = self.opts.port_base + 40
        for i in range(self.opts.uavs):
            port = 0 if local_base == 0 else local_base + i
            url = UdpUrl("udpin", self.opts.host, port)
            self._eps[i] = await UdpEndpoint.open(url, functools.partial(self._on_datagram, i))
        for v in self.vehicles:
            v.send_heartbeat()
        self._tasks = [asyncio.create_task(self._run(), name="emulator-tick")]

    async def aclose(self) -> None:
        await cancel_all(self._tasks)
        for ep in self._eps:
            if ep is not None:
                ep.close()
        self._eps = [None] * self.opts.uavs

    async def __aenter__(self) -> EmulatorHost:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.aclose()

    def local_port(self, i: int) -> int:
        ep = self._eps[i]
        return ep.local_port if ep is not None else 0

    # -- world binding (lockstep) ----------------------------------------------------------

    def attach(self, world: KinematicWorld) -> None:
        """A runner owns the physics from now on: it steps ``world``; vehicles fly in it."""
        missing = [u for u in self.ids if u not in world.uav_ids]
        if missing:
            raise ValueError(f"world has no body for {missing}")
        self.world = world
        self.free_running = False

    def detach(self) -> None:
        """The runner is done: the host steps the (last) world on the wall clock again."""
        self.free_running = True

    def retarget(self, i: int, port: int) -> None:
        """Send vehicle ``i``'s traffic to ``port`` (where its companion now listens)."""
        self._fixed[i][0] = (self.opts.host, port)

    def vehicle(self, uav: str) -> EmulatedAutopilot:
        return self.vehicles[self.ids.index(uav)]

    # -- I/O ---------------------------------------------------------------------------------

    def _on_datagram(self, i: int, data: bytes, addr: Addr) -> None:
        if self.vehicles[i].receive(data):
            peers = self._peers[i]
            if addr not in peers and addr not in self._fixed[i]:
                if len(peers) >= MAX_PEERS:
                    peers.pop(0)
                peers.append(addr)

    def _transmit(self, i: int, data: bytes) -> None:
        ep = self._eps[i]
        if ep is None:
            return
        for addr in (*self._fixed[i], *self._peers[i]):
            ep.send(data, addr)

    async def _run(self) -> None:
        last = time.monotonic()
        while True:
            await asyncio.sleep(TICK_S)
            now = time.monotonic()
            gap = now - last
            self.max_tick_gap_s = max(self.max_tick_gap_s, gap)
            if self.free_running:
                with contextlib.suppress(ValueError):
                    self.world.step(gap * self.opts.time_scale)
            for v in self.vehicles:
                try:
                    v.tick(now)
                except Exception:  # one vehicle's bug must not stop the others
                    log.exception("emulated %s: tick failed", v.uav)
            self.ticks += 1
            last = now
