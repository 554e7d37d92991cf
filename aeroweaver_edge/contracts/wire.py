"""Every Zenoh payload and key expression, in one place.

Payloads are ``msgspec.Struct``s encoded as MessagePack. Each carries a header (schema
version, sender, boot epoch, sequence number, sender wall-clock stamp, TTL) so receivers
can drop replays, stale or foreign data without trusting the clock of another UAV.
Decoding never raises into the caller: bad bytes are counted, logged at a limited rate,
and return ``None``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any, Final, Literal, TypeVar

import msgspec

from aeroweaver_edge.contracts import defaults
from aeroweaver_edge.contracts.hold_reasons import HoldCause

SCHEMA_VERSION: Final = 1
MAX_PAYLOAD_BYTES: Final = 64 * 1024
MAX_TEXT: Final = 4096
MAX_FACTS: Final = 8
MAX_FACT_CHARS: Final = 64

log = logging.getLogger(__name__)

Vec3 = tuple[float, float, float]
"""North, east, down in metres (or metres per second), local NED frame."""


class Header(msgspec.Struct, frozen=True, kw_only=True):
    v: int = SCHEMA_VERSION
    sender: str
    epoch: int  # boot epoch: lets receivers tell a restart from a replay
    seq: int
    stamp: float  # sender wall clock, informative only: never compared for safety
    ttl_s: float = 10.0


class StateBeacon(msgspec.Struct, frozen=True, kw_only=True, tag="state"):
    """Latest-wins pose and status of one UAV."""

    h: Header
    uav: str
    round: int
    pos: Vec3
    vel: Vec3
    role: str = ""
    status: str = "nominal"


BROADCAST: Final = "*"
"""``InboxMessage.to`` of a message for every peer it reaches."""

MessagePurpose = Literal["task", "coordination"]
"""Why a peer message exists: the task needs it (goal, ciphertext) or it only helps peers
coordinate (intent, target, status reports)."""


class InboxMessage(msgspec.Struct, frozen=True, kw_only=True, tag="msg"):
    """A peer message (directed, or ``to="*"`` for every peer it reaches); enters the
    recipient's next round as data, never as a command. Whether it reaches a recipient is
    judged there, on ``sender_pos`` and the recipient's own position in ``round``, with the
    mission's routing rule for ``sender_role``."""

    h: Header
    to: str
    round: int
    kind: str  # status / observation / intent / request / target / goal / ciphertext
    body: dict[str, str | int | float | bool] = {}
    sender_pos: Vec3 | None = None
    sender_role: str = ""
    ttl_rounds: int = 8
    purpose: MessagePurpose = "coordination"


MAX_CAUSES: Final = 64
Cause = Annotated[str, msgspec.Meta(max_length=64)]
Causes = Annotated[dict[Cause, int], msgspec.Meta(max_length=MAX_CAUSES)]
"""Counts by a fixed cause name (e.g. payloads a receiver refused): small and bounded."""


class DecisionDetail(msgspec.Struct, frozen=True, kw_only=True):
    """Why a UAV chose what it chose (for traces, the console and benchmarks): its labelled
    options, the selector's base scores, the experience advantages and the pick."""

    options: list[str]  # "A. cover_landmark(target_id=L0)", in label order
    base: dict[str, float] = {}  # label -> base score (log-prob) of the labels that came back
    advantage: dict[str, float] = {}  # label -> experience advantage (beta not applied)
    chosen: str | None = None  # the label picked (None: held without a pick)
    reason: str = ""  # scoring.choose's reason (e.g. corrected, bound kept base, no label)
    corrected: bool = False
    beta: float = 0.0
    text_label: str | None = None  # the label the model generated, if any
    omitted_bound: float | None = None  # log-prob bound on labels that did not come back


MAX_POINTS: Final = 32
Short = Annotated[str, msgspec.Meta(max_length=64)]


