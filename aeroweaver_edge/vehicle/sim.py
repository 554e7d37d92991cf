"""The simulator backend: Vehicle, Clock, Perception and RewardSource ports served by the
kinematic world over Zenoh, in lockstep.

The world sends each UAV its frozen perception (the round trigger, what it senses and its
private facts); the UAV answers with one gated velocity setpoint, the list of peer messages
it sent (so the world can tell each recipient what to wait for next round) and its guess,
if a skill recorded one. A UAV that misses the world's deadline holds.

Only the world speaks for the world: perception, rewards and episode events count only if
their header names the world identity (authentic when the mesh verifies signatures) and
they are for this UAV; a perception must be newer than the last one taken (one is kept
pending, the newest: a flood cannot queue up), and a reward only counts once, for a round
this UAV was sent a perception for and has not played past. Refusals are counted by cause
in ``rejected``.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections import Counter
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from aeroweaver_edge.contracts.observation import VehicleState
from aeroweaver_edge.contracts.ports import Health, Percept, RewardEvent, RoundTick
from aeroweaver_edge.contracts.wire import (
    HeaderFactory,
    Keys,
    MsgRef,
    SimCommand,
    SimEpisode,
    SimPerception,
    SimReward,
    Vec3,
)

if TYPE_CHECKING:
    from aeroweaver_edge.mesh.session import Mesh, Subscription

ZERO: Vec3 = (0.0, 0.0, 0.0)
WAITING_FOR_WORLD = "waiting for a simulated world"
"""What this UAV's ready report says while no world flies it (``waiting_for``): the
Commander tells an operator who runs no world at once, instead of watching in silence."""
WORLD = "world"  # the simulated world's identity (security.identity.WORLD)


class SimLink:
    """One UAV's link to the simulated world. Serves four ports from one subscription set."""

    def __init__(
        self, mesh: Mesh, keys: Keys, uav: str, headers: HeaderFactory, reward_wait_s: float = 2.0
    ) -> None:
        self._mesh = mesh
        self._keys = keys
        self.uav = uav
        self._headers = headers
        self._reward_wait_s = reward_wait_s
        self._tick_ready = asyncio.Event()
        self._reward_arrived = asyncio.Event()
        self.rejected: Counter[str] = Counter()
        self.superseded = 0  # perceptions replaced by a newer one before the daemon took them
        self.worlds = 0  # simulated worlds this link has flown in (a new epoch is a new world)
        self._world_epoch: int | None = None  # header epoch of the world being flown
        self._current: SimPerception | None = None  # the perception of the round in play
        self._reset()
        # Flight phases: the simulated airframe starts disarmed on the ground and goes
        # through arm and take-off like a real one. The world flies it at the fixed flight
        # level either way (take-off happens before the first round), so returns are as before.
        self.armed = False
        self.in_air = False
        self._subs: list[Subscription[Any]] = []

    def _reset(self) -> None:
        """Forget everything of the current world: the next one starts at episode 0."""
        # The newest perception not yet taken (None: none), and whether the world is over.
        self._next: SimPerception | None = None
        self._over = False
        self._taken: tuple[int, int] = (-1, -1)  # (episode, round) of the newest perception
        self._rewards: list[RewardEvent] = []
        self._reward_seen: set[tuple[int, int]] = set()
        self._last_played: tuple[int, int] | None = None
        self._setpoint: Vec3 = ZERO
        self._held = True
        self._shares = False  # this round's experience record will be published

    def next_world(self) -> None:
        """A service daemon is done with this world (its shutdown, or it went away for
        good): wait for the next one, whose rounds start again at episode 0."""
        self._reset()
        self._world_epoch = None

    def end_world(self) -> None:
        """The world went away and did not come back: end its rounds here, as its
        shutdown would (``next_round`` returns None). Nothing to end if no world flew this
        UAV since the last ``next_world``."""
        if self._world_epoch is None:
            return
        self._over = True
        self._tick_ready.set()
        self._reward_arrived.set()

    @property
    def world_over(self) -> bool:
        """No world is being flown: none sent this UAV a perception since the last
        ``next_world``, or the one that did has ended (its shutdown came)."""
        return self._world_epoch is None or self._over

    def waiting_for(self) -> str | None:
        """What this link waits for before a round can start, if anything."""
        return f"{WAITING_FOR_WORLD} (sim backend)" if self.world_over else None

    def _admit_world(self, epoch: int) -> str | None:
        """Admit a perception's epoch: the current world's, or a new world's (a later
        session: the previous world ended; its rounds are forgotten and this one starts
        afresh); an older epoch is an earlier world's (refused). Epochs are boot counters on a
        signed mesh and start times otherwise (``wire.boot_epoch``), both increasing."""
        if epoch == self._world_epoch:
            return None
        if self._world_epoch is not None:
            if epoch < self._world_epoch:  # a late payload of an earlier world
                return "perception_old_world"
            self._reset()
        self._world_epoch = epoch
        self.worlds += 1
        return None

    async def start(self) -> None:
        keys, mesh = self._keys, self._mesh
        self._subs = [
            mesh.subscribe(keys.sim_perception(self.uav), SimPerception, on_item=self._on),
            mesh.subscribe(keys.sim_reward(self.uav), SimReward, on_item=self._on),
            mesh.subscribe(keys.sim_episode, SimEpisode, on_item=self._on),
        ]

    async def aclose(self) -> None:
        subs, self._subs = self._subs, []
        for sub in subs:
            await sub.aclose()

    def _on(self, item: tuple[str, SimPerception | SimReward | SimEpisode]) -> None:
        msg = item[1]
        if isinstance(msg, SimPerception):
            why = self.on_perception(msg)
        elif isinstance(msg, SimReward):
            why = self.on_reward(msg)
        else:
            why = self.on_episode(msg)
        if why is not None:
            self.rejected[why] += 1

    def on_perception(self, msg: SimPerception) -> str | None:
        """Take a perception as the next round's, or say why not."""
        where = (msg.episode, msg.round)
        if msg.h.sender != WORLD:
            return "perception_not_world"
        if msg.uav != self.uav:
            return "perception_wrong_uav"
        if not all(math.isfinite(x) for x in (*msg.pos, *msg.vel, msg.deadline_s)):
            return "perception_non_finite"
        why = self._admit_world(msg.h.epoch)
        if why is not None:
            return why
        if where <= self._taken:
            return "perception_stale"
        self.superseded += self._next is not None  # the daemon fell behind
        self._taken, self._next = where, msg
        self._tick_ready.set()
        self._reward_arrived.set()  # a settle waiting on an older round stops (see settle)
        return None

    def _reward_round(self, where: tuple[int, int]) -> bool:
        """A reward counts for a round this UAV was sent a perception for, from the one it
        played last on (a late daemon still gets the rewards of rounds it is behind on)."""
        return (self._last_played or (-1, -1)) <= where <= self._taken

    def on_reward(self, msg: SimReward) -> str | None:
        """Take a reward, or say why not."""
        where = (msg.episode, msg.round)
        if msg.h.sender != WORLD:
            return "reward_not_world"
        if msg.uav != self.uav:
            return "reward_wrong_uav"
        if msg.h.epoch != self._world_epoch:
            return "reward_not_current"  # not the world this UAV flies in now
        if where in self._reward_seen:
            return "reward_duplicate"
        if not self._reward_round(where):
            return "reward_not_current"
        if not math.isfinite(msg.reward):
            return "reward_non_finite"
        self._reward_seen.add(where)
        if len(self._reward_seen) > 8:  # only these rounds can still count
            self._reward_seen = {k for k in self._reward_seen if self._reward_round(k)}
        self._rewards.append(RewardEvent(msg.episode, msg.round, msg.reward, msg.done, "sim"))
        self._reward_arrived.set()
        return None

    def on_episode(self, msg: SimEpisode) -> str | None:
        """The world's episode events; only its shutdown ends the world's rounds here (a
        service daemon then waits for the next world, ``next_world``)."""
        if msg.h.sender != WORLD:
            return "episode_not_world"
        if msg.phase == "shutdown":
            if self._world_epoch is not None and msg.h.epoch < self._world_epoch:
                return "episode_old_world"  # an earlier world's, late
            self._over = True
            self._tick_ready.set()
        return None

    async def _await_reward(
        self, key: tuple[int, int], bound_s: float | None = None, *, until_newer: bool = False
    ) -> None:
        """Lockstep: a round's reward reaches the agent before its next round starts.
        ``until_newer``: stop early once a perception of a later round has arrived. An ended
        world (``end_world``, its shutdown) ends the wait at once: a daemon whose world died
        mid-round lands then, not after the round's deadline."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(self._reward_wait_s if bound_s is None else bound_s):
                while key not in self._reward_seen and not (until_newer and self._taken > key):
                    if self._over:  # the world ended or went for good: no reward will come
                        return
                    self._reward_arrived.clear()
                    await self._reward_arrived.wait()

    # Clock
    async def next_round(self) -> RoundTick | None:
        while self._next is None and not self._over:
            self._tick_ready.clear()
            await self._tick_ready.wait()
        msg, self._next = self._next, None
        if self._last_played is not None:
            await self._await_reward(self._last_played)
        if msg is None:
            return None
        self._current = msg
        self._setpoint, self._held = ZERO, True
        self._shares = False
        return RoundTick(
            msg.episode, msg.round, msg.deadline_s, tuple(msg.expected_inbox),
            tuple(msg.expected_experience),
        )  # fmt: skip

    def will_share(self) -> None:
        """This round's experience record will be published once rewarded: the command
        says so, and the world tells the same-role peers to wait for it next round."""
        self._shares = True

    async def finish(
        self, tick: RoundTick, *, sent: Sequence[MsgRef], guess: str | None = None
    ) -> None:
        if (tick.episode, tick.round) <= self._taken:  # not a round of a world since forgotten
            self._last_played = (tick.episode, tick.round)
        self._mesh.put(
            self._keys.sim_command(self.uav),
            SimCommand(
                h=self._headers.next(),
                uav=self.uav,
                episode=tick.episode,
                round=tick.round,
                vel=self._setpoint,
                held=self._held,
                sent=list(sent),
                guess=guess,
                shares=self._shares,
            ),
            block=True,
        )

    async def settle(self, tick: RoundTick) -> None:
        """Wait (bounded) for ``tick``'s reward: the daemon takes it at the end of the round,
        so an episode's last reward is absorbed before the world starts the next one. The
        world rewards a round once every command is in or its deadline passed, so a UAV that
        decided early waits up to that deadline: with a fixed 2 s, an LLM swarm's fast UAV
        missed the episode's last reward and the barrier waited its full bound for it.
        A perception of a later round ends the wait: the world has moved on, and the next
        round waits ``reward_wait_s`` more for this reward. A UAV cut off by a partition lost
        the reward sent across it; before, it sat here the whole bound after the link healed
        (12 s at a 10 s deadline) and missed the first round the world sent it."""
        await self._await_reward(
            (tick.episode, tick.round), tick.deadline_s + self._reward_wait_s, until_newer=True
        )

    # Perception
    async def sense(self, tick: RoundTick) -> Percept:
        msg = self._require()
        return Percept(
            VehicleState(msg.pos, msg.vel, self.armed, self.in_air), msg.entities, msg.facts
        )

    # RewardSource
    def drain(self) -> list[RewardEvent]:
        out, self._rewards = self._rewards, []
        return out

    # Vehicle: arm and take-off change only the phase flags (the world is planar).
    def _require(self) -> SimPerception:
        if self._current is None:
            raise RuntimeError(f"{self.uav}: no perception from the simulator yet")
        return self._current

    async def state(self) -> VehicleState:
        msg = self._require()
        return VehicleState(msg.pos, msg.vel, self.armed, self.in_air)

    async def arm(self) -> None:
        self.armed = True

    async def takeoff(self, altitude_m: float) -> None:
        if not self.armed:
            raise RuntimeError(f"{self.uav}: take-off while disarmed")
        self.in_air = True

    async def set_velocity(self, north: float, east: float, down: float) -> None:
        if self.in_air:
            self._setpoint, self._held = (north, east, down), False

    async def goto(self, north: float, east: float, down: float) -> None:
        raise NotImplementedError("the kinematic simulator flies velocity setpoints only")

    async def hold(self) -> None:
        self._setpoint, self._held = ZERO, True

    async def land(self) -> None:
        await self.hold()
        self.in_air = self.armed = False

    async def return_home(self) -> None:
        await self.land()

    async def health(self) -> Health:
        return Health(ok=self._current is not None, detail="sim")
