"""The operator approval gate: levels, expiry, single use, who may approve, pending actions."""

from __future__ import annotations

from typing import get_args

import pytest

from aeroweaver_edge.config import ApprovalConfig, ConfigError, parse_config
from aeroweaver_edge.contracts.actions import VehicleAction
from aeroweaver_edge.contracts.wire import Approval, Header, VehicleActionKind
from aeroweaver_edge.safety.approval import (
    ACTION_ALIASES,
    ACTIONS,
    ApprovalGate,
    approve_phrase,
    parse_action,
)

TAKEOFF = VehicleAction("takeoff")
LAND = VehicleAction("land")
HOME = VehicleAction("return_home")


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def approval(
    action: str = "takeoff",
    *,
    uav: str = "uav0",
    sender: str = "operator",
    ident: str = "a" * 16,
    ttl: float = 60.0,
    stamp: float = 5000.0,
    mission: str = "",
) -> Approval:
    h = Header(sender=sender, epoch=1, seq=1, stamp=stamp)
    return Approval(h=h, id=ident, uav=uav, action=action, ttl_s=ttl, by="ana",  # type: ignore[arg-type]
                    mission_id=mission)  # fmt: skip


def gate(
    level: str = "normal", mission: list[str | None] | None = None
) -> tuple[ApprovalGate, Clock]:
    clock = Clock()
    box = mission if mission is not None else ["m1"]
    g = ApprovalGate(
        "uav0", ApprovalConfig(level=level), mission=lambda: box[0], clock=clock,  # type: ignore[arg-type]
        wall=lambda: clock.t + 4000.0,
    )  # fmt: skip
    return g, clock


def test_normal_level_needs_one_takeoff_approval_per_mission_and_none_to_land() -> None:
    box: list[str | None] = ["m1"]
    g, _clock = gate("normal", box)
    assert g.approve("uav0", LAND)
    assert g.approve("uav0", HOME)
    assert g.offer("land")
    assert g.offer("return_home")
    assert g.offer("go_to")
    assert not g.offer("take_off")
    assert [p.action for p in g.pending()] == ["takeoff"]
    assert not g.approve("uav0", TAKEOFF)
    rec = g.receive(approval())
    assert rec.state == "granted"
    assert rec.by == "ana"
    assert rec.sender == "operator"
    assert rec.expires - rec.received == pytest.approx(60.0)
    assert g.pending() == []
    assert g.offer("take_off")
    assert g.approve("uav0", TAKEOFF)
    assert g.approve("uav0", TAKEOFF)
    assert g.records()[-1].uses == 2
    assert g.records()[-1].mission_id == "m1"
    box[0] = "m2"  # the next mission needs its own approval
    assert not g.approve("uav0", TAKEOFF)
    assert not g.approve("uav1", LAND)  # never for another UAV


def test_strict_level_uses_each_approval_once_for_every_action() -> None:
    g, _clock = gate("strict")
    assert g.gates_launch
    for action, skill in ((TAKEOFF, "take_off"), (LAND, "land"), (HOME, "return_home")):
        assert not g.offer(skill)
        assert not g.approve("uav0", action)
    assert sorted(p.action for p in g.pending()) == ["land", "return_home", "takeoff"]
    g.receive(approval("land", ident="b" * 16))
    assert g.offer("land")
    assert g.approve("uav0", LAND)
    assert not g.approve("uav0", LAND)  # used up
    assert g.records()[-1].state == "used"
    # asked for again after its approval was used: pending again
    assert sorted(p.action for p in g.pending()) == ["land", "return_home", "takeoff"]


def test_approvals_expire_on_the_uavs_own_clock() -> None:
    g, clock = gate("normal")
    g.receive(approval(ttl=30.0))
    clock.t += 29.9
    assert g.offer("take_off")
    clock.t += 0.2
    assert not g.offer("take_off")
    assert g.records()[-1].state == "expired"