class VehicleStatus(msgspec.Struct, frozen=True, kw_only=True):
    """What a UAV's own vehicle link says at the end of a round, for observers (the console
    draws a field swarm from it when no simulated world publishes snapshots). Optional where
    the link does not report it; data only, nothing acts on it."""

    pos: Vec3  # local NED, metres
    vel: Vec3 = (0.0, 0.0, 0.0)
    armed: bool | None = None
    in_air: bool | None = None
    mode: Short = ""  # the autopilot's flight mode name, e.g. OFFBOARD, AUTO.LAND
    battery_pct: float | None = None  # remaining, 0..100 (None: the link does not say)
    heartbeat_age_s: float | None = None  # since the vehicle's last heartbeat
    phase: Short = ""  # the daemon's flight phase (flight_phases.Phase)
    points: Annotated[list[Entity], msgspec.Meta(max_length=MAX_POINTS)] = []
    """The known points of interest this UAV flies by (field config), e.g. landmarks."""


class ProgressReport(msgspec.Struct, frozen=True, kw_only=True, tag="report"):
    """Per-round progress; (``phase="ready"``) the ack that a UAV holds its assignment;
    (``phase="final"``) the daemon's last counters as it stops; or (``phase="experience"``)
    its shared-experience tally for ``episode``: how many of its own finalised records of
    that episode it published, and how many same-role peers' records of it it has taken
    (the orchestration's barrier between episodes waits on these)."""

    h: Header
    phase: Literal["round", "ready", "final", "experience"] = "round"
    uav: str
    mission_id: str
    episode: int
    round: int
    role: str
    skill: str
    invocation: str
    label: str | None
    held: bool
    hold_reason: str | None = None
    hold_cause: HoldCause | None = None  # the closed set of hold_reasons.HOLD_CAUSES
    reward: float | None = None
    prompt_tokens: int = 0
    completion_tokens: int = 0
    latency_s: float = 0.0
    cpu_s: float = 0.0  # the daemon thread's CPU time over the round
    messages_sent: int = 0
    messages_dropped: int = 0
    decode_errors: int = 0  # cumulative payloads this daemon rejected
    corrected: bool = False  # the experience correction changed the pick
    llm_calls: int = 0  # requests sent to the LLM endpoint this round (answered or not)
    llm_class: str = ""  # the selector's current logprob class (probe kind), if any
    prompt_cached: int = 0  # of prompt_tokens, served from the endpoint's prompt cache
    decision: DecisionDetail | None = None  # options, scores, advantages, pick (round phase)
    rejected: Causes = {}  # cumulative: everything this daemon refused, by cause
    missing_messages: int = 0  # cumulative: expected messages that never came
    experience_shared: int = 0  # experience phase: own records of ``episode`` published
    experience_taken: int = 0  # experience phase: same-role peers' records of ``episode`` taken
    experience_received: int = 0  # experience phase: peers' final records of it received, any role
    vehicle: VehicleStatus | None = None  # round phase: the vehicle link's view (field)


class MissionContext(msgspec.Struct, frozen=True, kw_only=True, tag="context"):
    """What the Commander tells every UAV about the mission. Data, never flight commands."""

    h: Header
    mission_id: str
    task: str
    text: str
    constraints: list[str] = []
    participants: list[str] = []
    episode: int = 0
    state: Literal["active", "ended"] = "active"  # "ended": every participant holds


class Assignment(msgspec.Struct, frozen=True, kw_only=True, tag="assign"):
    h: Header
    mission_id: str
    uav: str
    role: str
    local_goal: str
    skills: list[str]
    revision: int = 0


MAX_HELD_REWARDS: Final = 256


class ExperienceRecord(msgspec.Struct, frozen=True, kw_only=True, tag="exp"):
    """One decision's experience; published so same-role daemons learn from each other."""

    h: Header
    task: str
    role: str
    uav: str
    episode: int
    round: int
    state_text: str
    skill: str
    invocation: str
    reward: float | None = None
    ret: float | None = None
    final: bool = False
    reward_source: str = ""
    run: str = ""  # the publisher's run identity: part of the deduplication key
    # Shared in flight (share_every = "round"): the rewards (round, r) of this trajectory's
    # rounds since the publisher's previous record that have no record (it held), so the
    # receiver extends the earlier records' returns as the publisher did.
    held_rewards: Annotated[list[tuple[int, float]], msgspec.Meta(max_length=MAX_HELD_REWARDS)] = []


MAX_BATCH_RECORDS: Final = 64


