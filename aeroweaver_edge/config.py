"""Typed configuration for daemons, the Commander and the simulator.

Every section is a pydantic model with ``extra="forbid"`` so a typo in a TOML file is an
error naming the key, not a silently ignored setting. Every number is finite (``Finite``,
and no section accepts inf/NaN) and bounded on both sides: TOML reads ``inf``, ``nan`` and
2^63-1 as readily as 0.5, and an unbounded timeout, lease or radius is a silent "never"
(``round_s = inf`` starts a daemon that never decides). The bounds are wide enough for any
real deployment and are listed in docs/reliability.md.
"""

from __future__ import annotations

import ipaddress
import json
import tomllib
from pathlib import Path
from typing import Annotated, Any, Final, Literal, Self, TypeVar

from pydantic import (
    AllowInfNan,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from aeroweaver_edge.contracts import defaults as d
from aeroweaver_edge.contracts.endpoints import UdpUrl, endpoint_problem
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.contracts.selector_specs import EstimatorSpec, ScriptedBaseSpec

_ID_CHARS = set("abcdefghijklmnopqrstuvwxyz0123456789_-")
_RUN_CHARS = _ID_CHARS | set("ABCDEFGHIJKLMNOPQRSTUVWXYZ.:")

MAX_UAVS = d.MAX_UAVS
"""Largest simulated swarm (``aeroweaver sim --uavs``, ``SimConfig.uavs``): the one bound."""

# Documented bounds of the safety envelope (docs/reliability.md). Anything outside is a
# typo or a unit mistake, never a real envelope: a fence of +-1e9 m or a 1e6 m/s cap is no
# fence and no cap, and a zero separation turns collision avoidance off.
GEOFENCE_LIMIT_M = 10_000.0  # every geofence bound within +-10 km of home
ALTITUDE_LIMIT_M = 1_500.0  # altitude band within 0 .. 1500 m
MAX_SPEED_LIMIT_MPS = 60.0  # speed cap within (0, 60] m/s
SEPARATION_RANGE_M = (0.5, 100.0)  # minimum separation within 0.5 .. 100 m

Finite = Annotated[float, AllowInfNan(False)]
"""A float that is a number: inf and NaN are refused wherever a config holds one."""

# Upper bounds shared by many fields: generous for any real deployment, yet finite.
MAX_WAIT_S: Final = 3600.0  # any timeout, deadline, lease or grace: an hour at most
MAX_ROUND_S: Final = 60.0  # one decision round (the paper's is 0.5 s)
MAX_RANGE_M: Final = 100_000.0  # any radius or range (sensing, communication): 100 km
MAX_ROUNDS: Final = 100_000  # an episode's horizon
MAX_SEED: Final = 2**32 - 1  # what every random generator takes
MAX_BETA: Final = 100.0  # the experience correction weight (paper: 0.8)
MAX_NEIGHBOURHOOD: Final = 4096  # experience records retrieved per decision
MAX_SLOT: Final = 1023  # llama-server cache slots
MAX_LEASE_MS: Final = 600_000  # Zenoh link lease: 10 minutes
MAX_EXTRA_BODY_CHARS: Final = 16_384  # [llm] extra_body, as JSON


def _check_id(value: str, what: str) -> str:
    if not value or not set(value) <= _ID_CHARS or value[0] == "@":
        raise ValueError(
            f"{what} {value!r} must be non-empty lowercase letters, digits, '_' or '-'"
        )
    return value


def check_id(value: str, what: str) -> str:
    """Validate an identifier (UAV, swarm or process identity name); raises ValueError."""
    return _check_id(value, what)


class _Section(BaseModel):
    # allow_inf_nan=False: a float field without ``Finite`` is still refused inf/NaN.
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class SecurityConfig(_Section):
    """``[mesh.security]``: this process's identity and key material (``aeroweaver keys
    init`` writes it). With it every link is TLS with mutual authentication, the Zenoh ACL
    is built from the CA-signed identity list, and payloads are signed and verified."""

    identity: str  # this process's name = its certificate's CN (uav0, cmdr, world, ...)
    ca: str  # swarm CA certificate (PEM)
    cert: str  # this identity's TLS certificate (PEM)
    key: str  # its TLS private key (PEM, 0600)
    identities: str  # the CA-signed identity list (identities.json)
    signing_key: str | None = None  # Ed25519 key (PEM, 0600); None: this process signs nothing
    acl: bool = True  # load the Zenoh ACL generated from the identity list
    sign: bool = True  # sign what we publish; accept only signed payloads by allowed authors
    verify_name: bool = True  # TLS: the peer's certificate must name the address we dial
    state_dir: str | None = None  # persisted boot counter (a restart is a new epoch)

    @field_validator("identity")
    @classmethod
    def _identity(cls, value: str) -> str:
        return _check_id(value, "identity")


_SECURE_PROTOCOLS = frozenset({"tls", "quic"})
_LOCAL_PROTOCOLS = frozenset({"unixsock-stream", "unixpipe", "serial", "vsock"})


def endpoint_is_secure(endpoint: str) -> bool:
    return endpoint.split("/", 1)[0] in _SECURE_PROTOCOLS


def endpoint_is_loopback(endpoint: str) -> bool:
    """True if a ``proto/host:port[#opts]`` endpoint stays on this machine."""
    proto, _, rest = endpoint.partition("/")
    if proto in _LOCAL_PROTOCOLS:
        return True
    address = rest.split("#", 1)[0].split("?", 1)[0]
    host = address.rsplit(":", 1)[0] if ":" in address else address
    host = host.strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False  # a host name: it may resolve anywhere


_PROTECTED_OVERRIDES = ("transport/link/tls", "access_control", "transport/auth")


class MeshConfig(_Section):
    """Zenoh session settings; defaults suit a loopback CI mesh (see docs/notes/zenoh.md)."""

    mode: Literal["peer", "client", "router"] = "peer"
    listen: list[str] = Field(default_factory=lambda: ["tcp/127.0.0.1:0"])
    connect: list[str] = Field(default_factory=list)
    gossip: bool = True
    multicast: bool = False
    namespace: str | None = None
    lease_ms: int = Field(default=10_000, ge=500, le=MAX_LEASE_MS)
    comm_radius_m: Finite = Field(default=d.COMM_RADIUS_M, gt=0, le=MAX_RANGE_M)
    # Raw zenoh config overrides, path -> JSON5 value, applied last (escape hatch).
    zenoh_overrides: dict[str, str] = Field(default_factory=dict)
    security: SecurityConfig | None = None
    # Allow plain (unauthenticated, unencrypted) links off this machine. Never in the field.
    insecure: bool = False

    @model_validator(mode="after")
    def _secure_endpoints(self) -> Self:
        """A field config never listens or dials without TLS, and a secured one never opens
        a side door (a plain endpoint, or overrides that replace its TLS or ACL settings)."""
        for field_name in ("listen", "connect"):
            for i, ep in enumerate(getattr(self, field_name)):
                where = f"{field_name}[{i}] {ep!r}"
                why = endpoint_problem(ep, "listen" if field_name == "listen" else "connect")
                if why is not None:
                    raise ValueError(f"mesh.{where}: {why}")
                if self.security is not None and not endpoint_is_secure(ep):
                    raise ValueError(
                        f"{where}: with [mesh.security] every endpoint is tls/ or quic/"
                    )
                if self.security is None and endpoint_is_secure(ep):
                    raise ValueError(
                        f"{where}: a tls/ endpoint needs [mesh.security] (aeroweaver keys init)"
                    )
                if self.security is None and not self.insecure and not endpoint_is_loopback(ep):
                    raise ValueError(
                        f"{where}: plain link off this machine; add [mesh.security] "
                        "(aeroweaver keys init) or set insecure = true"
                    )
        if self.security is not None:
            for path in self.zenoh_overrides:
                if path.strip("/").startswith(_PROTECTED_OVERRIDES):
                    raise ValueError(f"zenoh_overrides[{path!r}]: set by [mesh.security]")
        return self


class LLMConfig(_Section):
    """An OpenAI-compatible endpoint. ``base_url = None`` means the embedded model."""

    base_url: str | None = None
    model: str = "smollm2-135m-instruct"
    api_key_env: str | None = None
    extra_body: dict[str, Any] = Field(default_factory=dict)
    deadline_s: Finite = Field(default=20.0, gt=0, le=MAX_WAIT_S)
    connect_timeout_s: Finite = Field(default=2.0, gt=0, le=MAX_WAIT_S)
    retries: int = Field(default=1, ge=0, le=5)
    breaker_failures: int = Field(default=3, ge=1, le=1000)
    breaker_reset_s: Finite = Field(default=10.0, gt=0, le=MAX_WAIT_S)
    top_logprobs: int = Field(default=20, ge=1, le=20)
    temperature: Finite = Field(default=0.0, ge=0, le=2.0)  # OpenAI's range
    # llama-server cache slot this daemon's decisions pin to (sent as ``id_slot``), so its
    # prompt prefix stays in its own KV cache. None: let the server choose (hosted APIs).
    slot: int | None = Field(default=None, ge=0, le=MAX_SLOT)

    @field_validator("extra_body")
    @classmethod
    def _extra_body(cls, value: dict[str, Any]) -> dict[str, Any]:
        """Goes into every request body as JSON: no inf/NaN (invalid JSON), bounded size."""
        try:
            text = json.dumps(value, allow_nan=False)
        except ValueError:
            raise ValueError("holds inf or nan, which JSON cannot carry") from None
        except (TypeError, RecursionError):
            raise ValueError("is not plain JSON data") from None
        if len(text) > MAX_EXTRA_BODY_CHARS:
            raise ValueError(f"is {len(text)} characters as JSON, at most {MAX_EXTRA_BODY_CHARS}")
        return value


class AgentConfig(_Section):
    """The selector and its experience memory (paper defaults)."""

    # llm: this UAV's own LLM; scripted: the task's reference policy; centralized / hmas2:
    # a baseline's central node decides (aeroweaver_lab.baselines), the UAV still executes.
    selector: Literal["llm", "scripted", "centralized", "hmas2"] = "llm"
    beta: Finite = Field(default=d.BETA, ge=0, le=MAX_BETA)
    gamma: Finite = Field(default=d.GAMMA, ge=0, le=1)
    neighbourhood: int = Field(default=d.NEIGHBOURHOOD, ge=1, le=MAX_NEIGHBOURHOOD)
    memory_path: str | None = None  # None: in-memory SQLite (lost on exit)
    # A configured memory that cannot be opened or written stops the daemon with a clear
    # error; false: it runs on with memory in RAM / dropped writes (and says so in the log).
    memory_required: bool = True
    # Run identity stamped on every record (the simulator gives its daemons one per run);
    # None: a new one at each daemon start, so runs never collide in a shared memory file.
    run_id: str | None = Field(default=None, min_length=1, max_length=64)
    share_experience: bool = True
    # When a daemon shares: "episode" (its finalised records as an episode ends) or "round"
    # (each record, with its round's reward, as it happens; the finalised ones still follow
    # at the episode's end): peers retrieve it from their next round on (docs/adaptation.md).
    share_every: Literal["episode", "round"] = "episode"
    max_labels: int = Field(default=26, ge=2, le=26)
    # Interaction history in the agent's context (paper §3.2): its own recent decisions and
    # rewards, in blocks of this many rounds so the prompt stays append-only. 0: none.
    history_rounds: int = Field(default=d.HISTORY_ROUNDS, ge=0, le=64)
    # The state text for experience retrieval holds received peer messages and the mission
    # context (role, goal, private facts) as in paper §3.3. False: pose and entities only.
    state_context: bool = True
    # Send coordination reports (intent, target, status) to peers. False (an ablation):
    # only task-required messages (goal, ciphertext) go out.
    coordination_reports: bool = True
    # Experience retrieval uses only finalised returns (trajectories that ended), not the
    # in-flight ones of the current episode (agent.memory, docs/adaptation.md).
    finalised_only: bool = False
    # How experience becomes an advantage (agent.estimators, docs/adaptation.md): "paper"
    # (the paper's rule), or horizon:H, centre, support:M, shrink:K, scale|tscore, comma-joined.
    # AEROWEAVER_ESTIMATOR, when set, overrides it (docs/configuration.md).
    estimator: str = "paper"
    # The scripted selector's base (agent.scripted): "reference" (the task's heuristic) or a
    # degraded testbed: hold-biased, position-biased, noisy[:SD], each optionally @T.
    # AEROWEAVER_SCRIPTED_BASE, when set, overrides it.
    scripted_base: str = "reference"

    @field_validator("estimator")
    @classmethod
    def _estimator(cls, value: str) -> str:
        return EstimatorSpec.parse(value).name  # ValueError: one line with the allowed forms

    @field_validator("scripted_base")
    @classmethod
    def _scripted_base(cls, value: str) -> str:
        return ScriptedBaseSpec.parse(value).name

    @field_validator("run_id")
    @classmethod
    def _run_id(cls, value: str | None) -> str | None:
        if value is not None and not set(value) <= _RUN_CHARS:
            raise ValueError(f"run id {value!r} may hold only letters, digits and _ - . :")
        return value


class SafetyConfig(_Section):
    """The physical envelope every command must fit, whatever chose it."""

    # NaN/inf would silently open the envelope (``max(x, nan)`` is ``x``; ``inf`` is no cap).
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    geofence_north_m: tuple[Finite, Finite] = (-d.ARENA_HALF_M, d.ARENA_HALF_M)
    geofence_east_m: tuple[Finite, Finite] = (-d.ARENA_HALF_M, d.ARENA_HALF_M)
    altitude_band_m: tuple[Finite, Finite] = (2.0, 60.0)
    max_speed_mps: Finite = Field(default=d.MAX_SPEED_MPS, gt=0, le=MAX_SPEED_LIMIT_MPS)
    min_separation_m: Finite = Field(
        default=d.MIN_SEPARATION_M, ge=SEPARATION_RANGE_M[0], le=SEPARATION_RANGE_M[1]
    )

    @field_validator("geofence_north_m", "geofence_east_m", "altitude_band_m")
    @classmethod
    def _ordered(cls, value: tuple[float, float]) -> tuple[float, float]:
        if value[0] >= value[1]:
            raise ValueError(f"lower bound {value[0]} must be below upper bound {value[1]}")
        return value

    @field_validator("geofence_north_m", "geofence_east_m")
    @classmethod
    def _fence_bounded(cls, value: tuple[float, float]) -> tuple[float, float]:
        if max(abs(value[0]), abs(value[1])) > GEOFENCE_LIMIT_M:
            raise ValueError(f"{list(value)} reaches beyond +-{GEOFENCE_LIMIT_M:g} m of home")
        return value

    @field_validator("altitude_band_m")
    @classmethod
    def _band_bounded(cls, value: tuple[float, float]) -> tuple[float, float]:
        if value[0] < 0 or value[1] > ALTITUDE_LIMIT_M:
            raise ValueError(f"{list(value)} must lie within 0 .. {ALTITUDE_LIMIT_M:g} m")
        return value


class VehicleConfig(_Section):
    """The UAV's own autopilot link and flight phases (docs/flight.md)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    backend: Literal["sim", "mavlink", "mavsdk"] = "sim"
    # mavlink: udpin://0.0.0.0:14540 (the autopilot sends to us) or udpout://HOST:PORT;
    # mavsdk: any MAVSDK connection URL (udpin://, udpout://, tcpout://, serial://).
    url: str | None = None
    altitude_m: Finite = Field(default=d.ALTITUDE_M, gt=0, le=120)  # flight level (take-off)
    personality: Literal["auto", "px4", "ardupilot"] = "auto"  # auto: from the heartbeat
    sysid: int | None = Field(default=None, ge=1, le=255)  # None: from the vehicle heartbeat
    signing_key: str | None = None  # MAVLink 2 key file (0600); timestamp kept beside it
    setpoint_hz: Finite = Field(default=20.0, ge=10.0, le=100.0)
    lease_s: Finite = Field(default=2.0, gt=0, le=120.0)  # agent silence before autopilot hold
    link_timeout_s: Finite = Field(default=2.5, ge=1.5, le=10.0)  # one lost 1 Hz heartbeat is ok
    connect_timeout_s: Finite = Field(default=15.0, gt=0, le=MAX_WAIT_S)
    command_timeout_s: Finite = Field(default=0.5, gt=0, le=10.0)  # per try, before a retry
    command_retries: int = Field(default=4, ge=0, le=10)
    failsafe_policy: Literal["warn", "refuse"] = "refuse"  # autopilot failsafe check at connect
    # What the autopilot does when this daemon falls silent (SIGKILL, SIGSTOP, a hung loop):
    # set at preflight (ArduPilot GCS failsafe with the daemon as GCS, PX4 offboard loss);
    # "check" writes nothing and only verifies. The daemon refuses to arm without it.
    companion_failsafe: Literal["land", "return", "check"] = "land"
    companion_loss_s: Finite = Field(default=3.0, ge=2.0, le=5.0)  # silence before the action
    # The swarm's shared local frame, [lat, lon, alt_m]: every vehicle's own local frame
    # (centred where its autopilot booted) is shifted into it, so positions, peers' beacons,
    # [field] points and the fence agree across vehicles. Unset: the autopilot's own frame.
    origin: tuple[Finite, Finite, Finite] | None = None
    upload_fence: bool = True  # the safety geofence, uploaded as the autopilot's fence
    end_action: Literal["land", "return"] = "land"  # at mission end or operator stop
    on_link_loss: Literal["failsafe", "land", "return"] = "failsafe"  # when the link is back
    takeoff_timeout_s: Finite = Field(default=60.0, gt=0, le=MAX_WAIT_S)
    # Clock, perception and rewards from the simulated world (lockstep) while the vehicle
    # flies over MAVLink/MAVSDK: ``aeroweaver sim --link mavlink``. Always on for "sim".
    sim_world: bool = False
    # A daemon flying in the simulated world holds when the world's liveliness token goes
    # and stops if it is not back within this grace (a partition shorter than this heals).
    world_grace_s: Finite = Field(default=10.0, gt=0, le=MAX_WAIT_S)

    @field_validator("origin")
    @classmethod
    def _origin_on_earth(
        cls, value: tuple[float, float, float] | None
    ) -> tuple[float, float, float] | None:
        if value is not None and not (
            -90 <= value[0] <= 90 and -180 <= value[1] <= 180 and -500 <= value[2] <= 10_000
        ):
            raise ValueError(
                f"{list(value)} is not [latitude, longitude, altitude_m] "
                "(-90..90, -180..180, -500..10000)"
            )
        return value

    @model_validator(mode="after")
    def _link(self) -> VehicleConfig:
        if self.backend == "sim":
            return self
        if self.url is None:
            raise ValueError(
                f"url is required for backend {self.backend!r}, e.g. udpin://0.0.0.0:14540"
            )
        if self.backend == "mavlink":
            UdpUrl.parse(self.url)
        elif "://" not in self.url:
            raise ValueError(f"url {self.url!r} is not a MAVSDK connection URL (scheme://...)")
        if self.lease_s < 2.0 / self.setpoint_hz:
            raise ValueError(f"lease_s {self.lease_s} is shorter than two setpoint periods")
        return self


class ApprovalConfig(_Section):
    """``[approval]``: operator approval for vehicle actions (``aeroweaver_edge.safety.approval``).
    normal: take-off needs one approval per mission, land and return none (docs/notes/safety.md);
    strict: every take-off (the mission launch too), landing and return needs its own."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    level: Literal["normal", "strict"] = "normal"
    # Identities whose approvals count (their signatures are checked when the mesh is secured).
    approvers: list[str] = Field(default_factory=lambda: ["operator"], min_length=1, max_length=16)
    max_ttl_s: Finite = Field(default=3600.0, gt=0, le=86_400)  # longer approvals are cut to this

    @field_validator("approvers")
    @classmethod
    def _approver_ids(cls, value: list[str]) -> list[str]:
        return [_check_id(v, "approver") for v in value]


class FieldPoint(_Section):
    """A known point of interest for a daemon flying without a simulator."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    id: str = Field(min_length=1, max_length=64)
    kind: Literal["landmark", "waypoint"] = "waypoint"
    north: Finite = Field(ge=-GEOFENCE_LIMIT_M, le=GEOFENCE_LIMIT_M)
    east: Finite = Field(ge=-GEOFENCE_LIMIT_M, le=GEOFENCE_LIMIT_M)


class FieldConfig(_Section):
    """Rounds on the wall clock and perception from telemetry + peers' beacons (no sim)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    round_deadline_s: Finite = Field(default=25.0, gt=0, le=MAX_WAIT_S)  # an LLM round's time
    sensing_radius_m: Finite = Field(default=d.SENSING_RADIUS_M, gt=0, le=MAX_RANGE_M)
    beacon_max_age_s: Finite = Field(default=3.0, gt=0, le=MAX_WAIT_S)  # by local receipt time
    points: list[FieldPoint] = Field(default_factory=list, max_length=256)


class UavConfig(_Section):
    """One daemon: ``aeroweaver daemon --config uav.toml``."""

    uav: str
    swarm: str = "default"
    index: int | None = Field(default=None, ge=0, le=65_535)  # None: the id's trailing digits
    round_s: Finite = Field(default=d.ROUND_S, gt=0, le=MAX_ROUND_S)
    mesh: MeshConfig = MeshConfig()
    llm: LLMConfig = LLMConfig()
    agent: AgentConfig = AgentConfig()
    safety: SafetyConfig = SafetyConfig()
    vehicle: VehicleConfig = VehicleConfig()
    field: FieldConfig = FieldConfig()
    approval: ApprovalConfig = ApprovalConfig()

    @field_validator("uav")
    @classmethod
    def _uav_id(cls, value: str) -> str:
        return _check_id(value, "uav id")

    @property
    def uav_index(self) -> int:
        if self.index is not None:
            return self.index
        digits = self.uav[len(self.uav.rstrip("0123456789")) :]
        return int(digits) if digits else 0

    @field_validator("swarm")
    @classmethod
    def _swarm_id(cls, value: str) -> str:
        return _check_id(value, "swarm id")


class SimConfig(_Section):
    """A simulated episode: world settings shared by the world and the runner."""

    task: str = "coverage"
    uavs: int = Field(default=3, ge=1, le=MAX_UAVS)
    seed: int = Field(default=1, ge=0, le=MAX_SEED)
    max_rounds: int = Field(default=d.MAX_ROUNDS, ge=1, le=MAX_ROUNDS)
    round_s: Finite = Field(default=d.ROUND_S, gt=0, le=MAX_ROUND_S)
    deadline_s: Finite = Field(default=d.DEADLINE_S, gt=0, le=MAX_WAIT_S)
    sensing_radius_m: Finite = Field(default=d.SENSING_RADIUS_M, gt=0, le=MAX_RANGE_M)
    altitude_m: Finite = Field(default=d.ALTITUDE_M, gt=0, le=ALTITUDE_LIMIT_M)
    max_speed_mps: Finite = Field(default=d.MAX_SPEED_MPS, gt=0, le=MAX_SPEED_LIMIT_MPS)
    max_accel_mps2: Finite = Field(default=d.MAX_ACCEL_MPS2, gt=0, le=1000.0)
    # Wall-clock floor per round (0: as fast as the daemons decide). The console sets the
    # paper's 0.5 s so a scripted run can be watched; results do not depend on it.
    pace_s: Finite = Field(default=0.0, ge=0, le=60)


class ConfigError(UserError):
    """A config file could not be used; the message names the file and the key, ``fix``
    (when there is a better one than "correct that setting") says what to do."""

    def __init__(self, message: str, fix: str = "") -> None:
        ValueError.__init__(self, message)  # str(): the message alone; explain adds the fix
        self.cause = message
        self.fix = fix

    def explain(self) -> tuple[int, str]:
        fix = (
            self.fix or "correct that setting (keys: configs/uav.toml; bounds: docs/reliability.md)"
        )
        return 2, f"config error: {self}; {fix}"


M = TypeVar("M", bound=BaseModel)


def _loc(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<root>"


def parse_config(data: dict[str, Any], model: type[M], source: str = "<config>") -> M:
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        problems = "; ".join(
            f"{_loc(e['loc'])}: {e['msg'].removeprefix('Value error, ')}" for e in exc.errors()
        )
        raise ConfigError(f"{source}: {problems}") from None


def load_config(path: str | Path, model: type[M]) -> M:
    """Read a TOML (or, by suffix, JSON) file into ``model``; any problem is a ``ConfigError``."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset {exc.start})",
            "save the file as UTF-8",
        ) from None
    try:
        data = json.loads(text) if path.suffix == ".json" else tomllib.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(
            f"{path}: not valid {path.suffix.lstrip('.').upper() or 'TOML'}: {exc}"
        ) from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a table of settings")
    return parse_config(data, model, str(path))
