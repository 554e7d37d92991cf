"""Every number in every config model is finite and bounded: the test walks the models (a
field added later is covered without editing this file), writes each numeric field as
inf, -inf, nan and a huge value into a real TOML file, and expects one ConfigError line that
names the file and the field. The real CLI refuses the same way (exit 2, one line)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import types
import typing
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from pydantic import BaseModel

from aeroweaver_edge.config import ConfigError, SimConfig, UavConfig, load_config

ROOT = Path(__file__).resolve().parents[2]
REQUIRED: dict[str, dict[str, Any]] = {  # section -> the fields it cannot be without
    "mesh.security": {
        "identity": "uav0", "ca": "ca.crt", "cert": "tls.crt", "key": "tls.key",
        "identities": "identities.json",
    },
    "field.points": {"id": "p", "north": 0.0, "east": 0.0},
}  # fmt: skip


def _plain(annotation: Any) -> Any:
    """``X | None`` -> ``X``."""
    if isinstance(annotation, types.UnionType) or typing.get_origin(annotation) is typing.Union:
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        return args[0] if len(args) == 1 else annotation
    return annotation


def _bare(annotation: Any) -> Any:
    """``Annotated[float, ...]`` -> ``float``."""
    if typing.get_origin(annotation) is typing.Annotated:
        return typing.get_args(annotation)[0]
    return annotation


def _model(annotation: Any) -> type[BaseModel] | None:
    plain = _plain(annotation)
    if typing.get_origin(plain) is list:
        plain = typing.get_args(plain)[0]
    return plain if isinstance(plain, type) and issubclass(plain, BaseModel) else None


def numeric_fields(model: type[BaseModel], prefix: str = "") -> Iterator[tuple[str, str, Any]]:
    """(section path, field name, annotation) for every number, recursively."""
    for name, info in model.model_fields.items():
        annotation = _plain(info.annotation)
        sub = _model(info.annotation)
        if sub is not None:
            yield from numeric_fields(sub, f"{prefix}.{name}" if prefix else name)
        elif annotation in (int, float) or (
            typing.get_origin(annotation) is tuple
            and all(_bare(a) in (int, float) for a in typing.get_args(annotation))
        ):
            yield prefix, name, annotation


def _toml(value: Any) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(
            value) else repr(value)  # fmt: skip
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, str):
        return f'"{value}"'
    return str(value)


def document(top: type[BaseModel], section: str, name: str, value: Any) -> str:
    """A minimal valid file of ``top`` with ``section.name = value``."""
    lines = ['uav = "uav0"'] if top is UavConfig else []
    fields = {**REQUIRED.get(section, {}), name: value}
    body = [f"{k} = {_toml(v)}" for k, v in fields.items()]
    if not section:
        return "\n".join([*lines, *body]) + "\n"
    if section == "field.points":
        return "\n".join([*lines, "[[field.points]]", *body]) + "\n"
    if section == "mesh.security":  # a secured mesh needs tls/ endpoints
        lines += ["[mesh]", 'listen = ["tls/127.0.0.1:0"]']
    return "\n".join([*lines, f"[{section}]", *body]) + "\n"


def bad_values(annotation: Any) -> list[tuple[str, Any]]:
    if annotation is int:
        return [("huge", 2**63 - 1), ("-huge", -(2**63)), ("inf", math.inf), ("nan", math.nan)]
    if annotation is float:
        return [("inf", math.inf), ("-inf", -math.inf), ("nan", math.nan), ("huge", 1e300)]
    # a pair (or a longer tuple): each bad value first or last, the others ordinary
    n = len(typing.get_args(annotation))
    return [
        (f"{where} {what}", (v, *[1.0] * (n - 1)) if where == "low" else (*[0.0] * (n - 1), v))
        for what, v in (("inf", math.inf), ("nan", math.nan), ("huge", 1e300))
        for where in ("low", "high")
    ] + [("both -inf/inf", (-math.inf, *[0.0] * (n - 2), math.inf))]


CASES = [
    pytest.param(top, section, name, value, id=f"{top.__name__}:{section or '-'}.{name}={what}")
    for top in (UavConfig, SimConfig)
    for section, name, annotation in numeric_fields(top)
    for what, value in bad_values(annotation)
]


def models(model: type[BaseModel]) -> Iterator[type[BaseModel]]:
    yield model
    for info in model.model_fields.values():
        sub = _model(info.annotation)
        if sub is not None:
            yield from models(sub)


def test_the_walk_reaches_every_config_model() -> None:
    """A section added to config.py but not reachable from the two files is caught here."""
    import aeroweaver_edge.config as config

    defined = {
        obj for obj in vars(config).values()
        if isinstance(obj, type) and issubclass(obj, BaseModel)
        and obj.__module__ == config.__name__ and not obj.__name__.startswith("_")
    }  # fmt: skip
    reached = {m for top in (UavConfig, SimConfig) for m in models(top)}
    assert defined == reached


def test_the_walk_finds_the_fields_the_issue_names() -> None:
    found = {(s, n) for top in (UavConfig, SimConfig) for s, n, _ in numeric_fields(top)}
    for wanted in [("", "round_s"), ("mesh", "lease_ms"), ("mesh", "comm_radius_m"),
                   ("llm", "deadline_s"), ("agent", "beta"), ("safety", "geofence_north_m"),
                   ("field.points", "north"), ("", "seed")]:  # fmt: skip
        assert wanted in found
    assert len(found) >= 45


@pytest.mark.parametrize(("top", "section", "name", "value"), CASES)
def test_every_number_is_finite_and_bounded(
    tmp_path: Path, top: type[BaseModel], section: str, name: str, value: Any
) -> None:
    path = tmp_path / "cfg.toml"
    path.write_text(document(top, section, name, value), encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_config(path, top)
    message = str(info.value)
    assert "\n" not in message
    assert str(path) in message
    where = f"{section}.{name}" if section else name
    if section == "field.points":
        where = f"field.points[0].{name}"
    assert where in message, message


@pytest.mark.parametrize(("top", "section", "name"), sorted({c.values[:3] for c in CASES}, key=str))
def test_the_minimal_document_itself_is_valid(
    tmp_path: Path, top: type[BaseModel], section: str, name: str
) -> None:
    """The refusal above is about the value: the same file with the default is accepted."""
    model: type[BaseModel] = top
    for part in filter(None, section.split(".")):
        found = _model(model.model_fields[part].annotation)
        assert found is not None
        model = found
    info = model.model_fields[name]
    value = info.default if info.default is not None else 1
    arity = len(typing.get_args(_plain(info.annotation)))
    if info.default is None and arity:  # an optional tuple: an ordinary one of its length
        value = (0.0,) * arity
    if section == "field.points":
        value = 0.0
    if value is None or (isinstance(value, tuple) and not value):
        pytest.skip("no default to write")
    path = tmp_path / "cfg.toml"
    path.write_text(document(top, section, name, value), encoding="utf-8")
    load_config(path, top)


@pytest.mark.parametrize(
    "line",
    ["round_s = inf", "[mesh]\nlease_ms = 9223372036854775807", "[mesh]\ncomm_radius_m = inf",
     "[llm]\ndeadline_s = inf", "[agent]\nbeta = inf"],
)  # fmt: skip
def test_the_daemon_refuses_with_one_line_and_exit_2(tmp_path: Path, line: str) -> None:
    path = tmp_path / "uav.toml"
    path.write_text(f'uav = "uav0"\n{line}\n', encoding="utf-8")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-m", "aeroweaver_edge", "daemon", "--config", str(path)],
        capture_output=True, text=True, timeout=60, env=env, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    key = line.split("\n")[-1].split(" =")[0]
    assert "config error" in lines[0]
    assert key in lines[0]
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    ("flag", "value"),
    [("--beta", "inf"), ("--beta", "1e9"), ("--deadline", "inf"), ("--llm-deadline", "nan"),
     ("--seed", "-1"), ("--rounds", "9223372036854775807"), ("--pace", "nan")],
)  # fmt: skip
def test_sim_flags_share_the_bounds(flag: str, value: str) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-m", "aeroweaver_edge", "sim", "--selector", "scripted",
         flag, value],
        capture_output=True, text=True, timeout=60, env=env,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert flag in proc.stderr


@pytest.mark.parametrize(
    "endpoint",
    ["tcp/127.0.0.1:99999", "tcp/127.0.0.1:-1", "tcp/127.0.0.1:http", "tcp/127.0.0.1",
     "udp/:7447", "tcp/[::1]:65536"],
)  # fmt: skip
def test_an_endpoint_port_out_of_range_is_named(tmp_path: Path, endpoint: str) -> None:
    path = tmp_path / "uav.toml"
    path.write_text(f'uav = "uav0"\n[mesh]\nconnect = ["{endpoint}"]\n', encoding="utf-8")
    with pytest.raises(ConfigError, match=r"mesh\.connect\[0\]"):
        load_config(path, UavConfig)


def test_mission_start_refuses_a_port_beyond_65535() -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-m", "aeroweaver_edge", "mission", "start", "--no-llm",
         "--connect", "tcp/127.0.0.1:99999", "Cover the landmarks"],
        capture_output=True, text=True, timeout=60, env=env,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "port 99999 is outside 1..65535" in proc.stderr
