"""The selector settings a config names, as text grammars: the advantage estimator
(``[agent] estimator``, ``horizon:3,centre``) and the scripted base (``[agent]
scripted_base``, ``noisy:1.5@2``). Parsed here, at the bottom, so a config is checked when it
loads without the config importing the agent; ``agent.estimators`` and ``agent.scripted``
subclass these with the arithmetic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Self

NOISE_SD: Final = 2.0
BASES: Final = ("reference", "hold-biased", "position-biased", "noisy")

_USAGE = (
    "expected paper, horizon:H, support:M, shrink:K, scale, tscore or centre (with a "
    "horizon), or a comma-joined mix (horizon:3,centre,scale)"
)


@dataclass(frozen=True)
class EstimatorSpec:
    """Which value a record has and how a neighbourhood's values become advantages: the
    setting (``[agent] estimator``); ``agent.estimators.Estimator`` does the arithmetic."""

    horizon: int | None = None  # None: the paper's return G_t
    support: int = 1  # fewest eligible records for a skill's own advantage
    centre: bool = False  # subtract the per-round mean H-step return of the group
    shrink: int = 0  # a skill's advantage times n / (n + shrink): thin evidence says less
    scale: bool = False  # advantages in units of the neighbourhood's spread of values
    tscore: bool = False  # ... in units of the standard error of the skill's mean

    @property
    def name(self) -> str:
        parts = [] if self.horizon is None else [f"horizon:{self.horizon}"]
        if self.centre:
            parts.append("centre")
        if self.support > 1:
            parts.append(f"support:{self.support}")
        if self.shrink:
            parts.append(f"shrink:{self.shrink}")
        if self.scale:
            parts.append("scale")
        if self.tscore:
            parts.append("tscore")
        return ",".join(parts) or "paper"

    @classmethod
    def parse(cls, text: str) -> Self:
        """``paper``, ``horizon:H``, ``support:M`` or a comma-joined mix; ``ValueError``
        with one line naming the problem otherwise."""
        horizon: int | None = None
        support = 1
        shrink = 0
        centre = scale = tscore = False
        parts = [p.strip() for p in text.split(",")]
        if not text.strip() or any(not p for p in parts):
            raise ValueError(f"estimator {text!r}: {_USAGE}")
        for part in parts:
            kind, _, arg = part.partition(":")
            if kind == "paper" and not arg:
                continue
            if kind == "centre" and not arg:
                centre = True
                continue
            if kind == "scale" and not arg:
                scale = True
                continue
            if kind == "tscore" and not arg:
                tscore = True
                continue
            if kind not in ("horizon", "support", "shrink"):
                raise ValueError(f"estimator {text!r}: unknown part {part!r}; {_USAGE}")
            try:
                n = int(arg)
            except ValueError:
                n = 0
            if not 1 <= n <= 1000:
                raise ValueError(f"estimator {text!r}: {kind} needs a whole number 1..1000")
            if kind == "horizon":
                horizon = n
            elif kind == "support":
                support = n
            else:
                shrink = n
        if centre and horizon is None:
            raise ValueError(f"estimator {text!r}: centre needs a horizon (horizon:3,centre)")
        if scale and tscore:
            raise ValueError(f"estimator {text!r}: scale or tscore, not both")
        return cls(horizon, support, centre, shrink, scale, tscore)


def _positive(value: str, text: str, what: str) -> float:
    try:
        x = float(value)
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and x > 0):
        raise ValueError(f"scripted base {text!r}: {what} must be a positive number")
    return x


@dataclass(frozen=True)
class ScriptedBaseSpec:
    """A scripted base: the reference policy, optionally degraded: the setting
    (``[agent] scripted_base``); ``agent.scripted.Base`` degrades the utilities."""

    kind: str = "reference"
    sd: float = NOISE_SD
    seed: int = 0
    temperature: float = 1.0  # log-softmax temperature: > 1 leaves the same argmax, less sure

    @property
    def name(self) -> str:
        name = self.kind
        if self.kind == "noisy" and self.sd != NOISE_SD:
            name = f"noisy:{self.sd:g}"
        return name if self.temperature == 1.0 else f"{name}@{self.temperature:g}"

    @classmethod
    def parse(cls, text: str) -> Self:
        """``reference``, ``hold-biased``, ``position-biased`` or ``noisy[:SD]``, each
        optionally ``@T`` (temperature T > 0); ``ValueError`` naming the choices otherwise."""
        body, at, temp = text.strip().partition("@")
        kind, colon, arg = body.partition(":")
        if kind not in BASES or (colon and (kind != "noisy" or not arg)):
            raise ValueError(
                f"unknown scripted base {text!r}: expected one of reference, hold-biased, "
                "position-biased, noisy[:SD], optionally @TEMPERATURE"
            )
        temperature = _positive(temp, text, "TEMPERATURE") if at else 1.0
        sd = _positive(arg, text, "SD") if arg else NOISE_SD
        return cls(kind, sd, temperature=temperature)


__all__ = ["BASES", "NOISE_SD", "EstimatorSpec", "ScriptedBaseSpec"]