class ExperienceBatch(msgspec.Struct, frozen=True, kw_only=True, tag="exp_batch"):
    """A daemon's recent own records, served on its experience key (a queryable), so a
    daemon that restarts or joins late fetches its role's experience from its peers."""

    h: Header
    uav: str
    records: Annotated[list[ExperienceRecord], msgspec.Meta(max_length=MAX_BATCH_RECORDS)] = []


class Entity(msgspec.Struct, frozen=True, kw_only=True):
    id: str
    kind: str  # landmark / uav / evader / food / ...
    pos: Vec3
    vel: Vec3 = (0.0, 0.0, 0.0)
    role: str = ""


class MsgRef(msgspec.Struct, frozen=True, kw_only=True, array_like=True):
    """Identifies one directed message: (sender, seq) is unique; ``to`` routes the manifest."""

    sender: str
    seq: int
    to: str = ""


Fact = Annotated[str, msgspec.Meta(max_length=MAX_FACT_CHARS)]
Facts = Annotated[dict[Fact, Fact], msgspec.Meta(max_length=MAX_FACTS)]
"""A UAV's private facts (goal landmark, symbol, key, cargo, own slot): a few short strings."""


class SimPerception(msgspec.Struct, frozen=True, kw_only=True, tag="perception"):
    """Simulator -> one UAV: the round trigger plus what that UAV can sense, frozen, and its
    private facts (only what its role may know; sent on that UAV's own key)."""

    h: Header
    uav: str
    episode: int
    round: int
    deadline_s: float
    pos: Vec3
    vel: Vec3
    entities: list[Entity] = []
    expected_inbox: list[MsgRef] = []  # lockstep: messages that reach this UAV, sent last round
    # lockstep ([agent] share_every = "round"): same-role peers that publish their last
    # round's experience record; the UAV stores them all before it decides
    expected_experience: list[str] = []
    facts: Facts = {}


class SimReward(msgspec.Struct, frozen=True, kw_only=True, tag="reward"):
    h: Header
    uav: str
    episode: int
    round: int
    reward: float
    done: bool = False
    reason: str = ""


class SimCommand(msgspec.Struct, frozen=True, kw_only=True, tag="command"):
    """One UAV -> simulator: its gated velocity for the round, the messages it sent and the
    guess its skill recorded this round, if any (private communication: the world scores it)."""

    h: Header
    uav: str
    episode: int
    round: int
    vel: Vec3
    held: bool = False
    sent: list[MsgRef] = []
    guess: Fact | None = None
    shares: bool = False  # publishes this round's experience record once rewarded


class SimEpisode(msgspec.Struct, frozen=True, kw_only=True, tag="episode"):
    """Simulator -> all: an episode has started or ended."""

    h: Header
    episode: int
    task: str
    phase: Literal["start", "end", "shutdown"]
    reason: str = ""


class CentralAsk(msgspec.Struct, frozen=True, kw_only=True, tag="ask"):
    """One UAV -> a baseline's central node (DESIGN §12, "baselines are selectors"): what this
    UAV perceived this round and its labelled options, so the central node can choose for it.
    Only the essentials of the UAV's decision request; executors and the gate stay on the UAV."""

    h: Header
    uav: str
    mission_id: str = ""
    episode: int
    round: int
    role: str = ""
    local_goal: str = ""
    observation: str = ""  # the UAV's observation text (agent.describe)
    messages: list[str] = []  # peer messages it received, one line each (prompt format)
    options: list[str] = []  # "A. cover_landmark(target_id=L0)", in label order
    deadline_s: float = 0.0  # the UAV's round budget: a later answer is of no use to it


class CentralReview(msgspec.Struct, frozen=True, kw_only=True, tag="review"):
    """One UAV -> the central node (HMAS-2): its local review of the proposed option."""

    h: Header
    uav: str
    episode: int
    round: int
    agree: bool | None = None  # None: the review failed (no usable answer)
    suggest: str | None = None  # the label it would rather take, if it disagrees
    error: str | None = None


class CentralAnswer(msgspec.Struct, frozen=True, kw_only=True, tag="central"):
    """The central node -> one UAV: a proposal to review (HMAS-2) or the final choice."""

    h: Header
    uav: str
    episode: int
    round: int
    phase: Literal["proposal", "final"] = "final"
    label: str | None = None  # None: no valid choice for this UAV (it holds)
    error: str | None = None  # set when no LLM answer came back at all (call failed)
    reason: str = ""


