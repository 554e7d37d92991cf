"""A complete, commented ``uav.toml``: every setting ``config.UavConfig`` knows, in every
section, written out with its value and a comment, so an operator edits a file that shows
what exists instead of guessing keys. Unset optional settings are written commented out.

The sections and keys come from the pydantic models themselves, so a setting added to
``config.py`` appears here too (with a pointer to config.py until it gets a comment below);
the test reads the file back and compares it with the config it was rendered from.
"""

from __future__ import annotations

import json
import textwrap
from typing import Any, Literal

from pydantic import BaseModel

Vehicle = Literal["sim", "emulator", "sitl", "mavlink", "mavsdk"]
VEHICLES: tuple[Vehicle, ...] = ("sim", "emulator", "sitl", "mavlink", "mavsdk")
VEHICLE_PORT = 14540  # PX4 SITL convention: instance i sends MAVLink to 14540 + i
# The emulator flies in an empty field: these are the demo's landmarks (configs/uav-emulator.toml).
DEMO_POINTS: tuple[dict[str, Any], ...] = (
    {"id": "L0", "kind": "landmark", "north": 12.0, "east": 8.0},
    {"id": "L1", "kind": "landmark", "north": -6.0, "east": 20.0},
    {"id": "L2", "kind": "landmark", "north": 18.0, "east": -10.0},
)

HEADER_SECTIONS = ("llm", "agent", "safety", "vehicle", "field", "approval")
"""The sections the header tells the operator to edit (each is written below)."""

