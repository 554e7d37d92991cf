"""The per-UAV daemon: wiring, lifecycle and the loop over rounds.

It talks only to ports (Vehicle, Clock, Perception, RewardSource, Selector); which backend
serves each port is chosen by the caller from config. One round is in ``decision_round``.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

from aeroweaver_edge.agent.history import InteractionHistory
from aeroweaver_edge.config import UavConfig
from aeroweaver_edge.decision_round import RoundContext, RoundOutcome, run_round
from aeroweaver_edge.lifecycle import cancel_all
from aeroweaver_edge.mission_state import MissionState
from aeroweaver_edge.observation import MissionView
from aeroweaver_edge.ports import Clock, Perception, RewardSource, Selector, Vehicle
from aeroweaver_edge.safety_gate import SafetyGate
from aeroweaver_edge.wire import (
    Assignment,
    ExperienceRecord,
    HeaderFactory,
    Keys,
    MissionContext,
    ProgressReport,
)

if TYPE_CHECKING:
    from aeroweaver_edge.agent.memory import AsyncExperienceMemory
    from aeroweaver_edge.mesh import Mesh, Subscription
    from aeroweaver_edge.skills import SkillRegistry

log = logging.getLogger(__name__)
T = TypeVar("T")


@dataclass
class DaemonStats:
    rounds: int = 0
    holds: int = 0
    invalid_choices: int = 0  # holds because no usable label came back
    deadline_misses: int = 0
    messages_sent: int = 0
    messages_dropped: int = 0
    prompt_tokens: int = 0
    prompt_cached: int = 0  # of prompt_tokens, served from the endpoint's prompt cache
    completion_tokens: int = 0
    llm_calls: int = 0
    corrected: int = 0
    experience_shared: int = 0
    experience_ingested: int = 0


@dataclass
class DaemonPorts:
    vehicle: Vehicle
    clock: Clock
    perception: Perception
    rewards: RewardSource


class UavDaemon:
    def __init__(
        self,
        cfg: UavConfig,
        *,
        mesh: Mesh,
        ports: DaemonPorts,
        selector: Selector,
        registry: SkillRegistry,
        headers: HeaderFactory,
        memory: AsyncExperienceMemory | None = None,
        uav_index: int = 0,
        altitude_m: float = 5.0,
        sensing_radius_m: float = 45.0,
        round_s: float = 0.5,
        on_round: Callable[[RoundOutcome], Awaitable[None]] | None = None,
    ) -> None:
        from aeroweaver_edge.peers import PeerLink

        self.cfg = cfg
        self.uav = cfg.uav
        self.keys = Keys(cfg.swarm)
        self.mesh = mesh
        self.ports = ports
        self.headers = headers
        self.memory = memory
        self.mission = MissionState(cfg.uav)
        self.stats = DaemonStats()
        self.link = PeerLink(mesh, self.keys, cfg.uav, headers, cfg.mesh.comm_radius_m)
        self._on_round = on_round
        self._last_reward: float | None = None
        self._warmed: tuple[str, str] | None = None
        self._tasks: list[asyncio.Task[Any]] = []
        self.rc = RoundContext(
            uav=cfg.uav,
            uav_index=uav_index,
            registry=registry,
            selector=selector,
            gate=SafetyGate(cfg.safety, horizon_s=round_s),
            vehicle=ports.vehicle,
            perception=ports.perception,
            link=self.link,
            agent=cfg.agent,
            memory=memory,
            history=(
                InteractionHistory(cfg.agent.history_rounds) if cfg.agent.history_rounds else None
            ),
            altitude_m=altitude_m,
            sensing_radius_m=sensing_radius_m,
        )

    async def _pump_context(self, sub: Subscription[MissionContext]) -> None:
        async for _key, msg in sub:
            self._changed(self.mission.update_context, msg)

    async def _pump_assignment(self, sub: Subscription[Assignment]) -> None:
        async for _key, msg in sub:
            self._changed(self.mission.update_assignment, msg)

    def _changed(self, update: Callable[[T], None], msg: T) -> None:
        before = self.mission.changes
        update(msg)
        if self.mission.changes != before:
            self._announce()

    def _announce(self) -> None:
        """Tell the Commander which assignment this daemon now flies by (a rebuilt context)."""
        view = self.mission.view()
        if view is None:
            return
        self.mesh.put(
            self.keys.report(self.uav),
            ProgressReport(
                h=self.headers.next(),
                phase="ready",
                uav=self.uav,
                mission_id=view.mission_id,
                episode=-1,
                round=-1,
                role=view.role,
                skill="",
                invocation="",
                label=None,
                held=True,
                decode_errors=self.mesh.codec.stats.total,
            ),
        )

    async def _pump_experience(self, sub: Subscription[ExperienceRecord]) -> None:
        async for key, rec in sub:
            view = self.mission.view()
            if self.memory is None or rec.uav == self.uav:
                continue
            if not rec.uav == rec.h.sender == key.split("/")[-2]:
                continue  # a UAV shares only its own experience, on its own key
            if view is not None and rec.role == view.role and await self.memory.ingest(rec):
                self.stats.experience_ingested += 1

    async def _catch_up(self) -> None:
        """A late or restarted daemon asks for the current context and its assignment."""
        for _key, ctx in await self.mesh.get(self.keys.context, MissionContext, timeout_s=1.0):
            self.mission.update_context(ctx)
        for _key, a in await self.mesh.get(self.keys.assign(self.uav), Assignment, timeout_s=1.0):
            self.mission.update_assignment(a)

    async def run(self) -> DaemonStats:
        """Run until the clock says the run is over (or the task is cancelled)."""
        # Subscribe now, before link.start() declares our liveliness token: a Commander that
        # sees the token may publish at once, and that must reach us.
        context = self.mesh.subscribe(self.keys.context, MissionContext)
        assignment = self.mesh.subscribe(self.keys.assign(self.uav), Assignment)
        self._tasks = [
            asyncio.create_task(self._pump_context(context), name=f"{self.uav}-context"),
            asyncio.create_task(self._pump_assignment(assignment), name=f"{self.uav}-assignment"),
        ]
        if self.memory is not None and self.cfg.agent.share_experience:
            shared = self.mesh.subscribe(self.keys.experience("*"), ExperienceRecord)
            self._tasks.append(
                asyncio.create_task(self._pump_experience(shared), name=f"{self.uav}-experience")
            )
        try:
            await self.link.start()
            await self._catch_up()
            self._announce()
            while True:
                tick = await self.ports.clock.next_round()
                await self._absorb_rewards()
                if tick is None:
                    break
                view = self.mission.view()
                await self._warm(view)
                out = await run_round(self.rc, tick, view)
                await self.ports.clock.finish(tick, out.sent)
                self._account(out)
                if view is not None and self.rc.history is not None:
                    self.rc.history.record_decision(
                        out.episode, out.round, out.invocation, out.chosen_by_agent
                    )
                self._report(out, view)
                await self._remember(out, view)
                if self._on_round is not None:
                    await self._on_round(out)
        finally:
            # Whatever ends the daemon (run over, Ctrl-C, SIGTERM, a bug), its body holds.
            try:
                await self.ports.vehicle.hold()
            except Exception:
                log.exception("%s: hold on shutdown failed", self.uav)
            await cancel_all(self._tasks)
            await self.link.aclose()
        return self.stats

    async def _warm(self, view: MissionView | None) -> None:
        """Build the memory index for a new role now, not inside a round's deadline."""
        if self.memory is None or view is None or (view.task, view.role) == self._warmed:
            return
        self._warmed = (view.task, view.role)
        await self.memory.warm(view.task, view.role)

    def _account(self, out: RoundOutcome) -> None:
        s = self.stats
        s.rounds += 1
        s.holds += out.held
        s.deadline_misses += out.reason == "deadline"
        s.invalid_choices += out.held and not out.chosen_by_agent and out.scores is not None
        s.messages_sent += len(out.sent)
        s.messages_dropped += out.dropped
        s.corrected += out.corrected
        if out.scores is not None:
            s.prompt_tokens += out.scores.prompt_tokens
            s.prompt_cached += out.scores.cached_tokens
            s.completion_tokens += out.scores.completion_tokens
            s.llm_calls += out.scores.prompt_tokens > 0 or out.scores.completion_tokens > 0

    def _report(self, out: RoundOutcome, view: MissionView | None) -> None:
        sc = out.scores
        self.mesh.put(
            self.keys.report(self.uav),
            ProgressReport(
                h=self.headers.next(),
                uav=self.uav,
                mission_id=view.mission_id if view else "",
                episode=out.episode,
                round=out.round,
                role=view.role if view else "",
                skill=out.skill,
                invocation=out.invocation,
                label=out.label,
                held=out.held,
                hold_reason=out.hold_reason,
                reward=self._last_reward,
                prompt_tokens=sc.prompt_tokens if sc else 0,
                prompt_cached=sc.cached_tokens if sc else 0,
                completion_tokens=sc.completion_tokens if sc else 0,
                latency_s=out.latency_s,
                messages_sent=len(out.sent),
                messages_dropped=out.dropped,
                decode_errors=self.mesh.codec.stats.total,
                corrected=out.corrected,
            ),
        )

    async def _remember(self, out: RoundOutcome, view: MissionView | None) -> None:
        if self.memory is None or view is None or not out.chosen_by_agent:
            return
        await self.memory.append(
            view.task,
            view.role,
            self.uav,
            out.episode,
            out.round,
            out.state_text,
            out.skill,
            out.invocation,
        )

    async def _absorb_rewards(self) -> None:
        for ev in self.ports.rewards.drain():
            self._last_reward = ev.reward
            if self.rc.history is not None:
                self.rc.history.record_reward(ev.episode, ev.round, ev.reward)
            if self.memory is None:
                continue
            await self.memory.add_reward(self.uav, ev.episode, ev.round, ev.reward, ev.source)
            if ev.done:
                await self.memory.finalise(self.uav, ev.episode)
                await self._share(ev.episode)

    async def _share(self, episode: int) -> None:
        if self.memory is None or not self.cfg.agent.share_experience:
            return
        for rec in await self.memory.export_final(self.uav, episode):
            self.mesh.put(
                self.keys.experience(self.uav), rec.to_wire(self.headers.next()), block=True
            )
            self.stats.experience_shared += 1