class WorldSnapshot(msgspec.Struct, frozen=True, kw_only=True, tag="snapshot"):
    """Simulator -> observers (the console, traces): the world after one round, published
    once per round. ``h.stamp`` is when the world published it (the console's latency
    reference). Read-only data: nothing acts on it."""

    h: Header
    task: str
    episode: int
    round: int  # 0-based decision round
    uavs: list[str]  # the UAVs we fly; the other bodies are the world's own agents
    bodies: list[Entity] = []
    entities: list[Entity] = []
    rewards: dict[str, float] = {}
    held: list[str] = []  # controlled UAVs whose applied command was a hold (or missing)
    messages: list[MsgRef] = []  # sent this round: (sender, seq, to)
    guesses: dict[str, str] = {}
    missed: list[str] = []
    absent: list[str] = []
    complete: bool = False
    done: bool = False
    reason: str = ""
    arena_half_m: float = defaults.ARENA_HALF_M
    comm_radius_m: float = defaults.COMM_RADIUS_M
    sensing_radius_m: float = defaults.SENSING_RADIUS_M


VehicleActionKind = Literal["takeoff", "land", "return_home"]
"""The vehicle actions an operator approves (``actions.VehicleAction.kind``)."""


class OperatorCommand(msgspec.Struct, frozen=True, kw_only=True, tag="operator"):
    """Operator -> Commander (``aw/<swarm>/operator/command``): stop the mission. The
    Commander acts on it only from an operator identity and only for its current mission;
    it never reaches a vehicle (every UAV holds, then lands or returns, by itself)."""

    h: Header
    action: Literal["stop"]
    mission_id: Annotated[str, msgspec.Meta(min_length=1, max_length=128)]
    reason: Annotated[str, msgspec.Meta(max_length=200)] = ""
    by: Annotated[str, msgspec.Meta(max_length=64)] = ""  # the person, for the record


class Approval(msgspec.Struct, frozen=True, kw_only=True, tag="approval"):
    """Operator -> one UAV (``aw/<swarm>/operator/approval/<uav>``): this vehicle action may
    run within ``ttl_s`` of receipt. Single-use or per mission, as the UAV's approval level
    says; the UAV checks the sender, the freshness and the id, records it and acknowledges."""

    h: Header
    id: Annotated[str, msgspec.Meta(min_length=8, max_length=64)]
    uav: str
    action: VehicleActionKind
    ttl_s: Annotated[float, msgspec.Meta(gt=0, le=86_400)]
    by: Annotated[str, msgspec.Meta(max_length=64)] = ""
    mission_id: str = ""  # "" : whatever mission the UAV flies when it is used


class ApprovalRecord(msgspec.Struct, frozen=True, kw_only=True):
    """One approval as a UAV recorded it: who, when, what, until when, and what became of it."""

    id: str
    action: VehicleActionKind
    sender: str  # the identity that sent it
    by: str  # the person it names
    issued: float  # sender's wall clock (informative)
    received: float  # this UAV's wall clock
    expires: float  # this UAV's wall clock: received + ttl
    mission_id: str = ""
    state: Literal["granted", "used", "expired", "refused"] = "granted"
    uses: int = 0
    reason: str = ""  # why it was refused, if it was


class PendingAction(msgspec.Struct, frozen=True, kw_only=True):
    action: VehicleActionKind
    since: float  # this UAV's wall clock, first asked
    skill: str = ""  # the skill that wanted it, or "" for the mission launch


class ApprovalStatus(msgspec.Struct, frozen=True, kw_only=True, tag="approval_status"):
    """One UAV -> everyone (``aw/<swarm>/uav/<id>/approval``, also served by query): its
    approval level, the vehicle actions waiting for an operator, and its recent records."""

    h: Header
    uav: str
    level: str
    pending: list[PendingAction] = []
    records: list[ApprovalRecord] = []
    ack: str = ""  # the approval id this status answers, if any


Payload = (
    StateBeacon
    | InboxMessage
    | ProgressReport
    | MissionContext
    | Assignment
    | ExperienceRecord
    | SimPerception
    | SimReward
    | SimCommand
    | SimEpisode
    | CentralAsk
    | CentralReview
    | CentralAnswer
    | WorldSnapshot
    | OperatorCommand
    | Approval
    | ApprovalStatus
)


