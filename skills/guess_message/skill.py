"""guess_message: the stationary eavesdropper records a guess (memo ``guess``) of the
sender's symbol after intercepting a ciphertext; it has no key."""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Hold, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import SYMBOLS, allowed, ciphertexts

NAME = "guess_message"
ROLES = frozenset({"eavesdropper"})


class Params(SkillParams):
    symbol: int = Field(ge=0, le=3, description="guessed plaintext symbol 0-3")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    """Every symbol 0-3, once a ciphertext has been intercepted."""
    if not allowed(ctx, ROLES) or not ciphertexts(obs):
        return []
    return [Params(symbol=s) for s in SYMBOLS]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    if not allowed(ctx, ROLES):
        return HOLD
    return Intent(Hold(), memo={"guess": str(params.symbol)})
