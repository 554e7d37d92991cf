"""The per-UAV daemon: wiring, lifecycle and the loop over rounds.

It talks only to ports (Vehicle, Clock, Perception, RewardSource, PeerChannel, Selector);
which backend serves each port is chosen by the caller from config. One round is in
``decision_round``. The Commander's context and assignment arrive over the mesh; when the
assignment changes, the peer channel gets the new role and the task's message routing.

The Commander's authority is its live session (``MissionState(track_commander=True)``):
the daemon watches its liveliness token, drops the mission (and holds) when it goes, and
asks for the context and its assignment whenever it (re)appears, then again with backoff
until it has both, so a daemon whose link formed after the Commander published (or whose
first query raced the Commander's plan) still gets its assignment.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections import Counter
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

import msgspec

from aeroweaver_edge.agent.history import InteractionHistory
from aeroweaver_edge.agent.memory.round_sharing import RoundSharing, wait_bound
from aeroweaver_edge.agent.memory.shared_intake import MAX_EPISODES, SharedIntake
from aeroweaver_edge.config import UavConfig
from aeroweaver_edge.contracts.defaults import ALTITUDE_M, ROUND_S
from aeroweaver_edge.contracts.hold_reasons import count_causes, format_counts
from aeroweaver_edge.contracts.observation import MissionView
from aeroweaver_edge.contracts.ports import (
    DaemonPorts,
    PeerChannel,
    Reach,
    RoundTick,
    Selector,
)
from aeroweaver_edge.contracts.wire import (
    MAX_CAUSES,
    Assignment,
    DecisionDetail,
    ExperienceRecord,
    HeaderFactory,
    Keys,
    MissionContext,
    ProgressReport,
    StateBeacon,
)
from aeroweaver_edge.daemon.decision_round import RoundContext, RoundOutcome, run_round
from aeroweaver_edge.daemon.flight_phases import ApprovalPredicate, FlightPhases
from aeroweaver_edge.daemon.mission_state import MissionState
from aeroweaver_edge.mesh.inbox import RADIO_DROPS, PeerLimits, within
from aeroweaver_edge.mesh.session import MeshError
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_edge.safety.approval import ApprovalGate
from aeroweaver_edge.safety.approval_link import ApprovalLink
from aeroweaver_edge.safety.gate import SafetyGate

if TYPE_CHECKING:
    from aeroweaver_edge.agent.memory.async_memory import AsyncExperienceMemory
    from aeroweaver_edge.mesh.session import LivelinessWatch, Mesh, Subscription
    from aeroweaver_edge.skills import SkillRegistry

log = logging.getLogger(__name__)
T = TypeVar("T")

CATCH_UP_RETRY_S = (0.25, 4.0)  # first and longest wait between catch-up queries


def _llm_requests(selector: Selector) -> int:
    """Requests the selector has sent so far (LLM selectors count them; others send none):
    counted around the round, so a request cut off by the deadline still counts."""
    return int(getattr(selector, "requests_sent", 0))


@dataclass
class DaemonStats:
    rounds: int = 0
    holds: int = 0
    invalid_choices: int = 0  # holds because no usable label came back
    deadline_misses: int = 0  # rounds this daemon did not finish within its own deadline
    holds_by_cause: dict[str, int] = field(default_factory=lambda: count_causes(()))
    messages_sent: int = 0
    messages_dropped: int = 0
    prompt_tokens: int = 0
    prompt_cached: int = 0  # of prompt_tokens, served from the endpoint's prompt cache
    completion_tokens: int = 0
    llm_calls: int = 0  # requests sent to the LLM endpoint, answered or not
    corrected: int = 0
    experience_shared: int = 0
    experience_ingested: int = 0


def routing(task: str, radius_m: float) -> Reach:
    """The message routing of ``task`` (its spec's rule), or plain range for a task the
    registry does not know (a field mission)."""
    from aeroweaver_edge.tasks import TASK_NAMES, get_spec

    if task not in TASK_NAMES:
        return within(radius_m)
    spec = get_spec(task)

    def reach(sender_role: str, receiver_role: str, distance_m: float) -> bool:
        return spec.reaches(sender_role, receiver_role, distance_m, radius_m)

    return reach


def _end_reason(ctx: MissionContext | None) -> str:
    """Why the Commander ended the mission (its ``ended: ...`` constraint), or ""."""
    if ctx is None or ctx.state != "ended":
        return ""
    ended = [c.removeprefix("ended: ") for c in ctx.constraints if c.startswith("ended: ")]
    return ended[-1] if ended else ""


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
        altitude_m: float = ALTITUDE_M,
        round_s: float = ROUND_S,
        on_round: Callable[[RoundOutcome], Awaitable[None]] | None = None,
        approve: ApprovalPredicate | None = None,
        peer_limits: PeerLimits | None = None,
    ) -> None:
        self.cfg = cfg
        self.uav = cfg.uav
        self.keys = Keys(cfg.swarm)
        self.mesh = mesh
        self.ports = ports
        self.headers = headers
        self.memory = memory
        self.mission = MissionState(cfg.uav, track_commander=True)
        self._holding_for_commander = False
        self.running = False  # inside run(): a stop must let its clean-up hold or land
        self._logged_mission: str | None = None  # the mission the INFO log last announced
        self._mission_start_stats: tuple[int, int, dict[str, int]] = (0, 0, {})
        self._need_catch_up = asyncio.Event()
        self.stats = DaemonStats()
        self._peer_link = None
        if ports.peers is None:
            from aeroweaver_edge.mesh.peers import PeerLink

            # A field daemon perceives its peers from their beacons (FieldPerception); in
            # simulation the world tells each UAV what it senses, so beacons are not followed.
            field = cfg.vehicle.backend != "sim" and not cfg.vehicle.sim_world
            self._peer_link = PeerLink(
                mesh, self.keys, cfg.uav, headers, cfg.mesh.comm_radius_m,
                track_neighbours=field, limits=peer_limits,
            )  # fmt: skip
        self.link: PeerChannel = ports.peers or self._peer_link  # type: ignore[assignment]
        self._routed: tuple[str, str] | None = None
        self._on_round = on_round
        self._last_reward: float | None = None
        self._warmed: tuple[str, str] | None = None
        self._tasks: list[asyncio.Task[Any]] = []
        # Operator approval for vehicle actions ([approval] level; approvals arrive over the
        # mesh, see approval_link). An explicit ``approve`` predicate replaces it (tests).
        self.approvals = ApprovalGate(cfg.uav, cfg.approval, mission=self._mission_id)
        self._approval_link: ApprovalLink | None = None
        gated = approve is None
        self.intake = SharedIntake(cfg.uav)  # same-role peers' records, stored per round
        self._shared: dict[int, int] = {}  # episode -> own records published
        # share_every = "round": each record as it happens, and a queryable for late joiners
        self.sharing: RoundSharing | None = None
        if memory is not None and cfg.agent.share_experience and cfg.agent.share_every == "round":
            self.sharing = RoundSharing(
                mesh, self.keys, cfg.uav, headers, self.intake, gamma=cfg.agent.gamma
            )
        self._joined = False  # this life has played a round (a later first round: fetch)
        # Flight phases (preflight, arm, take off, offboard, mission, land/return) wrap the
        # Vehicle port; the round flies through them. ``approve`` gates vehicle actions.
        self.phases = FlightPhases(
            ports.vehicle,
            uav=cfg.uav,
            altitude_m=altitude_m,
            end_action=cfg.vehicle.end_action,
            on_link_loss=cfg.vehicle.on_link_loss,
            takeoff_timeout_s=cfg.vehicle.takeoff_timeout_s,
            approve=self.approvals.approve if approve is None else approve,
            gate_launch=gated and self.approvals.gates_launch,
        )
        self.rc = RoundContext(
            uav=cfg.uav,
            uav_index=uav_index,
            registry=registry,
            selector=selector,
            gate=SafetyGate(cfg.safety, horizon_s=round_s),
            vehicle=self.phases,
            perception=ports.perception,
            link=self.link,
            agent=cfg.agent,
            memory=memory,
            history=(
                InteractionHistory(cfg.agent.history_rounds) if cfg.agent.history_rounds else None
            ),
            altitude_m=altitude_m,
            act=self.phases.act,
            offer=self.approvals.offer if gated else None,
        )

    def _mission_id(self) -> str | None:
        view = self.mission.view()
        return view.mission_id if view is not None else None

    @property
    def neighbours(self) -> Mapping[str, StateBeacon]:
        """Peers' latest beacons (followed by a field daemon's Zenoh link; else empty)."""
        return self._peer_link.neighbours if self._peer_link is not None else {}

    async def _pump_context(self, sub: Subscription[MissionContext]) -> None:
        async for _key, msg in sub:
            self._changed(self._take_context, msg)

    async def _pump_assignment(self, sub: Subscription[Assignment]) -> None:
        async for _key, msg in sub:
            self._changed(self._take_assignment, msg)

    def _take_context(self, msg: MissionContext) -> None:
        self.mission.update_context(msg, authenticated=self.mesh.authenticated)

    def _take_assignment(self, msg: Assignment) -> None:
        self.mission.update_assignment(msg, authenticated=self.mesh.authenticated)

    async def _pump_commander(self, watch: LivelinessWatch) -> None:
        """The Commander's token: authority starts and ends with it; each appearance is a
        (possibly new) session to catch up with."""
        async for key, alive in watch:
            if key != self.keys.alive_cmdr:
                continue
            if alive != self.mission.commander_is_alive:
                log.info("%s: Commander %s", self.uav, "up" if alive else "gone")
            self._changed(self.mission.commander_alive, alive)
            if alive:
                self._need_catch_up.set()

    def _changed(self, update: Callable[[T], None], msg: T) -> None:
        before = self.mission.changes
        update(msg)
        if self.mission.changes != before:
            self._announce()
            self._log_mission()

    def refusals(self) -> tuple[Counter[str], int]:
        """Everything this daemon refused so far by cause (payloads, peers' messages and
        beacons, Commander payloads, simulator payloads) and expected messages that never
        came: what its reports carry to the run summary."""
        out: Counter[str] = Counter(self.mesh.codec.stats.rejected)
        stats = getattr(self.link, "stats", None)
        missing = 0
        if stats is not None:
            out.update({k: v for k, v in stats.rejected.items() if k not in RADIO_DROPS})
            missing = stats.missing
        out.update(self.mission.rejected)
        out.update(getattr(self.ports.perception, "rejected", {}))
        return out, missing

    def _counters(self) -> dict[str, Any]:
        rejected, missing = self.refusals()
        return {
            "decode_errors": self.mesh.codec.stats.total,
            "rejected": dict(rejected.most_common(MAX_CAUSES)),
            "missing_messages": missing,
        }

    def _final_report(self) -> None:
        """The last counters, as the daemon stops (what no round report carried yet)."""
        view = self.mission.view()
        with contextlib.suppress(MeshError):
            self.mesh.put(
                self.keys.report(self.uav),
                ProgressReport(
                    h=self.headers.next(), phase="final", uav=self.uav,
                    mission_id=view.mission_id if view else (
                        self.mission.context.mission_id if self.mission.context else ""),
                    episode=-1, round=-1, role=view.role if view else "", skill="",
                    invocation="", label=None, held=True, **self._counters(),
                ),
                block=True,
            )  # fmt: skip

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
                hold_reason=self._waiting_for(),
                **self._counters(),
            ),
        )

    def _waiting_for(self) -> str | None:
        """What this daemon waits for before it can fly (a simulated world nobody runs
        yet), for the Commander to tell the operator; None when nothing."""
        waiting = getattr(self.ports.clock, "waiting_for", None)
        return waiting() if waiting is not None else None

    async def _pump_experience(self, sub: Subscription[ExperienceRecord]) -> None:
        """Take same-role peers' records as they come (stored at the next round start, in
        canonical order: ``SharedIntake``); tell the Commander the new tallies once per
        burst, for the orchestration's barrier between episodes."""
        async for first in sub:
            view = self.mission.view()
            role = view.role if view is not None else None
            for key, rec in (first, *sub.drain()):
                self.intake.offer(key, rec, role)
            for episode in self.intake.grown(self._run):
                self._tally(episode)
            if self.sharing is not None:
                self.sharing.arrived.set()

    @property
    def _run(self) -> str:
        return self.memory.run if self.memory is not None else ""

    def _tally(self, episode: int) -> None:
        """Report this daemon's shared-experience tally for ``episode`` (experience phase):
        its own records published (-1: not yet), peers' records received (any role, what
        the barrier checks) and of those, same-role ones taken."""
        view, ctx = self.mission.view(), self.mission.context
        self.mesh.put(
            self.keys.report(self.uav),
            ProgressReport(
                h=self.headers.next(), phase="experience", uav=self.uav,
                mission_id=view.mission_id if view else (ctx.mission_id if ctx else ""),
                episode=episode, round=-1, role=view.role if view else "", skill="",
                invocation="", label=None, held=True,
                experience_shared=self._shared.get(episode, -1),
                experience_taken=self.intake.taken(self._run, episode),
                experience_received=self.intake.received(self._run, episode),
            ),
            block=True,
        )  # fmt: skip

    async def _store_shared(self) -> None:
        if self.memory is not None and self.intake.pending:
            self.stats.experience_ingested += await self.intake.store(self.memory)

    async def _catch_up(self) -> None:
        """A late or restarted daemon asks for the current context and its assignment."""
        for _key, ctx in await self.mesh.get(self.keys.context, MissionContext, timeout_s=1.0):
            self._changed(self._take_context, ctx)
        for _key, a in await self.mesh.get(self.keys.assign(self.uav), Assignment, timeout_s=1.0):
            self._changed(self._take_assignment, a)

    def _caught_up(self) -> bool:
        m = self.mission
        return m.context is not None and m.assignment is not None

    async def _keep_caught_up(self) -> None:
        """Query whenever the Commander's token appears, then with backoff while it is
        alive and this daemon lacks its context or assignment (a publish that raced our
        link, or a plan not made yet). Bounded: one query pair per wait, waits double up
        to ``CATCH_UP_RETRY_S[1]``."""
        first, longest = CATCH_UP_RETRY_S
        while True:
            await self._need_catch_up.wait()
            self._need_catch_up.clear()
            wait = first
            while True:
                with contextlib.suppress(MeshError):  # closing: the task is cancelled next
                    await self._catch_up()
                if self._caught_up() or not self.mission.commander_is_alive:
                    break
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(wait):
                        await self._need_catch_up.wait()  # a new token: ask at once
                self._need_catch_up.clear()
                wait = min(2 * wait, longest)

    async def run(self, *, service: bool = False) -> DaemonStats:
        """Run until the clock says the run is over (or the task is cancelled). A
        ``service`` daemon (``aeroweaver daemon``) never ends by itself: when a simulated
        world ends it lands, forgets that world and waits for the next mission's."""
        self.running = True
        # Subscribe now, before link.start() declares our liveliness token: a Commander that
        # sees the token may publish at once, and that must reach us.
        context = self.mesh.subscribe(self.keys.context, MissionContext)
        assignment = self.mesh.subscribe(self.keys.assign(self.uav), Assignment)
        commander = self.mesh.watch_liveliness(self.keys.alive_cmdr)
        peers = self.mesh.watch_liveliness(self.keys.alive_uav("*"))
        self._tasks = [
            asyncio.create_task(self._pump_peers(peers), name=f"{self.uav}-peers-seen"),
            asyncio.create_task(self._pump_context(context), name=f"{self.uav}-context"),
            asyncio.create_task(self._pump_assignment(assignment), name=f"{self.uav}-assignment"),
            asyncio.create_task(self._pump_commander(commander), name=f"{self.uav}-commander"),
        ]
        self._approval_link = ApprovalLink(
            self.mesh, self.keys, self.uav, self.headers, self.approvals
        )
        self._approval_link.start()  # before the token, like the other subscriptions
        if self.memory is not None and self.cfg.agent.share_experience:
            shared = self.mesh.subscribe(self.keys.experience("*"), ExperienceRecord)
            self._tasks.append(
                asyncio.create_task(self._pump_experience(shared), name=f"{self.uav}-experience")
            )
        if self.sharing is not None:
            self.sharing.start()
        try:
            if self._peer_link is not None:
                await self._peer_link.start()
            await self._catch_up()
            self._announce()
            self._tasks.append(
                asyncio.create_task(self._keep_caught_up(), name=f"{self.uav}-catch-up")
            )
            while True:
                tick = await self.ports.clock.next_round()
                await self._absorb_rewards()
                if tick is not None and self.sharing is not None:
                    await self._take_round_experience(tick)
                await self._store_shared()
                if tick is None:
                    self._final_report()
                    if service and await self._next_world():
                        continue
                    break
                view = self.mission.view()
                # Flight phases: launch once a mission is assigned; land/return when it ends.
                # The Commander gone mid-mission is not the mission's end: hold (the round
                # holds without a view) and wait for it, in the air, however long it takes.
                if view is not None:
                    await self.phases.launch()
                elif self.phases.flying and not self.mission.commander_lost:
                    await self.phases.finish("mission ended")
                self._note_commander_loss(view)
                await self._warm(view)
                self._route(view)
                sent_before = _llm_requests(self.rc.selector)
                out = await run_round(self.rc, tick, view)
                shares = self.sharing is not None and view is not None and out.chosen_by_agent
                if shares and (will_share := getattr(self.ports.clock, "will_share", None)):
                    will_share()  # lockstep: the world tells our same-role peers to wait for it
                await self.ports.clock.finish(tick, sent=out.sent, guess=out.guess)
                calls = _llm_requests(self.rc.selector) - sent_before
                self._account(out, calls)
                if view is not None and self.rc.history is not None:
                    self.rc.history.record_decision(
                        out.episode, out.round, out.invocation, out.chosen_by_agent
                    )
                self._report(out, view, calls)
                await self._remember(out, view)
                await self._settle(tick)
                if shares:
                    await self._share_round(out)
                if self._on_round is not None:
                    await self._on_round(out)
        finally:
            # Whatever ends the daemon (run over, Ctrl-C, SIGTERM, a bug), its body lands or
            # returns if flying (vehicle.end_action), else holds. Never raises.
            await self.phases.finish("daemon stopping")
            await cancel_all(self._tasks)
            if self.sharing is not None:
                await self.sharing.aclose()
            if self._approval_link is not None:
                await self._approval_link.aclose()
            if self._peer_link is not None:
                await self._peer_link.aclose()
            self.running = False
        return self.stats

    async def _next_world(self) -> bool:
        """The simulated world ended (its shutdown, or it went away for good): land, and
        wait for the next world with a fresh start (its episodes count from 0 again, so
        this UAV's experience records go under a new run identity). False when the clock
        is not a world's (nothing to wait for)."""
        reset = getattr(self.ports.clock, "next_world", None)
        if reset is None:
            return False
        await self.phases.finish("the simulated world ended")
        self._log_mission()
        reset()
        self._shared.clear()
        self._last_reward = None
        if self.rc.history is not None:
            self.rc.history = InteractionHistory(self.cfg.agent.history_rounds)
        if self.memory is not None:
            from aeroweaver_edge.agent.memory.experience import new_run_id

            # Every memory call is awaited by this loop, so none is in flight right now.
            self.memory.sync.run = new_run_id()
        log.info("%s: the simulated world ended; idle, waiting for the next mission", self.uav)
        return True

    async def _pump_peers(self, watch: LivelinessWatch) -> None:
        """Log the swarm's UAVs as their daemons come and go (for the operator)."""
        async for key, alive in watch:
            uav = key.rsplit("/", 1)[-1]
            if uav != self.uav:
                log.info("%s: peer %s %s", self.uav, uav, "seen" if alive else "gone")

    def _log_mission(self) -> None:
        """INFO lines when this UAV's mission starts and ends (the end with its holds by
        cause), from the view the Commander's payloads make."""
        view = self.mission.view()
        now = view.mission_id if view is not None else None
        if now == self._logged_mission:
            return
        s = self.stats
        if self._logged_mission is not None and not self.mission.commander_lost:
            rounds, holds, causes = self._mission_start_stats
            by = {c: n - causes.get(c, 0) for c, n in s.holds_by_cause.items()}
            why = _end_reason(self.mission.context)
            log.info(
                "%s: mission %s ended%s: %d rounds, %d holds%s",
                self.uav, self._logged_mission, f" ({why})" if why else "",
                s.rounds - rounds, s.holds - holds,
                f" ({format_counts(by)})" if any(by.values()) else "",
            )  # fmt: skip
        elif self._logged_mission is not None:
            return  # the Commander went away mid-mission: logged as such, not an end
        self._logged_mission = now
        if view is not None:
            self._mission_start_stats = (s.rounds, s.holds, dict(s.holds_by_cause))
            log.info(
                "%s: mission %s (%s): role %s, skills %s",
                self.uav, view.mission_id, view.task, view.role, ", ".join(view.skills),
            )  # fmt: skip

    def _note_commander_loss(self, view: MissionView | None) -> None:
        """Log once per loss that a flying UAV holds for a vanished Commander."""
        if view is None and self.phases.flying and self.mission.commander_lost:
            if not self._holding_for_commander:
                self._holding_for_commander = True
                log.warning(
                    "%s: the Commander went away mid-mission; holding and waiting for it",
                    self.uav,
                )
        elif view is not None and self._holding_for_commander:
            self._holding_for_commander = False
            log.warning("%s: the Commander is back; carrying on", self.uav)

    def _route(self, view: MissionView | None) -> None:
        """Give the peer channel this UAV's role and its task's routing when they change."""
        key = (view.task, view.role) if view is not None else ("", "")
        if key != self._routed:
            self._routed = key
            self.link.set_routing(key[1], routing(key[0], self.cfg.mesh.comm_radius_m))

    async def _warm(self, view: MissionView | None) -> None:
        """Build the memory index for a new role now, not inside a round's deadline."""
        if self.memory is None or view is None or (view.task, view.role) == self._warmed:
            return
        self._warmed = (view.task, view.role)
        await self.memory.warm(view.task, view.role)

    def _account(self, out: RoundOutcome, llm_calls: int) -> None:
        s = self.stats
        s.rounds += 1
        s.holds += out.held
        s.deadline_misses += out.hold_cause == "deadline"
        s.invalid_choices += out.hold_cause == "invalid_answer"
        if out.hold_cause is not None:
            s.holds_by_cause[out.hold_cause] += 1
        s.messages_sent += len(out.sent)
        s.messages_dropped += out.dropped
        s.corrected += out.corrected
        s.llm_calls += llm_calls
        if out.scores is not None:
            s.prompt_tokens += out.scores.prompt_tokens
            s.prompt_cached += out.scores.cached_tokens
            s.completion_tokens += out.scores.completion_tokens

    def _report(self, out: RoundOutcome, view: MissionView | None, llm_calls: int) -> None:
        sc = out.scores
        llm_class = sc.extra.get("probe", "") if sc is not None else ""
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
                hold_cause=out.hold_cause,
                reward=self._last_reward,
                prompt_tokens=sc.prompt_tokens if sc else 0,
                prompt_cached=sc.cached_tokens if sc else 0,
                completion_tokens=sc.completion_tokens if sc else 0,
                latency_s=out.latency_s,
                cpu_s=out.cpu_s,
                messages_sent=len(out.sent),
                messages_dropped=out.dropped,
                corrected=out.corrected,
                llm_calls=llm_calls,
                llm_class=str(llm_class),
                decision=self._decision(out),
                vehicle=self.phases.status(getattr(self.ports.perception, "points", ())),
                **self._counters(),
            ),
        )

    def _decision(self, out: RoundOutcome) -> DecisionDetail | None:
        """The round's options, scores and pick, rounded for the wire (None: no options)."""
        if not out.options:
            return None
        sc = out.scores
        bound = sc.omitted_bound if sc is not None else None
        return DecisionDetail(
            options=list(out.options),
            base={k: round(v, 4) for k, v in (sc.logprobs.items() if sc else ())},
            advantage={k: round(v, 4) for k, v in out.advantages.items()},
            chosen=out.label,
            reason=out.reason,
            corrected=out.corrected,
            beta=self.cfg.agent.beta,
            text_label=sc.text_label if sc is not None else None,
            omitted_bound=round(bound, 4) if bound is not None and math.isfinite(bound) else None,
        )

    async def _remember(self, out: RoundOutcome, view: MissionView | None) -> None:
        if self.memory is None or view is None or not out.chosen_by_agent:
            return
        await self.memory.append(
            task=view.task,
            role=view.role,
            uav=self.uav,
            episode=out.episode,
            round=out.round,
            state_text=out.state_text,
            skill=out.skill,
            invocation=out.invocation,
        )

    async def _settle(self, tick: RoundTick) -> None:
        """A lockstep clock (the simulated world) can wait for this round's reward: taking
        it now, not at the next round's start, finalises and shares an episode's records
        before the world starts the next episode (the barrier waits for them)."""
        settle = getattr(self.ports.clock, "settle", None)
        if settle is not None:
            await settle(tick)
            await self._absorb_rewards()

    async def _absorb_rewards(self) -> None:
        for ev in self.ports.rewards.drain():
            self._last_reward = ev.reward
            if self.sharing is not None and math.isfinite(ev.reward):
                self.sharing.note_reward(ev.episode, ev.round, ev.reward)
            if self.rc.history is not None:
                self.rc.history.record_reward(ev.episode, ev.round, ev.reward)
            if self.memory is None:
                continue
            await self.memory.add_reward(self.uav, ev.episode, ev.round, ev.reward, ev.source)
            if ev.done:
                await self.memory.finalise(self.uav, ev.episode)
                await self._share(ev.episode)

    async def _take_round_experience(self, tick: RoundTick) -> None:
        """share_every = "round": a late or restarted daemon first fetches its role's recent
        experience from its peers' queryables; every round waits (bounded) for the records
        the world says its same-role peers published last round (stored next, together)."""
        sharing, view = self.sharing, self.mission.view()
        if sharing is None:
            return
        if not self._joined and view is not None:
            self._joined = True
            if (tick.episode, tick.round) != (0, 0):
                await sharing.fetch(view.role)
        if tick.experience_from and tick.round > 0:
            await sharing.wait_for(
                self._run, tick.episode, tick.round - 1, tick.experience_from,
                wait_bound(tick.deadline_s),
            )  # fmt: skip

    async def _share_round(self, out: RoundOutcome) -> None:
        """Publish this round's own record, with its reward if it came (share_every=round)."""
        if self.memory is None or self.sharing is None:
            return
        rec = await self.memory.get(self.uav, out.episode, out.round)
        if rec is None or rec.origin:
            return
        held = self.sharing.held_rewards(out.episode, out.round)
        wire = msgspec.structs.replace(rec.to_wire(self.headers.next()), held_rewards=held)
        self.mesh.put(self.keys.experience(self.uav), wire, block=True)
        self.sharing.published(wire)

    async def _share(self, episode: int) -> None:
        if self.memory is None or not self.cfg.agent.share_experience:
            return
        records = await self.memory.export_final(self.uav, episode)
        for rec in records:
            wire = rec.to_wire(self.headers.next())
            self.mesh.put(self.keys.experience(self.uav), wire, block=True)
            if self.sharing is not None:
                self.sharing.published(wire)
            self.stats.experience_shared += 1
        self._shared[episode] = len(records)
        while len(self._shared) > MAX_EPISODES:
            del self._shared[min(self._shared)]
        self._tally(episode)