class Keys:
    """Key expressions of one swarm (DESIGN §3). A UAV writes only under its own prefix or
    in its own slot of a peer's inbox, which keeps access-control rules simple."""

    def __init__(self, swarm: str) -> None:
        self.root = f"aw/{swarm}"

    def alive_uav(self, uav: str = "*") -> str:
        return f"{self.root}/alive/uav/{uav}"

    @property
    def alive_cmdr(self) -> str:
        return f"{self.root}/alive/cmdr"

    @property
    def alive_world(self) -> str:
        """The simulated world's token: a sim-backed daemon that loses it holds and exits."""
        return f"{self.root}/alive/world"

    @property
    def alive_all(self) -> str:
        return f"{self.root}/alive/**"

    def state(self, uav: str = "*") -> str:
        return f"{self.root}/uav/{uav}/state"

    def inbox(self, to: str, sender: str = "*") -> str:
        return f"{self.root}/uav/{to}/inbox/{sender}"

    def broadcast(self, sender: str = "*") -> str:
        """Messages ``sender`` sends to every peer it reaches (one put, under its own prefix)."""
        return f"{self.root}/uav/{sender}/broadcast"

    def report(self, uav: str = "*") -> str:
        return f"{self.root}/uav/{uav}/report"

    def experience(self, uav: str = "*") -> str:
        return f"{self.root}/uav/{uav}/experience"

    @property
    def context(self) -> str:
        return f"{self.root}/cmdr/context"

    def assign(self, uav: str = "*") -> str:
        return f"{self.root}/cmdr/assign/{uav}"

    def sim(self, leaf: str) -> str:
        return f"{self.root}/sim/{leaf}"

    def sim_perception(self, uav: str = "*") -> str:
        return self.sim(f"perception/{uav}")

    def sim_reward(self, uav: str = "*") -> str:
        return self.sim(f"reward/{uav}")

    def sim_command(self, uav: str = "*") -> str:
        """Under the UAV's own prefix: only that UAV may command its simulated body, and
        the access rule stays "a UAV writes only its own keys"."""
        return f"{self.root}/uav/{uav}/sim/command"

    def uav_of(self, key: str) -> str | None:
        """The UAV whose prefix ``key`` is under (``.../uav/<id>/...``), else None."""
        prefix = f"{self.root}/uav/"
        if not key.startswith(prefix):
            return None
        uav = key[len(prefix) :].split("/", 1)[0]
        return uav or None

    @property
    def sim_episode(self) -> str:
        return self.sim("episode")

    def ask(self, uav: str = "*") -> str:
        """A UAV's request to a baseline's central node (under the UAV's own prefix)."""
        return f"{self.root}/uav/{uav}/ask"

    def review(self, uav: str = "*") -> str:
        """A UAV's local review of the central proposal (HMAS-2; own prefix)."""
        return f"{self.root}/uav/{uav}/review"

    def central_answer(self, uav: str = "*") -> str:
        """The central node's proposal or final choice for ``uav``."""
        return f"{self.root}/central/answer/{uav}"

    @property
    def alive_central(self) -> str:
        return f"{self.root}/alive/central"

    @property
    def sim_snapshot(self) -> str:
        """The world after each round, for observers (``WorldSnapshot``)."""
        return self.sim("snapshot")

    @property
    def operator_command(self) -> str:
        """Operator -> Commander: stop the mission (``OperatorCommand``)."""
        return f"{self.root}/operator/command"

    def approval(self, uav: str = "*") -> str:
        """Operator -> one UAV: an approval for a vehicle action (``Approval``)."""
        return f"{self.root}/operator/approval/{uav}"

    def approval_status(self, uav: str = "*") -> str:
        """A UAV's approval level, pending actions and records (``ApprovalStatus``)."""
        return f"{self.root}/uav/{uav}/approval"


def last_chunk(key: str) -> str:
    return key.rsplit("/", 1)[-1]


T = TypeVar("T", bound=msgspec.Struct)


BULK_LEAVES: Final = frozenset({"broadcast", "experience", "state", "report", "approval"})


