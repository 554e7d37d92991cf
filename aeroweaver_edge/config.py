"""Typed configuration for daemons, the Commander and the simulator.

Every section is a pydantic model with ``extra="forbid"`` so a typo in a TOML file is an
error naming the key, not a silently ignored setting.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

_ID_CHARS = set("abcdefghijklmnopqrstuvwxyz0123456789_-")


def _check_id(value: str, what: str) -> str:
    if not value or not set(value) <= _ID_CHARS or value[0] == "@":
        raise ValueError(
            f"{what} {value!r} must be non-empty lowercase letters, digits, '_' or '-'"
        )
    return value


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class MeshConfig(_Section):
    """Zenoh session settings; defaults suit a loopback CI mesh (see notes/zenoh.md)."""

    mode: Literal["peer", "client", "router"] = "peer"
    listen: list[str] = Field(default_factory=lambda: ["tcp/127.0.0.1:0"])
    connect: list[str] = Field(default_factory=list)
    gossip: bool = True
    multicast: bool = False
    namespace: str | None = None
    lease_ms: int = Field(default=10_000, ge=500)
    comm_radius_m: float = Field(default=55.0, gt=0)
    # Raw zenoh config overrides, path -> JSON5 value, applied last (escape hatch).
    zenoh_overrides: dict[str, str] = Field(default_factory=dict)


class LLMConfig(_Section):
    """An OpenAI-compatible endpoint. ``base_url = None`` means the embedded model."""

    base_url: str | None = None
    model: str = "smollm2-135m-instruct"
    api_key_env: str | None = None
    extra_body: dict[str, Any] = Field(default_factory=dict)
    deadline_s: float = Field(default=20.0, gt=0)
    connect_timeout_s: float = Field(default=2.0, gt=0)
    retries: int = Field(default=1, ge=0, le=5)
    breaker_failures: int = Field(default=3, ge=1)
    breaker_reset_s: float = Field(default=10.0, gt=0)
    top_logprobs: int = Field(default=20, ge=1, le=20)
    temperature: float = Field(default=0.0, ge=0)
    # llama-server cache slot this daemon's decisions pin to (sent as ``id_slot``), so its
    # prompt prefix stays in its own KV cache. None: let the server choose (hosted APIs).
    slot: int | None = Field(default=None, ge=0)


class AgentConfig(_Section):
    """The selector and its experience memory (paper defaults)."""

    selector: Literal["llm", "scripted"] = "llm"
    beta: float = Field(default=0.8, ge=0)
    gamma: float = Field(default=0.95, ge=0, le=1)
    neighbourhood: int = Field(default=32, ge=1)
    memory_path: str | None = None  # None: in-memory SQLite (lost on exit)
    share_experience: bool = True
    max_labels: int = Field(default=26, ge=2, le=26)
    # Interaction history in the agent's context (paper §3.2): its own recent decisions and
    # rewards, in blocks of this many rounds so the prompt stays append-only. 0: none.
    history_rounds: int = Field(default=8, ge=0, le=64)
    # The state text for experience retrieval holds received peer messages and the mission
    # context (role, goal, private facts) as in paper §3.3. False: pose and entities only.
    state_context: bool = True


class SafetyConfig(_Section):
    """The physical envelope every command must fit, whatever chose it."""

    # NaN/inf would silently open the envelope (``max(x, nan)`` is ``x``; ``inf`` is no cap).
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    geofence_north_m: tuple[float, float] = (-70.0, 70.0)
    geofence_east_m: tuple[float, float] = (-70.0, 70.0)
    altitude_band_m: tuple[float, float] = (2.0, 60.0)
    max_speed_mps: float = Field(default=11.0, gt=0)
    min_separation_m: float = Field(default=2.0, ge=0)

    @field_validator("geofence_north_m", "geofence_east_m", "altitude_band_m")
    @classmethod
    def _ordered(cls, value: tuple[float, float]) -> tuple[float, float]:
        if value[0] >= value[1]:
            raise ValueError(f"lower bound {value[0]} must be below upper bound {value[1]}")
        return value


class VehicleConfig(_Section):
    backend: Literal["sim", "mavlink", "mavsdk"] = "sim"
    url: str | None = None  # e.g. udpin://0.0.0.0:14540 for mavlink
    altitude_m: float = Field(default=5.0, gt=0)  # mission flight level


class UavConfig(_Section):
    """One daemon: ``aeroweaver daemon --config uav.toml``."""

    uav: str
    swarm: str = "default"
    index: int | None = Field(default=None, ge=0)  # None: the trailing digits of the id
    round_s: float = Field(default=0.5, gt=0)
    mesh: MeshConfig = MeshConfig()
    llm: LLMConfig = LLMConfig()
    agent: AgentConfig = AgentConfig()
    safety: SafetyConfig = SafetyConfig()
    vehicle: VehicleConfig = VehicleConfig()

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
    uavs: int = Field(default=3, ge=1, le=10)
    seed: int = 1
    max_rounds: int = Field(default=24, ge=1)
    round_s: float = Field(default=0.5, gt=0)
    deadline_s: float = Field(default=30.0, gt=0)
    sensing_radius_m: float = Field(default=45.0, gt=0)
    altitude_m: float = Field(default=5.0, gt=0)
    max_speed_mps: float = Field(default=11.0, gt=0)
    max_accel_mps2: float = Field(default=30.0, gt=0)


class ConfigError(ValueError):
    """A config file could not be used; the message names the file and the key."""


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
        problems = "; ".join(f"{_loc(e['loc'])}: {e['msg']}" for e in exc.errors())
        raise ConfigError(f"{source}: {problems}") from None


def load_config(path: str | Path, model: type[M]) -> M:
    """Read a TOML (or, by suffix, JSON) file into ``model``; any problem is a ``ConfigError``."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        data = json.loads(text) if path.suffix == ".json" else tomllib.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(
            f"{path}: not valid {path.suffix.lstrip('.').upper() or 'TOML'}: {exc}"
        ) from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a table of settings")
    return parse_config(data, model, str(path))