# "section.key" -> (comment, example written when the value is unset). Keep to one idea each.
COMMENTS: dict[str, tuple[str, str]] = {
    "uav": ("this daemon's UAV id (= its certificate's CN)", ""),
    "swarm": ("the swarm id: every key is under aw/<swarm>/", ""),
    "index": ("position in the swarm; unset: the trailing digits of the uav id", "0"),
    "round_s": ("seconds per decision round (wall clock in the field)", ""),
    # [mesh]
    "mesh.mode": ("Zenoh mode: peer (direct links where radios reach) or client (router only)", ""),
    "mesh.listen": ("where this daemon accepts links (tls/ only with [mesh.security])", ""),
    "mesh.connect": ("where it dials: the router or a seed; gossip finds the rest", ""),
    "mesh.gossip": ("learn peers' addresses from peers", ""),
    "mesh.multicast": ("UDP multicast scouting (off: explicit endpoints only)", ""),
    "mesh.namespace": ("zenoh namespace of the swarm (isolation, not security)", '"lab"'),
    "mesh.lease_ms": ("peers notice a hung daemon after one lease", ""),
    "mesh.comm_radius_m": ("peer messages reach UAVs within this range (metres)", ""),
    "mesh.zenoh_overrides": ("raw zenoh settings, path -> JSON5 (never TLS or ACL)", ""),
    "mesh.insecure": ("allow plain links off this machine: never in the field", ""),
    # [mesh.security]
    "mesh.security.identity": ("this process's identity (= the certificate's CN)", ""),
    "mesh.security.ca": ("the swarm CA certificate", ""),
    "mesh.security.cert": ("this identity's TLS certificate", ""),
    "mesh.security.key": ("its TLS private key (0600)", ""),
    "mesh.security.identities": ("the CA-signed identity list (roles, signing keys)", ""),
    "mesh.security.signing_key": ("Ed25519 key signing what this daemon publishes (0600)", ""),
    "mesh.security.acl": ("load the Zenoh ACL generated from the identity list", ""),
    "mesh.security.sign": ("sign payloads; accept only signed ones by allowed authors", ""),
    "mesh.security.verify_name": ("a peer's certificate must name the address dialled", ""),
    "mesh.security.state_dir": ("boot counter (a restart is a new epoch, not a replay)", ""),
    # [llm]
    "llm.base_url": (
        "OpenAI-compatible endpoint with logprobs (vLLM, llama-server); unset: the embedded "
        "SmolLM2-135M, a plumbing demo with no judgement",
        '"http://10.0.0.10:8000/v1"',
    ),
    "llm.model": ("model name at that endpoint", ""),
    "llm.api_key_env": ("environment variable holding the API key", '"AEROWEAVER_API_KEY"'),
    "llm.extra_body": ("extra JSON fields sent with every request", ""),
    "llm.deadline_s": ("seconds one decision may take", ""),
    "llm.connect_timeout_s": ("seconds to open a connection to the endpoint", ""),
    "llm.retries": ("retries of a failed request (0..5)", ""),
    "llm.breaker_failures": ("failures in a row that open the circuit breaker (hold)", ""),
    "llm.breaker_reset_s": ("seconds before an open breaker tries again", ""),
    "llm.top_logprobs": ("label alternatives asked for per decision (1..20)", ""),
    "llm.temperature": ("sampling temperature (0: greedy)", ""),
    "llm.slot": ("llama-server cache slot to pin (id_slot); unset: server's choice", "0"),
    # [agent]
    "agent.selector": (
        "llm (this UAV's LLM), scripted (the task's reference policy, not an LLM), "
        "centralized or hmas2 (a baseline's central node decides)",
        "",
    ),
    "agent.beta": ("experience correction weight; 0 = plain logprob selector", ""),
    "agent.gamma": ("discount of returns stored as experience", ""),
    "agent.neighbourhood": ("experience records retrieved per decision", ""),
    "agent.memory_path": ("experience memory (SQLite); unset: in RAM, lost on exit", '"uav.db"'),
    "agent.memory_required": ("unusable memory: stop (true) or fly on in RAM (false)", ""),
    "agent.run_id": ("run identity on every record; unset: a new one per start", '"field-1"'),
    "agent.share_experience": ("publish this UAV's experience to its peers", ""),
    "agent.share_every": ("share each record as it happens (round) or at episode end", ""),
    "agent.max_labels": ("most options offered per decision (2..26)", ""),
    "agent.history_rounds": ("own recent decisions in the prompt, in blocks (0: none)", ""),
    "agent.state_context": ("retrieval state holds peer messages and mission context", ""),
    "agent.coordination_reports": ("send intent/target/status reports to peers", ""),
    "agent.finalised_only": ("retrieve only returns of finished trajectories", ""),
    "agent.estimator": (
        "how experience becomes an advantage: paper (the paper's rule), or horizon:H, "
        "centre, support:M, shrink:K, scale or tscore, comma-joined (docs/adaptation.md); "
        "AEROWEAVER_ESTIMATOR overrides it",
        "",
    ),
    "agent.scripted_base": (
        "the scripted selector's base: reference (the task's heuristic) or a degraded "
        "testbed: hold-biased, position-biased, noisy[:SD], each optionally @T; "
        "AEROWEAVER_SCRIPTED_BASE overrides it",
        "",
    ),
    # [safety]
    "safety.geofence_north_m": ("north bounds from home, metres (within +-10 km)", ""),
    "safety.geofence_east_m": ("east bounds from home, metres (within +-10 km)", ""),
    "safety.altitude_band_m": ("altitude band, metres (within 0..1500)", ""),
    "safety.max_speed_mps": ("speed cap, m/s (0, 60]", ""),
    "safety.min_separation_m": ("minimum separation between UAVs, metres (0.5..100)", ""),
    # [vehicle]
    "vehicle.backend": (
        "sim (waits for a simulated world: mission start --sim-world), mavlink (pymavlink "
        "over UDP, the default for real vehicles) or mavsdk (optional extra)",
        "",
    ),
    "vehicle.url": (
        "the autopilot link: udpin://ADDR:PORT (it sends to us) or udpout://HOST:PORT",
        '"udpin://0.0.0.0:14540"',
    ),
    "vehicle.altitude_m": ("take-off height and mission flight level, metres", ""),
    "vehicle.personality": ("auto (from the heartbeat), px4 or ardupilot", ""),
    "vehicle.sysid": ("autopilot system id; unset: from its heartbeat", "1"),
    "vehicle.signing_key": (
        "MAVLink 2 signing key file (0600): aeroweaver signing-key",
        '"/etc/aeroweaver/uav0.key"',
    ),
    "vehicle.setpoint_hz": ("rate of the daemon-owned setpoint stream (10..100 Hz)", ""),
    "vehicle.lease_s": ("agent silent this long: the autopilot's own hold takes over", ""),
    "vehicle.link_timeout_s": ("no heartbeat this long: link lost, no new motion", ""),
    "vehicle.connect_timeout_s": ("seconds to find the autopilot at start", ""),
    "vehicle.command_timeout_s": ("per try of a command, before a retry", ""),
    "vehicle.command_retries": ("retries of an unacknowledged command", ""),
    "vehicle.failsafe_policy": ("autopilot failsafe parameters off-profile: refuse or warn", ""),
    "vehicle.upload_fence": ("the [safety] geofence becomes the autopilot's fence too", ""),
    "vehicle.end_action": ("at mission end or operator stop: land or return", ""),
    "vehicle.companion_failsafe": (
        "what the autopilot does when this daemon falls silent (set at preflight): land, "
        "return, or check (write nothing, only verify)",
        "",
    ),
    "vehicle.companion_loss_s": ("seconds of daemon silence before that action (2-5)", ""),
    "vehicle.origin": (
        "the swarm's shared local frame [lat, lon, alt_m]; unset: the autopilot's own frame",
        "[47.397742, 8.545594, 488.0]",
    ),
    "vehicle.on_link_loss": ("when the link comes back: failsafe (hold), land or return", ""),
    "vehicle.takeoff_timeout_s": ("seconds a take-off may take", ""),
    "vehicle.sim_world": ("fly a real link inside the simulated world (sim --link)", ""),
    "vehicle.world_grace_s": ("simulated world gone this long: stop (shorter: hold, heal)", ""),
    # [field]
    "field.round_deadline_s": ("without a simulator: seconds an LLM round may take", ""),
    "field.sensing_radius_m": ("what this UAV perceives around it, metres", ""),
    "field.beacon_max_age_s": ("peers' beacons older than this are ignored", ""),
    "field.points": (
        "known points of interest, local NED metres from home (landmarks, waypoints)",
        '[{ id = "W0", kind = "waypoint", north = 20.0, east = 5.0 }]',
    ),
    "field.points[].id": ("the point's name, as skills and the console show it", ""),
    "field.points[].kind": ("landmark (a task's point of interest) or waypoint", ""),
    "field.points[].north": ("metres north of home (within +-10 km)", ""),
    "field.points[].east": ("metres east of home (within +-10 km)", ""),
    # [approval]
    "approval.level": (
        "normal: take-off needs one operator approval per mission; strict: every "
        "take-off, landing and return needs its own (aeroweaver approve)",
        "",
    ),
    "approval.approvers": ("identities whose approvals count", ""),
    "approval.max_ttl_s": ("longer approvals are cut to this many seconds", ""),
}