def traffic_lane(key_expr: str) -> str:
    """``"bulk"`` for peer traffic that may come in floods and can wait a little (messages,
    beacons, experience, reports, approval status); ``"control"`` for the rest (liveliness,
    the world's perceptions, rewards and commands, the Commander's context and assignments,
    a central node's answers), which a receiver serves first (``mesh.py``)."""
    if "/inbox/" in key_expr:
        return "bulk"
    return "bulk" if last_chunk(key_expr) in BULK_LEAVES else "control"


_WRITER_OF_AREA: Final = {"cmdr": "cmdr", "sim": "world", "central": "central",
                           "operator": "operator"}  # fmt: skip


def writer_of(key: str) -> str:
    """Who writes ``key`` under the swarm's key layout (``Keys``): the UAV of its prefix, the
    sender slot of an inbox, the owner of a liveliness token, or the ground node of its
    area; the key itself when it follows no rule. The ACL makes this the real writer in a
    secured swarm; receivers use it to keep one FIFO per sender (``mesh.py``)."""
    parts = key.split("/")
    rest = parts[2:] if len(parts) > 2 else []
    if len(rest) >= 2 and rest[0] == "uav":
        return rest[3] if len(rest) >= 4 and rest[2] == "inbox" else rest[1]
    if len(rest) >= 2 and rest[0] == "alive":
        return rest[2] if rest[1] == "uav" and len(rest) >= 3 else rest[1]
    if rest:
        return _WRITER_OF_AREA.get(rest[0], key)
    return key


class DecodeStats:
    """Counts rejected payloads and keeps the log quiet (one line per reason per interval).
    Thread-safe: a Zenoh callback counts what it drops before it reaches the loop."""

    def __init__(self, log_interval_s: float = 5.0) -> None:
        self.rejected: Counter[str] = Counter()
        self._interval = log_interval_s
        self._last_log: dict[str, float] = {}
        self._lock = threading.Lock()

    @property
    def total(self) -> int:
        return sum(self.rejected.values())

    def reject(self, reason: str, key: str, detail: str = "") -> None:
        """Count under ``reason``, a fixed category: payload-derived text goes in ``detail``
        (logged only), so a flood of distinct bad payloads cannot grow the counter or
        defeat the rate limit."""
        with self._lock:
            self.rejected[reason] += 1
            now = time.monotonic()
            if now - self._last_log.get(reason, -1e9) < self._interval:
                return
            self._last_log[reason] = now
        log.warning(
            "dropped payload on %s: %s%s (%d so far)",
            key,
            reason,
            f": {detail[:80]}" if detail else "",
            self.rejected[reason],
        )


class Codec:
    """Encodes our structs; decodes bytes into an expected type or ``None``."""

    def __init__(self, stats: DecodeStats | None = None) -> None:
        self.stats = stats or DecodeStats()
        self._encoder = msgspec.msgpack.Encoder()
        self._decoders: dict[type[Any], msgspec.msgpack.Decoder[Any]] = {}

    def encode(self, msg: msgspec.Struct) -> bytes:
        data = self._encoder.encode(msg)
        if len(data) > MAX_PAYLOAD_BYTES:
            raise ValueError(f"{type(msg).__name__} is {len(data)} bytes, cap {MAX_PAYLOAD_BYTES}")
        return data

    def decode(self, data: bytes, kind: type[T], key: str = "?") -> T | None:
        if len(data) > MAX_PAYLOAD_BYTES:
            self.stats.reject("oversize", key)
            return None
        decoder = self._decoders.get(kind)
        if decoder is None:
            decoder = self._decoders[kind] = msgspec.msgpack.Decoder(kind)
        try:
            msg: T = decoder.decode(data)
        except msgspec.ValidationError as exc:
            self.stats.reject(f"invalid {kind.__name__}", key, str(exc))
            return None
        except (msgspec.DecodeError, ValueError) as exc:
            # ValueError: msgspec raises UnicodeDecodeError for a str that is not UTF-8.
            self.stats.reject(f"undecodable {kind.__name__}", key, str(exc))
            return None
        header = getattr(msg, "h", None)
        if isinstance(header, Header) and header.v != SCHEMA_VERSION:
            self.stats.reject("schema version", key, f"v{header.v}")
            return None
        return msg


_epoch_lock = threading.Lock()
_last_epoch = 0


