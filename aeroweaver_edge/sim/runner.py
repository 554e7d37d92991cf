"""The world side of a simulated swarm: lockstep rounds over Zenoh.

Each round the runner lets the task's own agents decide on the frozen state (the evader,
the foragers, the eavesdropper, the concealment adversary), sends every present UAV its
frozen perception (what it senses within its role's radius, its private facts, and the
messages that reach it from last round), waits for each UAV's command until the deadline
(the world stays frozen meanwhile), applies them (a missing or held command holds that UAV;
a guess is recorded by the task), advances 0.5 s, scores the round and sends the rewards. A
UAV whose liveliness token disappears is marked absent and holds until its token is back
(a restarted daemon rejoins at the next round). The world's own token tells daemons it lives.

Which messages reach whom is computed here with the task's routing rule on the positions of
the round they were sent, exactly as each receiver's inbox judges them, so every recipient
waits for precisely the messages it will accept. World-flown agents that listen (the
eavesdropper) get a listen-only peer link on the world's mesh.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import Counter, defaultdict
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np

from aeroweaver_edge.config import SafetyConfig, SimConfig
from aeroweaver_edge.contracts.defaults import COMM_RADIUS_M
from aeroweaver_edge.contracts.wire import (
    BROADCAST,
    Entity,
    HeaderFactory,
    InboxMessage,
    Keys,
    MsgRef,
    SimCommand,
    SimEpisode,
    SimPerception,
    SimReward,
    Vec3,
    WorldSnapshot,
    last_chunk,
)
from aeroweaver_edge.mesh.inbox import RADIO_DROPS
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_edge.sim.command_check import CommandCheck
from aeroweaver_edge.sim.envelope import EnvelopeCheck, Violation
from aeroweaver_edge.sim.episode import Episode, EpisodeResult, RoundResult
from aeroweaver_edge.tasks.base import TaskDefinition
from aeroweaver_edge.world.kinematics import KinematicWorld

if TYPE_CHECKING:
    from aeroweaver_edge.mesh.peers import PeerLink
    from aeroweaver_edge.mesh.session import Mesh
    from aeroweaver_edge.sim.emulator.bridge import EmulatorBridge

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RoundLog:
    episode: int
    round: int  # 0-based decision round
    result: RoundResult
    commands: dict[str, SimCommand]
    missed: tuple[str, ...]  # present UAVs whose command did not arrive in time
    absent: tuple[str, ...]
    wait_s: float
    deliveries: int = 0  # (message, recipient) pairs that reach, of this round's messages
    wall_s: float = 0.0  # the whole round in the world: perceptions to rewards
    # The world after the round (for traces and observers): every body, ours and the
    # world's opponents (kind "uav", with role), then the static entities.
    bodies: tuple[Entity, ...] = ()
    entities: tuple[Entity, ...] = ()
    refused: dict[str, int] = field(default_factory=dict)  # world-side refusals this round
    violations: tuple[Violation, ...] = ()  # envelope violations among the applied commands


@dataclass
class RunnerStats:
    commands: int = 0
    deadline_misses: int = 0
    rejected_commands: int = 0  # refused by the command check (by cause: WorldRunner.check)
    unknown_tokens: int = 0  # liveliness tokens of ids the world does not fly
    snapshots_dropped: int = 0  # round snapshots over the payload cap (observers miss them)
    lost: dict[str, tuple[int, int]] = field(default_factory=dict)  # uav -> (episode, round) lost
    rejoined: dict[str, int] = field(default_factory=dict)  # uav -> times it came back after lost


class WorldRunner:
    def __init__(
        self,
        mesh: Mesh,
        swarm: str,
        task: TaskDefinition,
        cfg: SimConfig,
        *,
        on_round: Callable[[RoundLog], Awaitable[None]] | None = None,
        comm_radius_m: float = COMM_RADIUS_M,
        vehicles: EmulatorBridge | None = None,
        headers: HeaderFactory | None = None,
        safety: SafetyConfig | None = None,
    ) -> None:
        self.mesh = mesh
        # The envelope invariant: every applied command is judged against the daemons'
        # envelope (default: the default one), independently of their safety gates.
        self.envelope = EnvelopeCheck(safety or SafetyConfig(), horizon_s=cfg.round_s)
        self.comm_radius_m = comm_radius_m
        # flight link (sim --link mavlink|mavsdk): emulated autopilots fly the bodies
        self.vehicles = vehicles
        self.keys = Keys(swarm)
        self.task = task
        self.cfg = cfg
        self.headers = headers or HeaderFactory("world")
        self.stats = RunnerStats()
        self.check = CommandCheck(self.keys, task.uav_ids)  # sim/command_check.py
        self.alive: set[str] = set()
        self._on_round = on_round
        self._commands: dict[tuple[int, int], dict[str, SimCommand]] = defaultdict(dict)
        self._changed = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._where: tuple[int, int] = (-1, -1)
        self._window: tuple[int, int] | None = None  # the round whose commands count now
        self._finished = False
        self._listeners: dict[str, PeerLink] = {}

    async def start(self) -> None:
        from aeroweaver_edge.mesh.peers import PeerLink

        for body in self.task.scripted_listeners:
            link = PeerLink(
                self.mesh,
                self.keys,
                body,
                HeaderFactory(body),
                self.comm_radius_m,
                announce=False,
            )
            link.set_routing(self.task.role_of(body), self._reach)
            await link.start()
            self._listeners[body] = link
        self._tasks = [
            asyncio.create_task(self._pump_commands(), name="world-commands"),
            asyncio.create_task(self._pump_liveliness(), name="world-liveliness"),
        ]
        # Daemons flying in this world hold when this token goes, and stop if it stays gone.
        self.mesh.declare_token(self.keys.alive_world)

    async def aclose(self) -> None:
        await cancel_all(self._tasks)
        for link in self._listeners.values():
            await link.aclose()
        self._listeners.clear()

    async def _pump_commands(self) -> None:
        async for key, cmd in self.mesh.subscribe(self.keys.sim_command("*"), SimCommand):
            # Only while this round's commands are collected: late ones are never buffered.
            where = self._window or (-1, -1)
            ok = self.check.admit(key, cmd, where, self._commands.get(where, {}))
            self.stats.rejected_commands = self.check.refused_total
            if ok is not None:
                self._commands[where][ok.uav] = ok
                self._changed.set()

    async def _pump_liveliness(self) -> None:
        async for key, alive in self.mesh.watch_liveliness(self.keys.alive_uav("*")):
            uav = last_chunk(key)
            if uav not in self.task.uav_ids:
                self.stats.unknown_tokens += alive  # not flown here: never present, never lost
                continue
            if alive:
                if uav not in self.alive and uav in self.stats.lost:
                    # Back after leaving: counted here, not at a round start, so a daemon that
                    # restarts inside one round (never seen absent by a round) still counts.
                    self.stats.rejoined[uav] = self.stats.rejoined.get(uav, 0) + 1
                self.alive.add(uav)
            elif uav in self.alive:
                self.alive.discard(uav)
                if self._finished:
                    continue  # daemons leaving after the run ended were not lost
                self.stats.lost.setdefault(uav, self._where)
                log.warning("%s left the swarm at episode %d round %d; it holds", uav, *self._where)
            self._changed.set()

    async def wait_alive(self, uavs: list[str], timeout_s: float) -> set[str]:
        """Wait until every UAV's liveliness token is seen; returns the missing ones."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                while not set(uavs) <= self.alive:
                    self._changed.clear()
                    await self._changed.wait()
        return set(uavs) - self.alive

    def _publish_episode(
        self, episode: int, phase: Literal["start", "end", "shutdown"], reason: str = ""
    ) -> None:
        self.mesh.put(
            self.keys.sim_episode,
            SimEpisode(
                h=self.headers.next(),
                episode=episode,
                task=self.task.name,
                phase=phase,
                reason=reason,
            ),
            block=True,
        )

    async def _collect(
        self, key: tuple[int, int], expected: set[str]
    ) -> tuple[dict[str, SimCommand], float]:
        started = time.monotonic()
        self._window = key
        try:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(self.cfg.deadline_s):
                    while not (expected & self.alive) <= set(self._commands[key]):
                        self._changed.clear()
                        await self._changed.wait()
        finally:
            self._window = None
        return self._commands.pop(key, {}), time.monotonic() - started

    def _reach(self, sender_role: str, receiver_role: str, distance_m: float) -> bool:
        return self.task.spec.reaches(sender_role, receiver_role, distance_m, self.comm_radius_m)

    def _recipients(self, world: KinematicWorld, sender: str, ref: MsgRef) -> list[str]:
        """Who a message ``sender`` sent this round reaches: the bodies that listen (present
        UAVs and listening world agents) the routing rule lets it reach, now."""
        if ref.to == BROADCAST:
            pool = [b for b in world.uav_ids if b != sender]
        else:
            pool = [ref.to] if ref.to in world.uav_ids and ref.to != sender else []
        return [
            b
            for b in pool
            if (b in self._listeners or (b in self.alive and not self.task.is_scripted(b)))
            and self.task.reaches(sender, b, world, self.comm_radius_m)
        ]

    def _same_role(self, uav: str, sharers: list[str]) -> list[str]:
        """The sharers whose experience ``uav`` takes: its role's, not itself."""
        role = self.task.role_of(uav)
        return [u for u in sharers if u != uav and self.task.role_of(u) == role]

    async def _hear(
        self, rnd: int, world: KinematicWorld, expect: dict[str, list[MsgRef]]
    ) -> dict[str, list[InboxMessage]]:
        """What the listening world agents received last round (their own position noted)."""
        heard: dict[str, list[InboxMessage]] = {}
        for body, link in self._listeners.items():
            link.inbox.note_position(rnd, world.body(body).pos)
            heard[body] = await link.collect_inbox(
                expect=expect.get(body, []), timeout_s=self.cfg.deadline_s, max_round=rnd - 1
            )
        return heard

    async def run_episode(self, episode: int) -> EpisodeResult:
        rng = np.random.default_rng(self.cfg.seed + episode)
        world = self.task.build_world(rng, self.cfg)
        if self.vehicles is not None:  # flight link: the emulated autopilots fly this world
            self.vehicles.attach(world)
        ep = Episode(self.task, world, self.cfg.max_rounds)
        self._publish_episode(episode, "start")
        expect: dict[str, list[MsgRef]] = defaultdict(list)
        sharers: list[str] = []  # UAVs that publish last round's experience record
        controlled = self.task.uav_ids
        while not ep.done:
            round_started = time.monotonic()
            refused_before = self.refusals()
            rnd = ep.round
            self._where = (episode, rnd)
            self.mesh.note_round()  # each UAV's verification budget here gains a round's share
            present = [u for u in controlled if u in self.alive]
            for uav in controlled:
                if uav not in self.alive:
                    world.mark_absent(uav)
                elif world.body(uav).absent:  # a restarted daemon is back: it flies again
                    world.mark_present(uav)
            scripted = ep.scripted(await self._hear(rnd, world, expect))
            told: dict[str, list[str]] = {}  # the UAVs each one perceives
            for uav in present:
                body = world.body(uav)
                seen = self.task.visible(world, uav)
                told[uav] = [e.id for e in seen if e.kind == "uav"]
                self.mesh.put(
                    self.keys.sim_perception(uav),
                    SimPerception(
                        h=self.headers.next(),
                        uav=uav,
                        episode=episode,
                        round=rnd,
                        deadline_s=self.cfg.deadline_s,
                        pos=body.pos,
                        vel=body.vel,
                        entities=seen,
                        expected_inbox=expect.get(uav, []),
                        expected_experience=self._same_role(uav, sharers),
                        facts=self.task.private_facts(world, uav),
                    ),
                    block=True,
                )
            commands, waited = await self._collect((episode, rnd), set(present))
            missed = tuple(u for u in present if u not in commands)
            self.stats.deadline_misses += len(missed)
            self.stats.commands += len(commands)
            expect = defaultdict(list)
            sharers = sorted(u for u, c in commands.items() if c.shares)
            orders: dict[str, Vec3 | None] = {u: None for u in controlled}
            commanded = dict(orders)  # as the daemons sent them, before the world bounds them
            guesses: dict[str, str] = {}
            for uav, cmd in commands.items():
                if uav not in orders:
                    continue
                orders[uav] = None if cmd.held else self.check.bound(world, uav, cmd.vel)
                commanded[uav] = None if cmd.held else cmd.vel
                if cmd.guess is not None:
                    guesses[uav] = cmd.guess
                for ref in cmd.sent:
                    for to in self._recipients(world, uav, ref):
                        expect[to].append(ref)
            if self.vehicles is not None:
                # flight link: the bodies move as the autopilots were told over MAVLink; wait
                # until each declared setpoint has arrived, then hold only the silent UAVs.
                orders = await self.vehicles.settle(commands, controlled)
                commanded = orders
            # The invariant judges what each daemon commanded: the world's own bound (a sim
            # check no real vehicle has) must not hide a command that skipped the gate.
            violations = self.envelope.check_round(
                episode, rnd, {b.id: b.pos for b in world.bodies()}, commanded, told
            )
            ep.apply_actions(scripted)
            ep.apply(orders, guesses)
            res = ep.advance()
            for uav in controlled:
                self.mesh.put(
                    self.keys.sim_reward(uav),
                    SimReward(
                        h=self.headers.next(),
                        uav=uav,
                        episode=episode,
                        round=rnd,
                        reward=res.rewards.get(uav, 0.0),
                        done=res.done,
                        reason=res.reason or "",
                    ),
                    block=True,
                )
            log_ = RoundLog(
                episode=episode,
                round=rnd,
                result=res,
                commands=commands,
                missed=missed,
                absent=tuple(u for u in controlled if u not in self.alive),
                wait_s=waited,
                deliveries=sum(len(v) for v in expect.values()),
                wall_s=time.monotonic() - round_started,
                bodies=tuple(b.as_entity() for b in world.bodies()),
                entities=tuple(world.entities()),
                refused=dict(self.refusals() - refused_before),
                violations=tuple(violations),
            )
            self._publish_snapshot(log_, controlled)
            if self._on_round is not None:
                await self._on_round(log_)
            if self.cfg.pace_s > 0:  # watchable runs: at least pace_s of wall time per round
                await asyncio.sleep(max(0.0, self.cfg.pace_s - (time.monotonic() - round_started)))
        result = ep.result()
        self._publish_episode(episode, "end", result.reason)
        return result

    def refusals(self) -> Counter[str]:
        """Everything the world side refused so far, by cause: commands (command check),
        payloads (decoding, signatures), listeners' messages, tokens of unknown ids."""
        out: Counter[str] = Counter(self.check.refused)
        out.update(self.mesh.codec.stats.rejected)
        for link in self._listeners.values():
            out.update({k: v for k, v in link.stats.rejected.items() if k not in RADIO_DROPS})
        if self.stats.unknown_tokens:
            out["unknown_token"] += self.stats.unknown_tokens
        return out

    @property
    def missing_messages(self) -> int:
        """Expected messages the world's listeners never got."""
        return sum(link.stats.missing for link in self._listeners.values())

    def _publish_snapshot(self, log_: RoundLog, controlled: list[str]) -> None:
        """The world after this round, for observers (the console); nothing acts on it."""
        held = [u for u in controlled if (c := log_.commands.get(u)) is None or c.held]
        snap = WorldSnapshot(
            h=self.headers.next(),
            task=self.task.name,
            episode=log_.episode,
            round=log_.round,
            uavs=list(controlled),
            bodies=list(log_.bodies),
            entities=list(log_.entities),
            rewards=dict(log_.result.rewards),
            held=held,
            messages=[
                MsgRef(sender=u, seq=ref.seq, to=ref.to)
                for u, c in sorted(log_.commands.items())
                for ref in c.sent
            ],
            guesses={u: c.guess for u, c in log_.commands.items() if c.guess is not None},
            missed=list(log_.missed),
            absent=list(log_.absent),
            complete=log_.result.complete,
            done=log_.result.done,
            reason=log_.result.reason or "",
            comm_radius_m=self.comm_radius_m,
            sensing_radius_m=self.cfg.sensing_radius_m,
        )
        try:
            self.mesh.put(self.keys.sim_snapshot, snap)
        except ValueError as exc:  # over the payload cap: observers miss a round, the run goes on
            self.stats.snapshots_dropped += 1
            log.warning("round snapshot not published: %s", exc)

    def shutdown(self) -> None:
        """Tell every daemon the run is over (they leave their round loop and exit)."""
        self._finished = True
        self._publish_episode(-1, "shutdown")