_UNKNOWN = ("see aeroweaver_edge/config.py", "")


def render(cfg: BaseModel, header: list[str], notes: dict[str, list[str]] | None = None) -> str:
    """``cfg`` as a complete TOML file: ``header`` lines first (without ``#``), then every
    key with its comment. ``notes[section]`` adds comment lines at the top of a section."""
    out = [*_comment(header), ""]
    _model(cfg, "", out, notes or {})
    return "\n".join(out) + "\n"


def _model(model: BaseModel, path: str, out: list[str], notes: dict[str, list[str]]) -> None:
    subsections: list[tuple[str, BaseModel]] = []
    if path:
        out += ["", f"[{path}]"]
        out += _comment(notes.get(path, []))
    for name in type(model).model_fields:
        value = getattr(model, name)
        key = f"{path}.{name}" if path else name
        if isinstance(value, BaseModel):
            subsections.append((key, value))
            continue
        comment, example = COMMENTS.get(key, _UNKNOWN)
        out += _comment([comment])
        if value is None:
            out.append(f"# {name} = {example or '...'}")
        else:
            out.append(f"{name} = {toml_value(value)}")
    for key, sub in subsections:
        _model(sub, key, out, notes)


def _comment(lines: list[str], width: int = 90) -> list[str]:
    """Comment lines, each wrapped to ``width`` columns."""
    out: list[str] = []
    for line in lines:
        out += [
            f"# {part}"
            for part in textwrap.wrap(
                line, width - 2, break_long_words=False, break_on_hyphens=False
            )
        ] or ["#"]
    return out


def toml_value(value: Any) -> str:
    """A TOML value for what the config models hold (no None: unset keys are omitted)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        text = repr(value)
        if text in ("inf", "-inf", "nan"):
            return text
        return text if any(c in text for c in ".en") else text + ".0"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, BaseModel):
        value = value.model_dump(exclude_none=True)
    if isinstance(value, dict):
        if not value:
            return "{}"
        items = ", ".join(f"{_key(str(k))} = {toml_value(v)}" for k, v in value.items())
        return "{ " + items + " }"
    if isinstance(value, list | tuple):
        items_ = [toml_value(v) for v in value]
        if items_ and any(isinstance(v, BaseModel | dict) for v in value):
            return "[\n" + "".join(f"  {i},\n" for i in items_) + "]"
        return "[" + ", ".join(items_) + "]"
    raise TypeError(f"no TOML form for {type(value).__name__}")


def _key(key: str) -> str:
    return (
        key
        if key and all(c.isascii() and (c.isalnum() or c in "_-") for c in key)
        else (json.dumps(key, ensure_ascii=False))
    )


__all__ = ["COMMENTS", "HEADER_SECTIONS", "render", "toml_value"]