def boot_epoch() -> int:
    """A default boot epoch: wall-clock nanoseconds, made strictly increasing within the
    process (two factories never share one, even on a coarse clock) and, as time goes on,
    across restarts. A persisted boot counter (``mesh.secured``) is the stronger kind."""
    global _last_epoch
    with _epoch_lock:
        _last_epoch = max(time.time_ns(), _last_epoch + 1)
        return _last_epoch


class HeaderFactory:
    """Stamps outgoing payloads with sender, boot epoch and a strictly increasing sequence."""

    def __init__(self, sender: str, epoch: int | None = None) -> None:
        self.sender = sender
        self.epoch = epoch if epoch is not None else boot_epoch()
        self._seq = 0

    def next(self, ttl_s: float = 10.0) -> Header:
        self._seq += 1
        return Header(
            sender=self.sender, epoch=self.epoch, seq=self._seq, stamp=time.time(), ttl_s=ttl_s
        )

    @property
    def last_seq(self) -> int:
        return self._seq


@dataclass
class _Window:
    epoch: int
    seen: float  # monotonic time of the last accepted message (any stream)
    seqs: dict[str, int]  # last accepted seq per stream, within this epoch
    released: bool = False


class ReplayFilter:
    """Delivers each (sender, epoch, seq) at most once, in increasing order per sender.

    Streams (e.g. ``"inbox"`` and ``"beacon"``) keep their own sequence order but share the
    sender's epoch, so whatever was heard first from a sender fixes its epoch for all of
    them. A newer epoch means the sender restarted. An *authenticated* epoch (a signature
    covers the header) is taken at once. An unauthenticated one could be forged, and a
    forged future epoch would otherwise lock the genuine sender out, so it moves the window
    only once the current epoch is over (the sender's session ended, ``release``, or it has
    been silent for ``quiet_s``) and, with ``max_epoch_step`` (boot counters count restarts,
    so a genuine step is small), never by more than that.
    """

    def __init__(
        self,
        *,
        quiet_s: float = 5.0,
        max_epoch_step: int | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.quiet_s = quiet_s
        self.max_epoch_step = max_epoch_step
        self._clock = clock
        self._latest: dict[str, _Window] = {}

    def check(self, header: Header, *, authenticated: bool = False, stream: str = "") -> str | None:
        """``None`` if delivered (and recorded); otherwise why not: ``replay``,
        ``old_epoch``, ``epoch_jump`` or ``epoch_contested``."""
        now = self._clock()
        prev = self._latest.get(header.sender)
        if prev is not None and header.epoch == prev.epoch:
            if header.seq <= prev.seqs.get(stream, -1):
                return "replay"
            prev.seqs[stream] = header.seq
            prev.seen = now
            return None
        if prev is not None:
            if header.epoch < prev.epoch:
                return "old_epoch"
            if not authenticated:
                if self.max_epoch_step is not None and (
                    header.epoch - prev.epoch > self.max_epoch_step
                ):
                    return "epoch_jump"
                if not prev.released and now - prev.seen < self.quiet_s:
                    return "epoch_contested"
        self._latest[header.sender] = _Window(header.epoch, now, {stream: header.seq})
        return None

    def would_refuse(self, header: Header, *, stream: str = "") -> str | None:
        """What ``check`` would certainly say without recording anything: ``replay`` (this
        epoch, a sequence number already passed) or ``old_epoch``; None otherwise. Cheap,
        so receivers run it before verifying a signature."""
        prev = self._latest.get(header.sender)
        if prev is None:
            return None
        if header.epoch == prev.epoch:
            return "replay" if header.seq <= prev.seqs.get(stream, -1) else None
        return "old_epoch" if header.epoch < prev.epoch else None

    def accept(self, header: Header, *, authenticated: bool = False, stream: str = "") -> bool:
        return self.check(header, authenticated=authenticated, stream=stream) is None

    def epoch_of(self, sender: str) -> int | None:
        window = self._latest.get(sender)
        return window.epoch if window is not None else None

    def release(self, sender: str) -> None:
        """The sender's session ended (its liveliness token went away): its next epoch may
        take over without waiting for ``quiet_s``. Older epochs stay refused."""
        window = self._latest.get(sender)
        if window is not None:
            window.released = True
