"""decode_message: the stationary receiver decrypts a received ciphertext with its key
(``obs.facts["key"]``) and records the plaintext as its guess (memo ``guess``)."""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Hold, Intent
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import allowed, ciphertexts, symbol

NAME = "decode_message"
ROLES = frozenset({"receiver"})


class Params(SkillParams):
    symbol: int = Field(ge=0, le=3, description="decoded plaintext symbol 0-3 to record")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    """One option per distinct received ciphertext, already decrypted with the key."""
    key = symbol(obs.facts.get("key"))
    if key is None or not allowed(ctx, ROLES):
        return []
    decoded = dict.fromkeys(c ^ key for c in ciphertexts(obs))
    return [Params(symbol=s) for s in decoded]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    """Record the guess; the receiver never moves and sends nothing."""
    if not allowed(ctx, ROLES):
        return HOLD
    return Intent(Hold(), memo={"guess": str(params.symbol)})
