"""The 22-skill task catalogue plus the flight skills, on hand-made observations.

Conventions under test (skills/_common.py): agents are entities of kind ``uav`` told apart
by ``role``; static objects are ``landmark``, ``food``, ``forest``, ``treasure`` (role =
colour), ``slot`` and ``waypoint``; private facts come in ``obs.facts`` (``goal_landmark``,
``private_symbol``, ``key``, ``slot``, ``cargo``) and guesses are recorded as ``guess``.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aeroweaver_edge.contracts.actions import HOLD, Hold, Intent, MoveTo, Outgoing, VehicleAction
from aeroweaver_edge.contracts.observation import Observation, VehicleState
from aeroweaver_edge.contracts.skill_api import SkillContext
from aeroweaver_edge.contracts.wire import Entity, Header, InboxMessage
from aeroweaver_edge.skills import Skill, SkillParamError, SkillRegistry, load_skills

TASK_SKILLS = {
    "cover_landmark",
    "pursue_target",
    "follow_peer",
    "evade_peer",
    "return_in_bounds",
    "signal_goal",
    "follow_signal",
    "encode_message",
    "decode_message",
    "guess_message",
    "take_formation_slot",
    "signal_target",
    "seek_food",
    "seek_cover",
    "collect_treasure",
    "deliver_treasure",
    "meet_collector",
    "approach_goal",
    "approach_decoy",
    "infer_goal",
    "explore_local",
    "hold_position",
}
FLIGHT_SKILLS = {"take_off", "go_to", "orbit", "land", "return_home"}
EARLIER = {"cover_landmark", "explore_local", "return_in_bounds", "hold_position"}
OWN = (-30.0, -30.0, -5.0)


@pytest.fixture(scope="module")
def reg() -> SkillRegistry:
    return load_skills()


def obs(
    *entities: Entity,
    messages: tuple[InboxMessage, ...] = (),
    facts: dict[str, str] | None = None,
    own: tuple[float, float, float] = OWN,
    in_air: bool = True,
    round_: int = 3,
) -> Observation:
    state = VehicleState(pos=own, vel=(0.0, 0.0, 0.0), in_air=in_air)
    return Observation(
        uav="u1",
        episode=0,
        round=round_,
        own=state,
        entities=entities,
        messages=messages,
        facts=dict(facts or {}),
    )


def ctx(role: str, uav_index: int = 1, altitude_m: float = 5.0, **settings: float) -> SkillContext:
    return SkillContext(
        uav="u1",
        uav_index=uav_index,
        role=role,
        task="t",
        altitude_m=altitude_m,
        settings=dict(settings),
    )


def msg(
    kind: str,
    body: dict[str, str | int | float | bool],
    sender: str = "u2",
    round_: int = 2,
    seq: int = 1,
) -> InboxMessage:
    h = Header(sender=sender, epoch=1, seq=seq, stamp=0.0)
    return InboxMessage(h=h, to="u1", round=round_, kind=kind, body=body)


def uav(
    id_: str, role: str, n: float = 0.0, e: float = 0.0, vn: float = 0.0, ve: float = 0.0
) -> Entity:
    return Entity(id=id_, kind="uav", pos=(n, e, -5.0), vel=(vn, ve, 0.0), role=role)


def thing(id_: str, kind: str, n: float, e: float, role: str = "") -> Entity:
    return Entity(id=id_, kind=kind, pos=(n, e, 0.0), role=role)


def run(skill: Skill, o: Observation, c: SkillContext, **params: object) -> Intent:
    return skill.execute(skill.parse_params(params), o, c)


def invocations(skill: Skill, o: Observation, c: SkillContext) -> list[str]:
    return [skill.invocation(p) for p in skill.options(o, c)]


L0, L1, L2 = (
    thing("L0", "landmark", -28, 24),
    thing("L1", "landmark", 4, 34),
    thing("L2", "landmark", 32, 20),
)
EVADER = uav("ev", "evader", 10.0, 5.0, vn=2.0, ve=-1.0)
FORAGER = uav("fg", "forager", -20.0, 10.0)
PURSUER = uav("p2", "pursuer", -25.0, -30.0)
LEADER = uav("ld", "leader", 0.0, 0.0)
COLLECTOR = uav("c2", "collector", -10.0, 0.0)
DEP_RED, DEP_BLUE = uav("dr", "deposit_red", 5.0, 5.0), uav("db", "deposit_blue", -5.0, 5.0)
T_RED, T_BLUE = thing("T0", "treasure", -25, 0, "red"), thing("T1", "treasure", 20, 4, "blue")
FOOD, FOREST = thing("F0", "food", 25, 25), thing("W0", "forest", 15, 17)
SLOT0, SLOT1 = thing("S0", "slot", 22, 12), thing("S1", "slot", 6.8, 32.9)


# ------------------------------------------------------------------ the registry


def test_registry_loads_the_catalogue_and_the_flight_skills(reg: SkillRegistry) -> None:
    assert set(reg.names()) == TASK_SKILLS | FLIGHT_SKILLS
    assert len(reg) == 27


def test_names_and_aliases_are_unique(reg: SkillRegistry) -> None:
    words = [w for s in reg for w in (s.name, *s.doc.aliases)]
    assert len(words) == len(set(words))


@pytest.mark.parametrize("name", sorted(TASK_SKILLS | FLIGHT_SKILLS))
def test_documents_are_complete(reg: SkillRegistry, name: str) -> None:
    skill = reg.get(name)
    d = skill.doc
    for part in (d.tags, d.aliases, d.conditions, d.provenance, skill.body):
        assert part
    assert isinstance(d.inputs, dict)
    assert set(d.inputs) == set(skill.params.model_fields)
    assert set(skill.json_schema()["properties"]) == set(skill.params.model_fields)
    assert skill.prompt_text().startswith(f"{name}: ")


@pytest.mark.parametrize(
    ("name", "words"),
    [
        ("pursue_target", ["pursue", "chase", "intercept", "catch"]),
        ("take_formation_slot", ["formation", "circle", "line", "slot"]),
        ("encode_message", ["private", "encrypted", "secret"]),
        ("evade_peer", ["evade", "flee", "escape"]),
        ("return_home", ["return", "launch", "home"]),
    ],
)
def test_descriptions_carry_the_operators_words(
    reg: SkillRegistry, name: str, words: list[str]
) -> None:
    text = reg.get(name).description.lower()
    assert all(w in text for w in words)


# ------------------------------------------------------------------ role preconditions

# skill, a role allowed to call it, an observation that offers options for that role
TARGET_MSG = msg("target", {"target_id": "ev", "north": 1.0, "east": 2.0})
GOAL_MSG = msg("goal", {"target_id": "L1", "north": 3.0, "east": 33.0})
CIPHER_MSG = msg("ciphertext", {"ciphertext": 1})
CARGO_MSG = msg("intent", {"cargo": "red"}, sender="c2")
GOAL_L1 = {"goal_landmark": "L1"}

ROLE_CASES: list[tuple[str, str, Observation]] = [
    ("pursue_target", "pursuer", obs(EVADER)),
    ("pursue_target", "leader", obs(FORAGER)),
    ("follow_peer", "pursuer", obs(messages=(TARGET_MSG,))),
    ("evade_peer", "evader", obs(PURSUER)),
    ("evade_peer", "forager", obs(LEADER)),
    ("signal_goal", "speaker", obs(facts=GOAL_L1)),
    ("follow_signal", "listener", obs(messages=(GOAL_MSG,))),
    ("encode_message", "sender", obs(facts={"private_symbol": "2", "key": "3"})),
    ("decode_message", "receiver", obs(messages=(CIPHER_MSG,), facts={"key": "3"})),
    ("guess_message", "eavesdropper", obs(messages=(CIPHER_MSG,))),
    ("take_formation_slot", "member", obs(SLOT0)),
    ("signal_target", "leader", obs(FORAGER)),
    ("seek_food", "forager", obs(FOOD)),
    ("seek_cover", "forager", obs(FOREST)),
    ("collect_treasure", "collector", obs(T_RED)),
    ("deliver_treasure", "collector", obs(DEP_RED, facts={"cargo": "red"})),
    ("meet_collector", "deposit_red", obs(COLLECTOR, messages=(CARGO_MSG,))),
    ("approach_goal", "informed", obs(L0, L1, facts=GOAL_L1)),
    ("approach_decoy", "informed", obs(L0, L1, facts=GOAL_L1)),
    ("infer_goal", "adversary", obs(L0, L1)),
]


@pytest.mark.parametrize(("name", "role", "o"), ROLE_CASES)
def test_allowed_role_gets_options_and_every_option_round_trips(
    reg: SkillRegistry, name: str, role: str, o: Observation
) -> None:
    skill = reg.get(name)
    opts = skill.options(o, ctx(role))
    assert opts
    for p in opts:
        assert skill.parse_params(p.model_dump()) == p
        assert skill.execute(p, o, ctx(role)) != HOLD  # it does something: move, say or record


@pytest.mark.parametrize(("name", "role", "o"), ROLE_CASES)
@pytest.mark.parametrize("wrong", ["searcher", "", "member_of_the_public"])
def test_other_roles_get_no_options_and_execute_holds(
    reg: SkillRegistry, name: str, role: str, o: Observation, wrong: str
) -> None:
    skill = reg.get(name)
    assert skill.options(o, ctx(wrong)) == []
    [option] = skill.options(o, ctx(role))[:1]
    assert skill.execute(option, o, ctx(wrong)) == HOLD


@pytest.mark.parametrize(("name", "role", "o"), ROLE_CASES)
def test_executors_are_pure(reg: SkillRegistry, name: str, role: str, o: Observation) -> None:
    skill = reg.get(name)
    memo_before = dict(o.memo)
    for p in skill.options(o, ctx(role)):
        assert skill.execute(p, o, ctx(role)) == skill.execute(p, o, ctx(role))
    assert o.memo == memo_before


# ------------------------------------------------------------------ target missing -> hold

MISSING_CASES = [
    ("pursue_target", "pursuer", {"target_id": "ev"}),
    ("evade_peer", "evader", {"target_id": "p2"}),
    ("signal_target", "leader", {"target_id": "fg"}),
    ("follow_peer", "pursuer", {"target_id": "ev"}),
    ("follow_signal", "listener", {"target_id": "L1"}),
    ("take_formation_slot", "member", {"target_id": "S0"}),
    ("seek_food", "forager", {"target_id": "F0"}),
    ("seek_cover", "forager", {"target_id": "W0"}),
    ("collect_treasure", "collector", {"target_id": "T0"}),
    ("deliver_treasure", "collector", {"target_id": "dr"}),
    ("meet_collector", "deposit_red", {"target_id": "c2"}),
    ("approach_goal", "informed", {"target_id": "L1"}),
    ("approach_decoy", "informed", {"target_id": "L0"}),
    ("infer_goal", "adversary", {"target_id": "L0"}),
]


@pytest.mark.parametrize(("name", "role", "params"), MISSING_CASES)
def test_missing_target_holds(
    reg: SkillRegistry, name: str, role: str, params: dict[str, object]
) -> None:
    memo = {"goal_landmark": "L1", "cargo": "red" if name == "deliver_treasure" else ""}
    skill = reg.get(name)
    assert run(skill, obs(facts=memo), ctx(role), **params) == HOLD
    assert skill.options(obs(facts=memo), ctx(role)) == []


@pytest.mark.parametrize(
    ("name", "role", "params", "decoy"),
    [
        ("pursue_target", "pursuer", {"target_id": "p2"}, PURSUER),  # a pursuer is no target
        ("evade_peer", "evader", {"target_id": "c2"}, COLLECTOR),  # a collector is no threat
        ("seek_food", "forager", {"target_id": "W0"}, FOREST),
        ("seek_cover", "forager", {"target_id": "F0"}, FOOD),
        ("collect_treasure", "collector", {"target_id": "L0"}, L0),
        ("take_formation_slot", "member", {"target_id": "L0"}, L0),
        ("infer_goal", "adversary", {"target_id": "F0"}, FOOD),
    ],
)
def test_target_of_the_wrong_kind_or_role_holds(
    reg: SkillRegistry, name: str, role: str, params: dict[str, object], decoy: Entity
) -> None:
    skill = reg.get(name)
    assert run(skill, obs(decoy), ctx(role), **params) == HOLD
    assert skill.options(obs(decoy), ctx(role)) == []


# ------------------------------------------------------------------ pursuit / evasion


def test_pursue_target_aims_at_a_ring_slot_ahead_and_reports_the_target(reg: SkillRegistry) -> None:
    skill = reg.get("pursue_target")
    o = obs(EVADER, FORAGER, PURSUER, L0)
    assert invocations(skill, o, ctx("pursuer")) == [
        "pursue_target(target_id=ev)",
        "pursue_target(target_id=fg)",
    ]
    intent = run(skill, o, ctx("pursuer", uav_index=0), target_id="ev")
    # 1 s lead on (2, -1) m/s plus the 3 m ring slot at bearing 0 for UAV index 0
    assert intent.motion == MoveTo((10.0 + 2.0 + 3.0, 5.0 - 1.0, -5.0))
    assert intent.messages == (
        Outgoing(
            to="*",
            kind="target",
            body={
                "skill": "pursue_target",
                "target_id": "ev",
                "north": 10.0,
                "east": 5.0,
                "vn": 2.0,
                "ve": -1.0,
            },
        ),
    )


def test_pursuers_take_different_ring_slots(reg: SkillRegistry) -> None:
    skill = reg.get("pursue_target")
    aims = []
    for i in range(3):
        intent = run(
            skill, obs(EVADER), ctx("pursuer", uav_index=i, pursuit_lead_s=0.0), target_id="ev"
        )
        assert isinstance(intent.motion, MoveTo)
        aims.append(intent.motion.target)
    for a in aims:
        assert math.dist(a[:2], EVADER.pos[:2]) == pytest.approx(3.0)
    assert min(math.dist(a, b) for i, a in enumerate(aims) for b in aims[i + 1 :]) > 5.0


def test_follow_peer_uses_the_newest_report_and_ignores_malformed_ones(reg: SkillRegistry) -> None:
    skill = reg.get("follow_peer")
    messages = (
        msg("target", {"target_id": "ev", "north": 1.0, "east": 2.0}, round_=1),
        msg("target", {"target_id": "ev", "north": 5.0, "east": 6.0}, sender="u3", round_=2),
        msg("target", {"target_id": "fg", "north": "far", "east": 2.0}),
        msg("target", {"target_id": "zz", "north": float("nan"), "east": 2.0}),
        msg("target", {"north": 1.0, "east": 1.0}),
        msg("target", {"target_id": "x" * 65, "north": 1.0, "east": 1.0}),
        msg("intent", {"target_id": "L0", "north": 1.0, "east": 1.0}),
    )
    o = obs(messages=messages)
    assert invocations(skill, o, ctx("pursuer")) == ["follow_peer(target_id=ev)"]
    intent = run(skill, o, ctx("pursuer"), target_id="ev")
    assert intent.motion == MoveTo((5.0, 6.0, -5.0))
    assert [m.kind for m in intent.messages] == ["intent"]
    assert intent.messages[0].body["skill"] == "follow_peer"
    assert run(skill, o, ctx("pursuer"), target_id="fg") == HOLD


def test_signal_target_holds_still_and_reports(reg: SkillRegistry) -> None:
    intent = run(reg.get("signal_target"), obs(FORAGER), ctx("leader"), target_id="fg")
    assert intent.motion == Hold()
    [report] = intent.messages
    assert (report.to, report.kind) == ("*", "target")
    assert report.body["target_id"] == "fg"
    assert (report.body["north"], report.body["east"]) == (-20.0, 10.0)


def test_a_signalled_target_can_be_followed(reg: SkillRegistry) -> None:
    [report] = run(reg.get("signal_target"), obs(FORAGER), ctx("leader"), target_id="fg").messages
    inbox = obs(messages=(msg(report.kind, report.body, sender="ld"),))
    follow = reg.get("follow_peer")
    assert invocations(follow, inbox, ctx("pursuer")) == ["follow_peer(target_id=fg)"]
    assert run(follow, inbox, ctx("pursuer"), target_id="fg").motion == MoveTo((-20.0, 10.0, -5.0))


def test_evade_peer_flies_to_the_mirrored_point(reg: SkillRegistry) -> None:
    threat = uav("p2", "pursuer", -30.0, -60.0)  # 30 m due west
    intent = run(reg.get("evade_peer"), obs(threat), ctx("evader"), target_id="p2")
    assert intent.motion == MoveTo((-30.0, 0.0, -5.0))
    assert intent.messages[0].body["target_id"] == "p2"


def test_evade_peer_escapes_at_least_the_minimum_distance(reg: SkillRegistry) -> None:
    threat = uav("p2", "pursuer", -30.0, -32.0)  # 2 m west
    intent = run(reg.get("evade_peer"), obs(threat), ctx("forager"), target_id="p2")
    assert isinstance(intent.motion, MoveTo)
    assert intent.motion.target == pytest.approx((-30.0, -10.0, -5.0))


def test_evade_peer_stays_inside_the_arena(reg: SkillRegistry) -> None:
    threat = uav("p2", "pursuer", 0.0, 50.0)
    intent = run(
        reg.get("evade_peer"), obs(threat, own=(0.0, 55.0, -5.0)), ctx("evader"), target_id="p2"
    )
    assert intent.motion == MoveTo((0.0, 60.0, -5.0))


def test_evade_peer_with_the_threat_on_top_flees_toward_the_centre(reg: SkillRegistry) -> None:
    threat = uav("p2", "pursuer", -30.0, -30.0)
    intent = run(reg.get("evade_peer"), obs(threat), ctx("evader"), target_id="p2")
    assert isinstance(intent.motion, MoveTo)
    n, e, _ = intent.motion.target
    assert math.hypot(n, e) < math.hypot(-30.0, -30.0)


# ------------------------------------------------------------------ guided navigation


def test_signal_goal_offers_only_the_private_goal_and_stays_put(reg: SkillRegistry) -> None:
    skill = reg.get("signal_goal")
    o = obs(L0, L1, facts={"goal_landmark": "L1"})
    assert invocations(skill, o, ctx("speaker")) == ["signal_goal(target_id=L1)"]
    intent = run(skill, o, ctx("speaker"), target_id="L1")
    assert intent.motion == Hold()
    assert intent.messages == (
        Outgoing(
            to="*",
            kind="goal",
            body={"skill": "signal_goal", "target_id": "L1", "north": 4.0, "east": 34.0},
            purpose="task",  # the listener cannot do its task without it
        ),
    )
    assert run(skill, o, ctx("speaker"), target_id="L0") == HOLD  # never signal a false goal


def test_signal_goal_without_seeing_the_landmark_names_it_only(reg: SkillRegistry) -> None:
    skill = reg.get("signal_goal")
    [message] = run(
        skill, obs(facts={"goal_landmark": "L2"}), ctx("speaker"), target_id="L2"
    ).messages
    assert message.body == {"skill": "signal_goal", "target_id": "L2"}
    assert skill.options(obs(L0), ctx("speaker")) == []  # no private goal, nothing to say


def test_follow_signal_prefers_the_seen_landmark_then_the_reported_position(
    reg: SkillRegistry,
) -> None:
    skill = reg.get("follow_signal")
    goal = msg("goal", {"target_id": "L1", "north": 3.0, "east": 33.0})
    assert run(skill, obs(L1, messages=(goal,)), ctx("listener"), target_id="L1").motion == MoveTo(
        (4.0, 34.0, -5.0)
    )
    assert run(skill, obs(messages=(goal,)), ctx("listener"), target_id="L1").motion == MoveTo(
        (3.0, 33.0, -5.0)
    )
    bare = msg("goal", {"target_id": "L1"})
    assert run(skill, obs(messages=(bare,)), ctx("listener"), target_id="L1") == HOLD
    assert skill.options(obs(messages=(bare,)), ctx("listener")) == []
    assert invocations(skill, obs(L1, messages=(bare,)), ctx("listener")) == [
        "follow_signal(target_id=L1)"
    ]
    assert run(skill, obs(L0, messages=(goal,)), ctx("listener"), target_id="L0") == HOLD


# ------------------------------------------------------------------ private communication


def _deliver(intent: Intent, sender: str = "alice") -> tuple[InboxMessage, ...]:
    return tuple(msg(m.kind, m.body, sender=sender) for m in intent.messages)


@pytest.mark.parametrize("plain", range(4))
@pytest.mark.parametrize("key", range(4))
def test_encode_decode_round_trip(reg: SkillRegistry, plain: int, key: int) -> None:
    encode, decode = reg.get("encode_message"), reg.get("decode_message")
    sender = obs(facts={"private_symbol": str(plain), "key": str(key)})
    [option] = encode.options(sender, ctx("sender"))
    assert option.model_dump() == {"symbol": plain}
    sent = encode.execute(option, sender, ctx("sender"))
    assert sent.motion == Hold()
    assert sent.messages == (
        Outgoing(
            to="*",
            kind="ciphertext",
            body={"skill": "encode_message", "ciphertext": plain ^ key},
            purpose="task",  # the receiver's whole task
        ),
    )
    receiver = obs(messages=_deliver(sent), facts={"key": str(key)})
    [decoded] = decode.options(receiver, ctx("receiver"))
    assert decoded.model_dump() == {"symbol": plain}
    recorded = decode.execute(decoded, receiver, ctx("receiver"))
    assert recorded == Intent(Hold(), memo={"guess": str(plain)})


def test_encode_needs_both_private_symbol_and_key(reg: SkillRegistry) -> None:
    skill = reg.get("encode_message")
    for memo in (
        {"private_symbol": "1"},
        {"key": "1"},
        {"private_symbol": "4", "key": "1"},
        {"private_symbol": "1", "key": "x"},
        {},
    ):
        assert skill.options(obs(facts=memo), ctx("sender")) == []
    assert run(skill, obs(facts={"private_symbol": "1"}), ctx("sender"), symbol=1) == HOLD


def test_decode_needs_a_key_and_a_well_formed_ciphertext(reg: SkillRegistry) -> None:
    skill = reg.get("decode_message")
    good = msg("ciphertext", {"ciphertext": 2})
    assert skill.options(obs(messages=(good,)), ctx("receiver")) == []
    bad = tuple(msg("ciphertext", {"ciphertext": c}) for c in (7, -1, True, "2", 1.5))
    assert skill.options(obs(messages=bad, facts={"key": "1"}), ctx("receiver")) == []


def test_guess_message_offers_every_symbol_after_an_interception(reg: SkillRegistry) -> None:
    skill = reg.get("guess_message")
    assert skill.options(obs(), ctx("eavesdropper")) == []
    o = obs(messages=(msg("ciphertext", {"ciphertext": 3}),))
    assert invocations(skill, o, ctx("eavesdropper")) == [
        f"guess_message(symbol={s})" for s in range(4)
    ]
    assert run(skill, o, ctx("eavesdropper"), symbol=3) == Intent(Hold(), memo={"guess": "3"})


@pytest.mark.parametrize("name", ["encode_message", "decode_message", "guess_message"])
@pytest.mark.parametrize("bad", [4, -1, 1.0, "1", True])
def test_symbols_outside_0_to_3_are_refused(reg: SkillRegistry, name: str, bad: object) -> None:
    with pytest.raises(SkillParamError):
        reg.get(name).parse_params({"symbol": bad})


# ------------------------------------------------------------------ formation


def test_take_formation_slot_offers_only_the_owned_slot(reg: SkillRegistry) -> None:
    skill = reg.get("take_formation_slot")
    assert invocations(skill, obs(SLOT0, SLOT1, facts={"slot": "S1"}), ctx("member")) == [
        "take_formation_slot(target_id=S1)"
    ]
    assert invocations(skill, obs(SLOT0, SLOT1), ctx("member")) == [
        "take_formation_slot(target_id=S0)",
        "take_formation_slot(target_id=S1)",
    ]
    intent = run(skill, obs(SLOT0, SLOT1), ctx("member", altitude_m=8.0), target_id="S1")
    assert intent.motion == MoveTo((6.8, 32.9, -8.0))
    assert intent.messages[0].body == {
        "skill": "take_formation_slot",
        "target_id": "S1",
        "north": 6.8,
        "east": 32.9,
    }


# ------------------------------------------------------------------ world communication


@pytest.mark.parametrize(("name", "target"), [("seek_food", FOOD), ("seek_cover", FOREST)])
def test_forager_moves(reg: SkillRegistry, name: str, target: Entity) -> None:
    skill = reg.get(name)
    o = obs(FOOD, FOREST, LEADER)
    assert invocations(skill, o, ctx("forager")) == [f"{name}(target_id={target.id})"]
    intent = run(skill, o, ctx("forager"), target_id=target.id)
    assert intent.motion == MoveTo((target.pos[0], target.pos[1], -5.0))
    assert intent.messages[0].kind == "intent"


# ------------------------------------------------------------------ collection-delivery


def test_collector_collects_only_when_empty_and_delivers_only_its_colour(
    reg: SkillRegistry,
) -> None:
    collect, deliver = reg.get("collect_treasure"), reg.get("deliver_treasure")
    empty = obs(T_RED, T_BLUE, DEP_RED, DEP_BLUE)
    assert invocations(collect, empty, ctx("collector")) == [
        "collect_treasure(target_id=T0)",
        "collect_treasure(target_id=T1)",
    ]
    assert deliver.options(empty, ctx("collector")) == []
    intent = run(collect, empty, ctx("collector"), target_id="T1")
    assert intent.motion == MoveTo((20.0, 4.0, -5.0))
    assert intent.messages[0].body == {
        "skill": "collect_treasure",
        "target_id": "T1",
        "north": 20.0,
        "east": 4.0,
        "colour": "blue",
        "cargo": "",
    }

    loaded = obs(T_RED, T_BLUE, DEP_RED, DEP_BLUE, facts={"cargo": "blue"})
    assert collect.options(loaded, ctx("collector")) == []
    assert run(collect, loaded, ctx("collector"), target_id="T0") == HOLD
    assert invocations(deliver, loaded, ctx("collector")) == ["deliver_treasure(target_id=db)"]
    assert run(deliver, loaded, ctx("collector"), target_id="dr") == HOLD  # wrong colour
    intent = run(deliver, loaded, ctx("collector"), target_id="db")
    assert intent.motion == MoveTo((-5.0, 5.0, -5.0))
    assert intent.messages[0].body["cargo"] == "blue"


def test_meet_collector_follows_announced_cargo(reg: SkillRegistry) -> None:
    skill = reg.get("meet_collector")
    c3 = uav("c3", "collector", 12.0, -3.0)
    messages = (
        msg("intent", {"cargo": "red"}, sender="c2", round_=1, seq=4),
        msg("intent", {"cargo": ""}, sender="c2", round_=2, seq=5),  # delivered since
        msg("intent", {"cargo": "red"}, sender="c3", round_=2, seq=9),
        msg("intent", {"cargo": "blue"}, sender="dr", round_=2, seq=2),
    )
    o = obs(COLLECTOR, c3, DEP_BLUE, messages=messages)
    assert invocations(skill, o, ctx("deposit_red")) == ["meet_collector(target_id=c3)"]
    assert skill.options(o, ctx("deposit_blue")) == []
    assert skill.options(o, ctx("deposit_")) == []
    assert run(skill, o, ctx("deposit_red"), target_id="c3").motion == MoveTo((12.0, -3.0, -5.0))
    assert run(skill, o, ctx("deposit_red"), target_id="c2") == HOLD


def test_collector_intent_feeds_meet_collector(reg: SkillRegistry) -> None:
    loaded = obs(DEP_RED, facts={"cargo": "red"})
    sent = run(reg.get("deliver_treasure"), loaded, ctx("collector"), target_id="dr")
    deposit_view = obs(uav("u1", "collector", -30.0, -30.0), messages=_deliver(sent, sender="u1"))
    assert invocations(reg.get("meet_collector"), deposit_view, ctx("deposit_red")) == [
        "meet_collector(target_id=u1)"
    ]


# ------------------------------------------------------------------ goal concealment


def test_informed_agent_goal_and_decoys(reg: SkillRegistry) -> None:
    goal, decoy = reg.get("approach_goal"), reg.get("approach_decoy")
    o = obs(L0, L1, L2, facts={"goal_landmark": "L1"})
    assert invocations(goal, o, ctx("informed")) == ["approach_goal(target_id=L1)"]
    assert invocations(decoy, o, ctx("informed")) == [
        "approach_decoy(target_id=L0)",
        "approach_decoy(target_id=L2)",
    ]
    assert run(goal, o, ctx("informed"), target_id="L1").motion == MoveTo((4.0, 34.0, -5.0))
    assert run(goal, o, ctx("informed"), target_id="L0") == HOLD
    assert run(decoy, o, ctx("informed"), target_id="L1") == HOLD
    assert run(decoy, o, ctx("informed"), target_id="L2").motion == MoveTo((32.0, 20.0, -5.0))
    unknown = obs(L0, L1, L2)
    assert goal.options(unknown, ctx("informed")) == []
    assert decoy.options(unknown, ctx("informed")) == []
    assert run(decoy, unknown, ctx("informed"), target_id="L2") == HOLD


def test_infer_goal_offers_every_visible_landmark(reg: SkillRegistry) -> None:
    skill = reg.get("infer_goal")
    o = obs(L0, L2, uav("i1", "informed", 30.0, 20.0))
    assert invocations(skill, o, ctx("adversary")) == [
        "infer_goal(target_id=L0)",
        "infer_goal(target_id=L2)",
    ]
    assert run(skill, o, ctx("adversary"), target_id="L2").motion == MoveTo((32.0, 20.0, -5.0))


# ------------------------------------------------------------------ flight skills


@pytest.mark.parametrize(
    ("name", "on_ground"),
    [("take_off", True), ("land", False), ("return_home", False)],
)
def test_vehicle_action_skills_hold_and_are_offered_in_the_right_state(
    reg: SkillRegistry, name: str, on_ground: bool
) -> None:
    skill = reg.get(name)
    ground, air = obs(in_air=False), obs(in_air=True)
    offered, refused = (ground, air) if on_ground else (air, ground)
    [option] = skill.options(offered, ctx("any"))
    assert skill.options(refused, ctx("any")) == []
    intent = skill.execute(option, offered, ctx("any"))
    # The motion is a hold; the vehicle action goes to the daemon's flight phases.
    assert intent.motion == HOLD.motion
    assert intent.messages == ()
    assert intent.action == VehicleAction(KIND[name])
    assert any("vehicle port" in c for c in skill.doc.conditions)


KIND = {"take_off": "takeoff", "land": "land", "return_home": "return_home"}


def test_take_off_altitude_is_bounded(reg: SkillRegistry) -> None:
    skill = reg.get("take_off")
    assert skill.parse_params({"altitude_m": 10.0}).model_dump() == {"altitude_m": 10.0}
    for bad in (1.0, 61.0, -5.0):
        with pytest.raises(SkillParamError):
            skill.parse_params({"altitude_m": bad})


def test_go_to_flies_to_the_point_at_the_given_or_default_altitude(reg: SkillRegistry) -> None:
    skill = reg.get("go_to")
    assert run(skill, obs(), ctx("any", altitude_m=6.0), north_m=10.0, east_m=-20.0) == Intent(
        MoveTo((10.0, -20.0, -6.0))
    )
    assert run(skill, obs(), ctx("any"), north_m=10, east_m=-20, altitude_m=15).motion == MoveTo(
        (10.0, -20.0, -15.0)
    )
    for bad in (
        {"north_m": 71.0, "east_m": 0.0},
        {"north_m": 0.0, "east_m": -70.5},
        {"north_m": 0.0},
        {"north_m": 0.0, "east_m": 0.0, "altitude_m": 0.5},
    ):
        with pytest.raises(SkillParamError):
            skill.parse_params(bad)


def test_go_to_and_orbit_offer_visible_points_of_interest(reg: SkillRegistry) -> None:
    wp = thing("WP1", "waypoint", 12.34, -5.06)
    far = thing("WP2", "waypoint", 90.0, 0.0)
    o = obs(wp, far, L1, FOOD, PURSUER)
    assert invocations(reg.get("go_to"), o, ctx("any")) == [
        "go_to(north_m=12.3, east_m=-5.1, altitude_m=None)",
        "go_to(north_m=4.0, east_m=34.0, altitude_m=None)",
    ]
    assert invocations(reg.get("orbit"), o, ctx("any", orbit_radius_m=15.0)) == [
        "orbit(centre_north_m=12.3, centre_east_m=-5.1, radius_m=15.0)",
        "orbit(centre_north_m=4.0, centre_east_m=34.0, radius_m=15.0)",
    ]
    bad_radius = ctx("any", orbit_radius_m=500.0)
    assert [p.model_dump()["radius_m"] for p in reg.get("orbit").options(o, bad_radius)] == [
        10.0
    ] * 2
    assert reg.get("go_to").options(obs(wp, in_air=False), ctx("any")) == []
    assert reg.get("orbit").options(obs(wp, in_air=False), ctx("any")) == []


def test_orbit_steps_clockwise_along_the_circle(reg: SkillRegistry) -> None:
    skill = reg.get("orbit")
    # due north of the centre at the radius: the next point is a short arc toward east
    intent = run(
        skill,
        obs(own=(10.0, 0.0, -5.0)),
        ctx("any"),
        centre_north_m=0,
        centre_east_m=0,
        radius_m=10,
    )
    assert isinstance(intent.motion, MoveTo)
    n, e, d = intent.motion.target
    assert math.hypot(n, e) == pytest.approx(10.0)
    assert (e > 0, n < 10.0, d) == (True, True, -5.0)
    assert math.atan2(e, n) == pytest.approx(6.0 / 10.0)
    # from far away the aim is still on the circle
    far = run(
        skill,
        obs(own=(60.0, 60.0, -5.0)),
        ctx("any"),
        centre_north_m=0,
        centre_east_m=0,
        radius_m=10,
    )
    assert isinstance(far.motion, MoveTo)
    assert math.hypot(*far.motion.target[:2]) == pytest.approx(10.0)


def test_orbit_traces_the_whole_circle(reg: SkillRegistry) -> None:
    skill = reg.get("orbit")
    pos = (10.0, 0.0, -5.0)
    seen = []
    for _ in range(12):
        intent = run(
            skill, obs(own=pos), ctx("any"), centre_north_m=0, centre_east_m=0, radius_m=10
        )
        assert isinstance(intent.motion, MoveTo)
        pos = intent.motion.target
        seen.append(math.atan2(pos[1], pos[0]) % (2 * math.pi))
    assert max(seen) - min(seen) > 1.5 * math.pi


# ------------------------------------------------------------------ invariants


ROLES = [
    *("searcher", "pursuer", "evader", "speaker", "listener", "sender", "receiver"),
    *("eavesdropper", "member", "leader", "forager", "collector", "deposit_red"),
    *("deposit_blue", "informed", "adversary"),
]


def everything() -> Observation:
    """One crowded view with every entity kind, private fact and message kind."""
    memo = {"goal_landmark": "L1", "private_symbol": "1", "key": "2", "cargo": "red"}
    entities = (L0, L1, EVADER, FORAGER, PURSUER, LEADER, COLLECTOR, DEP_RED, T_RED, FOOD)
    return obs(
        *entities, FOREST, SLOT0, facts=memo, messages=(TARGET_MSG, GOAL_MSG, CIPHER_MSG, CARGO_MSG)
    )


@pytest.mark.parametrize("role", ROLES)
def test_every_option_for_every_role_executes_to_a_finite_intent(
    reg: SkillRegistry, role: str
) -> None:
    o = everything()
    for skill in reg:
        for p in skill.options(o, ctx(role)):
            intent = skill.execute(p, o, ctx(role))
            if isinstance(intent.motion, MoveTo):
                assert all(math.isfinite(x) for x in intent.motion.target)
            for m in intent.messages:
                assert m.kind in {"intent", "target", "goal", "ciphertext"}
                assert not {"private_symbol", "key"} & set(m.body)


# ------------------------------------------------------------------ robustness

_REG = load_skills()
NEW_SKILLS = sorted(TASK_SKILLS - EARLIER | FLIGHT_SKILLS)

_ids = st.one_of(st.sampled_from(["L0", "L1", "ev", "c2", "S0", "T0", ""]), st.text(max_size=80))
_floats = st.floats(allow_nan=True, allow_infinity=True)
_kinds = st.sampled_from(["landmark", "uav", "food", "forest", "treasure", "slot", "waypoint", "x"])
_roles = st.sampled_from(["", "red", "blue", "evader", "forager", "pursuer", "leader", "collector"])
_scalars = st.one_of(st.booleans(), st.integers(-10, 10), _floats, _ids)
_entities = st.builds(
    Entity,
    id=_ids,
    kind=_kinds,
    pos=st.tuples(_floats, _floats, _floats),
    vel=st.tuples(_floats, _floats, _floats),
    role=_roles,
)
_bodies = st.dictionaries(
    st.sampled_from(["target_id", "north", "east", "ciphertext", "cargo", "skill"]), _scalars
)
_messages = st.builds(
    msg,
    kind=st.sampled_from(["target", "goal", "ciphertext", "intent"]),
    body=_bodies,
    sender=st.sampled_from(["u2", "c2", "ev"]),
    round_=st.integers(0, 5),
    seq=st.integers(1, 9),
)
_facts = st.dictionaries(
    st.sampled_from(["goal_landmark", "private_symbol", "key", "slot", "cargo"]),
    st.one_of(_ids, st.sampled_from(["0", "1", "2", "3", "red", "blue"])),
)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    entities=st.lists(_entities, max_size=6),
    messages=st.lists(_messages, max_size=5),
    facts=_facts,
    in_air=st.booleans(),
)
def test_no_observation_makes_a_skill_raise(
    entities: list[Entity], messages: list[InboxMessage], facts: dict[str, str], in_air: bool
) -> None:
    o = obs(*entities, messages=tuple(messages), facts=facts, in_air=in_air)
    for role in ROLES:
        c = ctx(role)
        for skill in (_REG.get(n) for n in NEW_SKILLS):
            for p in skill.options(o, c):
                assert isinstance(skill.execute(p, o, c), Intent)