def test_max_ttl_caps_a_long_approval() -> None:
    clock = Clock()
    g = ApprovalGate("uav0", ApprovalConfig(max_ttl_s=10.0), mission=lambda: None, clock=clock,
                     wall=lambda: clock.t + 4000.0)  # fmt: skip
    rec = g.receive(approval(ttl=3600.0))
    assert rec.expires - rec.received == pytest.approx(10.0)
    clock.t += 10.5
    assert not g.approve("uav0", TAKEOFF)


@pytest.mark.parametrize(
    ("msg", "why"),
    [
        (approval(uav="uav1"), "addressed to uav1"),
        (approval(sender="uav2"), "'uav2' is not an approver"),
        (approval(sender="cmdr"), "'cmdr' is not an approver"),
        (approval(stamp=100.0, ttl=60.0), "expired before it arrived"),
        (approval(mission="m9"), "for mission m9, flying m1"),
    ],
)
def test_refused_approvals_grant_nothing_and_are_recorded(msg: Approval, why: str) -> None:
    g, _clock = gate("normal")
    rec = g.receive(msg)
    assert rec.state == "refused"
    assert rec.reason == why
    assert not g.approve("uav0", TAKEOFF)
    assert g.records()[-1].reason == why


def test_an_approval_id_is_accepted_once() -> None:
    g, _clock = gate("strict")
    assert g.receive(approval()).state == "granted"
    assert g.approve("uav0", TAKEOFF)
    again = g.receive(approval())
    assert again.state == "refused"
    assert again.reason == "duplicate approval id"
    assert not g.approve("uav0", TAKEOFF)
    assert [r.state for r in g.records()] == ["used"]  # the duplicate keeps the original's record


def test_approvers_come_from_config() -> None:
    clock = Clock()
    g = ApprovalGate("uav0", ApprovalConfig(approvers=["ops2"]), clock=clock,
                     wall=lambda: clock.t + 4000.0)  # fmt: skip
    assert g.receive(approval(sender="operator")).state == "refused"
    assert g.receive(approval(sender="ops2", ident="c" * 16)).state == "granted"
    with pytest.raises(ConfigError, match="approver"):
        parse_config({"approvers": ["Bad Name"]}, ApprovalConfig)
    with pytest.raises(ConfigError, match="level"):
        parse_config({"level": "lax"}, ApprovalConfig)


def test_status_changes_are_announced() -> None:
    g, _clock = gate("normal")
    seen: list[int] = []
    g.on_change = lambda: seen.append(1)
    g.offer("take_off")
    g.offer("take_off")  # still pending: no new announcement
    assert len(seen) == 1
    g.receive(approval())
    assert len(seen) == 2


@pytest.mark.parametrize(
    ("text", "kind"),
    [("takeoff", "takeoff"), ("LAND", "land"), (" return_home ", "return_home"),
     ("take_off", "takeoff")],  # the skill's name: an input alias, never written
)  # fmt: skip
def test_parse_action(text: str, kind: str) -> None:
    assert parse_action(text) == kind


@pytest.mark.parametrize("text", ["arm", "return", "take off", ""])
def test_parse_action_names_the_choices(text: str) -> None:
    with pytest.raises(ValueError, match=f"^unknown vehicle action {text!r}; choose takeoff, "
                       "land or return_home$"):  # fmt: skip
        parse_action(text)


def test_every_action_has_one_spelling_and_it_is_the_wire_s() -> None:
    assert set(ACTIONS) == set(get_args(VehicleActionKind))
    assert set(ACTION_ALIASES.values()) <= set(ACTIONS)
    assert not set(ACTION_ALIASES) & set(ACTIONS)
    assert [approve_phrase("uav0", a) for a in ACTIONS] == [
        "approve uav0 takeoff", "approve uav0 land", "approve uav0 return_home"]  # fmt: skip
    # the gate records and announces the canonical action, whichever skill asked
    g, _clock = gate()
    g.offer("take_off")
    assert [(p.action, p.skill) for p in g.pending()] == [("takeoff", "take_off")]
    assert g.receive(approval()).action == "takeoff"
