"""The access table: one source for the Zenoh ACL and the application's signature check."""

from __future__ import annotations

import json

import pytest
import zenoh

from aeroweaver_edge.contracts.wire import Keys
from aeroweaver_edge.security.identity import default_members
from aeroweaver_edge.security.policy import Authorizer, Role, build_acl

K = Keys("s")
MEMBERS = default_members(3)


def test_acl_is_default_deny_with_one_subject_per_certificate_name() -> None:
    acl = build_acl("s", MEMBERS)
    assert acl["enabled"] is True
    assert acl["default_permission"] == "deny"
    assert [s["cert_common_names"] for s in acl["subjects"]] == [[n] for n in sorted(MEMBERS)]
    ids = [r["id"] for r in acl["rules"]]
    assert len(ids) == len(set(ids))
    assert all(r["permission"] == "allow" for r in acl["rules"])
    for policy in acl["policies"]:
        assert set(policy["rules"]) <= set(ids)
    conf = zenoh.Config()
    conf.insert_json5("access_control", json.dumps(acl))  # zenoh accepts the section


def _rules(acl: dict[str, object], name: str) -> dict[str, dict[str, object]]:
    rules = acl["rules"]
    assert isinstance(rules, list)
    return {r["id"].removeprefix(f"{name}-"): r for r in rules if r["id"].startswith(f"{name}-")}


def test_observer_writes_serves_and_declares_no_token() -> None:
    rules = _rules(build_acl("s", MEMBERS), "observer")
    assert set(rules) == {"in-read", "in-alive", "out-data", "out-decl"}
    assert rules["in-read"]["key_exprs"] == ["aw/s/**"]


def test_uav_rules_name_only_its_own_keys() -> None:
    rules = _rules(build_acl("s", MEMBERS), "uav1")
    assert rules["in-write"]["key_exprs"] == ["aw/s/uav/uav1/**", "aw/s/uav/*/inbox/uav1"]
    assert rules["in-write"]["messages"] == ["put", "delete"]
    assert rules["in-write"]["flows"] == ["ingress"]
    assert rules["in-token"]["key_exprs"] == ["aw/s/alive/uav/uav1"]
    assert rules["in-serve"]["key_exprs"] == ["aw/s/uav/uav1/**"]
    reads = rules["in-read"]["key_exprs"]
    assert "aw/s/sim/perception/uav1" in reads
    assert "aw/s/uav/*/broadcast" in reads  # every peer's broadcast key
    assert not [k for k in reads if "uav2" in k or "uav0" in k]


def test_world_hears_the_radio_its_listeners_hear_and_writes_only_sim() -> None:
    rules = _rules(build_acl("s", MEMBERS), "world")
    assert rules["in-write"]["key_exprs"] == ["aw/s/sim/**"]
    reads = rules["in-read"]["key_exprs"]
    assert {"aw/s/uav/*/broadcast", "aw/s/uav/*/inbox/*", "aw/s/uav/*/sim/command"} <= set(reads)


def test_namespace_prefixes_every_rule() -> None:
    acl = build_acl("s", MEMBERS, namespace="run-7")
    for rule in acl["rules"]:
        assert all(k.startswith("run-7/aw/s/") for k in rule["key_exprs"]), rule


AUTHOR = Authorizer("s", MEMBERS)


@pytest.mark.parametrize(
    ("name", "key", "allowed"),
    [
        ("uav1", K.state("uav1"), True),
        ("uav1", K.report("uav1"), True),
        ("uav1", K.experience("uav1"), True),
        ("uav1", K.sim_command("uav1"), True),
        ("uav1", K.inbox("uav0", "uav1"), True),
        ("uav1", K.inbox("uav0", "uav2"), False),
        ("uav1", K.state("uav2"), False),
        ("uav1", K.sim_command("uav2"), False),
        ("uav1", K.context, False),
        ("uav1", K.sim_perception("uav1"), False),
        ("cmdr", K.context, True),
        ("cmdr", K.assign("uav2"), True),
        ("cmdr", K.state("uav2"), False),
        ("cmdr", K.sim_episode, False),
        ("world", K.sim_perception("uav2"), True),
        ("world", K.sim_reward("uav2"), True),
        ("world", K.sim_episode, True),
        ("world", K.sim_command("uav2"), False),
        ("world", K.context, False),
        ("central", "aw/s/central/plan/uav0", True),
        ("central", K.state("uav0"), False),
        ("observer", K.state("uav0"), False),
        ("router", K.state("uav0"), False),
        ("uav9", K.state("uav9"), False),
        ("uav1", "aw/other/uav/uav1/state", False),
    ],
)
def test_write_table(name: str, key: str, allowed: bool) -> None:
    assert AUTHOR.may_write(name, key) is allowed


def test_roles_are_closed() -> None:
    assert {r.value for r in Role} == {
        "uav", "commander", "world", "central", "observer", "router", "operator",
    }  # fmt: skip
