"""Which advantage estimator and scripted base a daemon runs: one precedence, everywhere.

``[agent] estimator`` and ``[agent] scripted_base`` (``config.AgentConfig``) are the settings;
the environment variables ``AEROWEAVER_ESTIMATOR`` and ``AEROWEAVER_SCRIPTED_BASE``, when set
and not empty, override them (an experiment switches every daemon without editing files);
a command-line flag (``aeroweaver sim --estimator/--base``, the adaptation bench) overrides
both. The overrides are resolved where a config enters the program (``aeroweaver daemon``
after loading its file, a simulated run when it writes its daemons' configs), so the daemon
itself reads only its config. A daemon a simulated run spawned gets neither variable
(``orchestration.daemons``): the run has already resolved them into the config it wrote.
"""

from __future__ import annotations

import os
from typing import Final, Literal

from aeroweaver_edge.agent.estimators import ENV_ESTIMATOR, Estimator
from aeroweaver_edge.agent.scripted import ENV_BASE, Base
from aeroweaver_edge.config import AgentConfig
from aeroweaver_edge.contracts.errors import UserError

Field = Literal["estimator", "scripted_base"]
ENV: Final[dict[Field, str]] = {"estimator": ENV_ESTIMATOR, "scripted_base": ENV_BASE}
EXAMPLE: Final[dict[Field, str]] = {"estimator": "horizon:3,centre", "scripted_base": "hold-biased"}


def canonical(field: Field, text: str) -> str:
    """The canonical form of a value (``ValueError``: one line with the allowed forms)."""
    if field == "estimator":
        return Estimator.parse(text).name
    return Base.parse(text).name


def from_env(field: Field) -> str | None:
    """The environment's override of ``field`` (None: unset or empty); a bad value is the
    user's to fix: one line naming the variable and the allowed forms (exit 2)."""
    name = ENV[field]
    text = os.environ.get(name, "")
    if not text.strip():
        return None
    try:
        return canonical(field, text)
    except ValueError as exc:
        raise UserError(f"{name}: {exc}", f"unset it or set e.g. {name}={EXAMPLE[field]}") from None


def resolve(field: Field, flag: str | None = None, configured: str | None = None) -> str:
    """flag > environment > configured > the default (``AgentConfig``'s)."""
    if flag is not None:
        return flag
    env = from_env(field)
    if env is not None:
        return env
    if configured is not None:
        return configured
    default = AgentConfig.model_fields[field].default
    assert isinstance(default, str)
    return default


def with_env_overrides(agent: AgentConfig) -> AgentConfig:
    """``agent`` with the environment's overrides applied (unchanged when none is set)."""
    update: dict[str, str] = {f: v for f in ENV if (v := from_env(f)) is not None}
    return agent.model_copy(update=update) if update else agent


__all__ = ["ENV", "Field", "canonical", "from_env", "resolve", "with_env_overrides"]
