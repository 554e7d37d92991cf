"""Who may write, serve, declare and read which keys: one table, two enforcers.

The table (``grants``) is the single source of truth. ``build_acl`` turns it into Zenoh's
``access_control`` section (subjects by certificate CN, default deny, evaluated by every
receiving node), and ``Authorizer.may_write`` applies the same table in the application to
end-to-end signed payloads, so a relay or router that forwards for others (and is allowed
to by the per-hop ACL) still cannot make a UAV accept a key its author may not write.

Per role (S = ``aw/<swarm>``, after the Zenoh namespace if one is set):

| role      | writes (put/delete)                     | serves (queryable/reply) | token          |
|-----------|-----------------------------------------|--------------------------|----------------|
| uav X     | S/uav/X/** and S/uav/*/inbox/X           | S/uav/X/**               | S/alive/uav/X  |
| commander | S/cmdr/**                               | S/cmdr/**                | S/alive/cmdr   |
| world     | S/sim/**                                | S/sim/**                 | S/alive/world  |
| central   | S/central/**                            | S/central/**             | S/alive/central|
| observer  | nothing                                 | nothing                  | none           |
| operator  | S/operator/**                           | nothing                  | none           |
| router    | S/** (it relays for everyone)           | S/**                     | S/**           |

Reads (subscribe, query, and what a node sends *to* that subject) are least privilege too:
a UAV reads beacons, its own inbox, every peer's broadcast key, shared experience, the
context, its own assignment and its own simulator perception and reward, so private facts
do not cross UAVs. The world reads the UAVs' simulator commands, beacons and the radio its
world-flown listeners (the eavesdropper) hear: broadcasts and their inboxes. The operator
(``aeroweaver console`` / ``mcp`` / ``approve`` with its key) reads what an observer reads and
writes only operator keys: stop commands the Commander reads and approvals a UAV reads.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import zenoh

from aeroweaver_edge.contracts.wire import Keys


class Role(enum.StrEnum):
    UAV = "uav"
    COMMANDER = "commander"
    WORLD = "world"
    CENTRAL = "central"
    OBSERVER = "observer"
    OPERATOR = "operator"
    ROUTER = "router"


@dataclass(frozen=True)
class Grants:
    """Key expressions (without namespace) one identity may use, by kind of operation."""

    write: tuple[str, ...]
    serve: tuple[str, ...]
    token: tuple[str, ...]
    read: tuple[str, ...]
    alive: tuple[str, ...]  # liveliness subscribers and liveliness queries


def grants(keys: Keys, name: str, role: Role) -> Grants:
    """The table above, for one identity. ``keys`` fixes the swarm."""
    s = keys.root
    alive = (keys.alive_all,)
    if role is Role.UAV:
        return Grants(
            write=(f"{s}/uav/{name}/**", keys.inbox("*", name)),
            serve=(f"{s}/uav/{name}/**",),
            token=(keys.alive_uav(name),),
            read=(
                keys.state("*"),
                keys.inbox(name, "*"),
                keys.broadcast("*"),
                keys.experience("*"),
                keys.context,
                keys.assign(name),
                keys.sim_perception(name),
                keys.sim_reward(name),
                keys.sim_episode,
                f"{s}/central/**",
                keys.approval(name),
            ),
            alive=alive,
        )
    if role is Role.COMMANDER:
        return Grants(
            write=(f"{s}/cmdr/**",),
            serve=(f"{s}/cmdr/**",),
            token=(keys.alive_cmdr,),
            read=(
                keys.state("*"), keys.report("*"), f"{s}/cmdr/**", keys.sim_episode,
                keys.operator_command,
            ),
            alive=alive,
        )  # fmt: skip
    if role is Role.WORLD:
        return Grants(
            write=(f"{s}/sim/**",),
            serve=(f"{s}/sim/**",),
            token=(f"{s}/alive/world",),
            # World-flown listeners (the eavesdropper) hear broadcasts and their own inbox;
            # their names are not identities, so the inbox grant cannot name them.
            read=(
                keys.sim_command("*"),
                keys.state("*"),
                keys.broadcast("*"),
                keys.inbox("*", "*"),
                f"{s}/sim/**",
            ),
            alive=alive,
        )
    if role is Role.CENTRAL:
        return Grants(
            write=(f"{s}/central/**",),
            serve=(f"{s}/central/**",),
            token=(f"{s}/alive/central",),
            read=(f"{s}/**",),
            alive=alive,
        )
    if role is Role.OBSERVER:
        return Grants(write=(), serve=(), token=(), read=(f"{s}/**",), alive=alive)
    if role is Role.OPERATOR:
        return Grants(write=(f"{s}/operator/**",), serve=(), token=(), read=(f"{s}/**",),
                      alive=alive)  # fmt: skip
    if role is Role.ROUTER:
        everything = (f"{s}/**",)
        return Grants(
            write=everything, serve=everything, token=everything, read=everything, alive=alive
        )
    raise ValueError(f"unknown role {role!r}")  # pragma: no cover - exhaustive enum


def _ns(namespace: str | None, exprs: Iterable[str]) -> list[str]:
    """ACL rules see keys as they travel, i.e. with the session namespace in front."""
    return [f"{namespace}/{e}" if namespace else e for e in exprs]


def build_acl(
    swarm: str, identities: Mapping[str, Role], namespace: str | None = None
) -> dict[str, Any]:
    """Zenoh's ``access_control`` section for a swarm: default deny, one subject per
    identity (certificate CN), ingress = what that identity may send us, egress = what we
    may send to it. Every node of the swarm loads the same section (the ACL is per hop)."""
    keys = Keys(swarm)
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    everything = _ns(namespace, [f"{keys.root}/**"])

    def rule(rid: str, messages: list[str], flow: str, exprs: Iterable[str]) -> str | None:
        key_exprs = _ns(namespace, exprs)
        if not key_exprs:
            return None  # zenoh rejects an empty key_exprs list: no rule means denied
        rules.append(
            {
                "id": rid,
                "messages": messages,
                "flows": [flow],
                "permission": "allow",
                "key_exprs": key_exprs,
            }
        )
        return rid

    for name, role in sorted(identities.items()):
        g = grants(keys, name, role)
        ids = [
            rule(f"{name}-in-write", ["put", "delete"], "ingress", g.write),
            rule(f"{name}-in-serve", ["declare_queryable", "reply"], "ingress", g.serve),
            rule(f"{name}-in-token", ["liveliness_token"], "ingress", g.token),
            rule(f"{name}-in-read", ["declare_subscriber", "query"], "ingress", g.read),
            rule(
                f"{name}-in-alive",
                ["declare_liveliness_subscriber", "liveliness_query"],
                "ingress",
                g.alive,
            ),
            rule(f"{name}-out-data", ["put", "delete", "reply"], "egress", g.read),
        ]
        # What we declare or ask is not secret: our declarations, queries and tokens may
        # reach every identity (the receiving side's ingress rules judge them).
        rules.append(
            {
                "id": f"{name}-out-decl",
                "messages": [
                    "declare_subscriber", "declare_queryable", "query", "liveliness_token",
                    "declare_liveliness_subscriber", "liveliness_query",
                ],
                "flows": ["egress"],
                "permission": "allow",
                "key_exprs": everything,
            }
        )  # fmt: skip
        subjects.append({"id": f"cn-{name}", "cert_common_names": [name]})
        policies.append(
            {
                "id": f"policy-{name}",
                "rules": [r for r in ids if r is not None] + [f"{name}-out-decl"],
                "subjects": [f"cn-{name}"],
            }
        )
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


class Authorizer:
    """The write column of the table, for checking signed payloads in the application.
    A router relays for everyone but authors nothing, so here it may write no key."""

    def __init__(self, swarm: str, identities: Mapping[str, Role]) -> None:
        self.keys = Keys(swarm)
        self.roles = dict(identities)
        self._allowed: dict[str, list[zenoh.KeyExpr]] = {}
        for name, role in self.roles.items():
            if role is Role.ROUTER:
                continue
            g = grants(self.keys, name, role)
            self._allowed[name] = [zenoh.KeyExpr(e) for e in (*g.write, *g.serve)]

    def may_write(self, name: str, key: str) -> bool:
        """True if ``name`` may publish (or answer queries) on ``key``."""
        allowed = self._allowed.get(name)
        if not allowed:
            return False
        try:
            target = zenoh.KeyExpr(key)
        except zenoh.ZError:
            return False
        return any(pattern.includes(target) for pattern in allowed)
