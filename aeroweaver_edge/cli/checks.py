"""Checks that run before a command starts its work, so a user error costs nothing.

Argument types (argparse calls them: a bad value is a one-line usage error) and preflight
checks of outputs, memory directories, the API-key variable, the task and the skill tree.
Each failure is a ``UserError`` naming the cause and the fix.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from pydantic import BaseModel, TypeAdapter, ValidationError

from aeroweaver_edge.contracts.errors import UserError


def int_in(lo: int, hi: int | None = None) -> Callable[[str], int]:
    """An argparse type: an integer within [lo, hi]."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if value < lo or (hi is not None and value > hi):
            bound = f"{lo}..{hi}" if hi is not None else f"at least {lo}"
            raise argparse.ArgumentTypeError(f"{value} is out of range ({bound})")
        return value

    parse.__name__ = "integer"
    return parse


def finite(*, minimum: float = 0.0, strict: bool = True) -> Callable[[str], float]:
    """An argparse type: a finite number above ``minimum`` (or at least it, ``strict=False``)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text} is not a finite number")
        if value < minimum or (strict and value == minimum):
            rel = ">" if strict else ">="
            raise argparse.ArgumentTypeError(f"{value:g} must be {rel} {minimum:g}")
        return value

    parse.__name__ = "number"
    return parse


def config_value(model: type[BaseModel], name: str) -> Callable[[str], Any]:
    """An argparse type for a flag that sets config field ``model.name``: the field's own
    type and bounds (``config.py``), so a flag and a config file refuse the same values."""
    info = model.model_fields[name]
    adapter: TypeAdapter[Any] = TypeAdapter(info.rebuild_annotation())
    allow_nan = model.model_config.get("allow_inf_nan", True)

    def parse(text: str) -> Any:
        value: Any = text
        try:
            value = int(text)
        except ValueError:
            try:
                value = float(text)
            except ValueError:
                raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if isinstance(value, float) and not allow_nan and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text} is not a finite number")
        try:
            return adapter.validate_python(value)
        except ValidationError as exc:
            raise argparse.ArgumentTypeError(_bound_message(text, exc)) from None

    parse.__name__ = "number"
    return parse


def mission_text(text: str) -> str:
    """An argparse type: a mission text that passes ``commander.mission_text`` (UTF-8, no
    control characters, at most 8 KiB), checked before any process or session starts."""
    from commander.mission_text import MissionTextError, check_mission_text

    try:
        return check_mission_text(text)
    except MissionTextError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


mission_text.__name__ = "mission text"


_BOUNDS = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<",
           "less_than_equal": "<="}  # fmt: skip


def _bound_message(text: str, exc: ValidationError) -> str:
    """``-1 must be >= 0``, as the other argparse types say it."""
    err = exc.errors()[0]
    ctx = err.get("ctx") or {}
    for kind, op in _BOUNDS.items():
        if err["type"] == kind:
            limit = next(iter(ctx.values()))
            return f"{text} must be {op} {limit:g}" if isinstance(limit, float) else (
                f"{text} must be {op} {limit}"
            )  # fmt: skip
    if err["type"] == "int_from_float":
        return f"{text} is not a whole number"
    why = str(err["msg"]).removeprefix("Value error, ")
    return f"{text}: {why[:1].lower()}{why[1:]}"


def _nearest_existing(path: Path) -> Path:
    here = path
    while not here.exists() and here != here.parent:
        here = here.parent
    return here


def _probe_write(directory: Path, what: str, fix: str) -> None:
    """Create and remove a file in ``directory``: the only honest writability test (root
    passes every permission check; a read-only mount or a full disk does not)."""
    try:
        with tempfile.NamedTemporaryFile(dir=directory, prefix=".aeroweaver-probe-"):
            pass
    except OSError as exc:
        why = exc.strerror or str(exc)
        raise UserError(f"{what}: cannot write in {directory} ({why})", fix) from None


def check_output_file(path: Path, flag: str) -> None:
    """``path`` can be written at the end of the run (missing directories are created)."""
    fix = f"give {flag} a path in a writable directory"
    if path.is_dir():
        raise UserError(f"{flag} {path} is a directory", fix)
    if path.exists() and not os.access(path, os.W_OK):
        raise UserError(f"{flag} {path} is not writable", fix)
    parent = _nearest_existing(path.parent)
    if not parent.is_dir():
        raise UserError(f"{flag} {path}: {parent} is not a directory", fix)
    _probe_write(parent, f"{flag} {path}", fix)


def check_memory_dir(path: Path, flag: str = "--memory-dir", fix: str = "") -> None:
    """The memory directory exists (created if needed) and takes new files; the memory
    files already in it are writable."""
    fix = fix or f"give {flag} a writable directory"
    if path.exists() and not path.is_dir():
        raise UserError(f"{flag} {path} is not a directory", fix)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{flag} {path} cannot be created ({exc.strerror or exc})", fix) from None
    _probe_write(path, f"{flag} {path}", fix)
    for existing in sorted(path.glob("*.sqlite3")):
        if not os.access(existing, os.R_OK | os.W_OK):
            raise UserError(f"{flag}: {existing} is not writable", fix)


def check_memory_path(path: str | None) -> None:
    """A daemon's ``agent.memory_path``: its directory can hold the file."""
    if path is None:
        return
    p = Path(path)
    fix = (
        "set agent.memory_path to a file in a writable directory, or agent.memory_required "
        "= false to fly without persistent memory"
    )
    if p.is_dir():
        raise UserError(f"agent.memory_path {p} is a directory", fix)
    check_memory_dir(p.parent, f"agent.memory_path {p}: directory", fix)


def check_api_key_env(name: str | None) -> None:
    if name and not os.environ.get(name):
        raise UserError(
            f"the API-key variable {name} is not set (or empty)",
            f"export {name}=<key>, or drop --api-key-env",
        )


def check_llm_url(url: str | None, flag: str = "--llm") -> None:
    if url is None:
        return
    parts = urlsplit(url)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise UserError(
            f"{flag} must be an http(s) URL with a host",
            "e.g. --llm http://127.0.0.1:8080/v1",
        )


def check_task(task: str, uavs: int | None) -> None:
    """The task exists and can fly ``uavs`` UAVs (``None``: its default team)."""
    from aeroweaver_edge.tasks import TASK_NAMES, create

    if task not in TASK_NAMES:
        raise UserError(f"unknown task {task!r}", f"choose one of: {', '.join(TASK_NAMES)}")
    try:
        create(task, uavs)
    except ValueError as exc:
        raise UserError(f"task {task} cannot fly {uavs} UAVs: {exc}", "change --uavs") from None


def check_skills() -> None:
    """Load and validate the skill tree now (``SkillError`` names the file and field)."""
    from aeroweaver_edge.skills import load_skills

    load_skills()
