"""encode_message: the stationary sender sends ``ciphertext = plaintext XOR key``.

Private facts (strings in ``obs.facts``): ``private_symbol`` (the plaintext, "0".."3") and
``key`` ("0".."3", shared with the receiver only). The plaintext never leaves the UAV.
"""

from __future__ import annotations

from pydantic import Field

from aeroweaver_edge.contracts.actions import HOLD, Hold, Intent, Outgoing
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams
from skills._common import Scalar, allowed, symbol

NAME = "encode_message"
ROLES = frozenset({"sender"})


class Params(SkillParams):
    symbol: int = Field(ge=0, le=3, description="plaintext symbol 0-3 (your private symbol)")


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    """Only the sender's own private symbol, and only when it holds a key to encrypt with."""
    plain, key = symbol(obs.facts.get("private_symbol")), symbol(obs.facts.get("key"))
    if plain is None or key is None or not allowed(ctx, ROLES):
        return []
    return [Params(symbol=plain)]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    key = symbol(obs.facts.get("key"))
    if key is None or not allowed(ctx, ROLES):
        return HOLD
    body: dict[str, Scalar] = {"skill": NAME, "ciphertext": params.symbol ^ key}
    return Intent(
        Hold(), messages=(Outgoing(to="*", kind="ciphertext", body=body, purpose="task"),)
    )
