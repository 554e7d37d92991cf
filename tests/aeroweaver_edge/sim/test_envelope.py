"""The world's envelope check (sim/envelope.py): each rule at its boundary, the counting,
and its agreement with the safety gate, which it must not share any code with."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aeroweaver_edge.config import SafetyConfig
from aeroweaver_edge.contracts.actions import Motion, MoveTo, SetVelocity
from aeroweaver_edge.contracts.wire import Vec3
from aeroweaver_edge.safety.gate import SafetyGate
from aeroweaver_edge.sim import envelope
from aeroweaver_edge.sim.envelope import KEEP, EnvelopeCheck
from tests.helpers.envelope import raw_velocity

CFG = SafetyConfig()  # fence +-70 m, altitude 2..60 m, 11 m/s, 2 m
H = 0.5
HOME: Vec3 = (0.0, 0.0, -5.0)


def kinds(vel: Vec3 | None, pos: Vec3 = HOME, cfg: SafetyConfig = CFG, **kw: object) -> set[str]:
    check = EnvelopeCheck(cfg, H)
    return {k for k, _ in check.judge(pos, vel, **kw)}  # type: ignore[arg-type]


def static(*points: Vec3) -> list[tuple[Vec3, Vec3]]:
    return [(p, p) for p in points]


def test_the_oracle_shares_no_code_with_the_gate() -> None:
    tree = ast.parse(Path(envelope.__file__).read_text(encoding="utf-8"))
    imported = {
        node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module
    } | {a.name for node in ast.walk(tree) if isinstance(node, ast.Import) for a in node.names}
    assert "aeroweaver_edge.safety.gate" not in imported
    assert not any("safety_gate" in m for m in imported)


def test_a_hold_is_always_inside() -> None:
    assert kinds(None) == set()
    assert kinds((0.0, 0.0, 0.0), pos=(500.0, 0.0, -5.0)) == set()  # even outside the fence


def test_speed_cap_is_inclusive_and_three_dimensional() -> None:
    assert kinds((11.0, 0.0, 0.0)) == set()
    assert kinds((11.0 * (1 + 1e-6), 0.0, 0.0)) == {"speed"}
    assert kinds((0.0, 8.0, -8.0)) == {"speed"}  # 11.3 m/s with the climb
    assert kinds((math.inf, 0.0, 0.0)) == {"speed"}  # never a pass for a non-finite command


def test_geofence_judges_the_position_one_horizon_ahead() -> None:
    at_edge: Vec3 = (65.0, 0.0, -5.0)
    assert kinds((10.0, 0.0, 0.0), pos=at_edge) == set()  # lands on 70.0 m exactly
    assert kinds((10.002, 0.0, 0.0), pos=at_edge) == {"geofence"}  # 1 mm beyond
    assert kinds((0.0, -10.002, 0.0), pos=(0.0, -65.0, -5.0)) == {"geofence"}  # east side too
    fence = SafetyConfig(geofence_north_m=(-10.0, 20.0), geofence_east_m=(5.0, 6.0))
    assert kinds((0.0, 1.0, 0.0), pos=(0.0, 5.0, -5.0), cfg=fence) == set()
    assert kinds((0.0, -1.0, 0.0), pos=(0.0, 5.0, -5.0), cfg=fence) == {"geofence"}


def test_outside_the_fence_only_the_way_back_is_allowed() -> None:
    outside: Vec3 = (80.0, 0.0, -5.0)
    assert kinds((-11.0, 0.0, 0.0), pos=outside) == set()  # 5.5 m nearer: still out, fine
    assert kinds((0.0, 11.0, 0.0), pos=outside) == {"geofence"}  # staying 10 m out
    assert kinds((1.0, 0.0, 0.0), pos=outside) == {"geofence"}  # further out


def test_altitude_band_is_judged_on_the_predicted_altitude() -> None:
    assert kinds((0.0, 0.0, -6.0), pos=(0.0, 0.0, -57.0)) == set()  # 60 m exactly
    assert kinds((0.0, 0.0, -6.01), pos=(0.0, 0.0, -57.0)) == {"altitude"}
    assert kinds((0.0, 0.0, 6.01), pos=(0.0, 0.0, -5.0)) == {"altitude"}  # below 2 m
    assert kinds((0.0, 0.0, -4.0), pos=(0.0, 0.0, -1.0)) == set()  # climbing back in


def test_separation_from_a_neighbour_that_stays_put() -> None:
    peer: Vec3 = (5.0, 0.0, -5.0)
    assert kinds((6.0, 0.0, 0.0), neighbours=static(peer)) == set()  # ends 2.0 m away
    assert kinds((6.02, 0.0, 0.0), neighbours=static(peer)) == {"separation"}
    too_close: Vec3 = (1.0, 0.0, -5.0)
    assert kinds((-2.0, 0.0, 0.0), neighbours=static(too_close)) == set()  # backing off
    assert kinds((0.0, 2.0, 0.0), neighbours=static(too_close)) == set()  # not closing in


def test_separation_counts_the_closest_approach_not_only_the_end_point() -> None:
    fast = SafetyConfig(max_speed_mps=60.0)
    peer: Vec3 = (5.0, 0.5, -5.0)
    # Ends 5 m past the peer, but flies within 0.5 m of it on the way.
    assert kinds((20.0, 0.0, 0.0), cfg=fast, neighbours=static(peer)) == {"separation"}


def test_a_pair_flying_at_each_other_is_judged_together() -> None:
    check = EnvelopeCheck(CFG, H)
    pos = {"a": HOME, "b": (7.0, 0.0, -5.0)}
    told = {"a": ["b"], "b": ["a"]}
    # Each alone would end 3.5 m from where the other was; together they meet.
    found = check.check_round(0, 0, pos, {"a": (7.0, 0.0, 0.0), "b": (-7.0, 0.0, 0.0)}, told)
    assert {(v.uav, v.kind) for v in found} == {("a", "separation"), ("b", "separation")}
    # Half the spare gap each, (7 - 2) / 2 = 2.5 m: they end exactly 2 m apart.
    ok = check.check_round(0, 1, pos, {"a": (5.0, 0.0, 0.0), "b": (-5.0, 0.0, 0.0)}, told)
    assert ok == []
    # Only the one who closes in is blamed when the other backs away too slowly.
    one = check.check_round(0, 2, pos, {"a": (11.0, 0.0, 0.0), "b": (0.5, 0.0, 0.0)}, told)
    assert [(v.uav, v.kind) for v in one] == [("a", "separation")]


def test_only_neighbours_the_uav_was_told_about_count() -> None:
    check = EnvelopeCheck(CFG, H)
    pos = {"a": HOME, "b": (3.0, 0.0, -5.0), "evader0": (3.0, 0.0, -5.0)}
    orders: dict[str, Vec3 | None] = {"a": (4.0, 0.0, 0.0), "b": None}
    assert check.check_round(0, 0, pos, orders, {"a": []}) == []
    found = check.check_round(0, 1, pos, orders, {"a": ["evader0"]})  # world-flown: static
    assert [(v.uav, v.kind, v.round) for v in found] == [("a", "separation", 1)]


def test_counting_and_the_summary() -> None:
    check = EnvelopeCheck(CFG, H)
    for r in range(KEEP + 5):
        check.check("uav1", 0, r, HOME, (20.0, 0.0, 0.0))  # speed only
    check.check("uav0", 0, 0, (69.0, 0.0, -5.0), (0.0, 0.0, -150.0))  # speed and altitude
    check.check("uav0", 0, 1, HOME, None)
    check.check("uav2", 0, 1, HOME, (1.0, 0.0, 0.0))
    s = check.summary()
    assert s["total"] == KEEP + 5 + 2
    assert s["by_kind"] == {"speed": KEEP + 6, "geofence": 0, "altitude": 1, "separation": 0}
    assert s["by_uav"] == {"uav0": {"speed": 1, "altitude": 1}, "uav1": {"speed": KEEP + 5}}
    assert (s["checked"], s["moving"]) == (KEEP + 8, KEEP + 7)
    assert len(s["first"]) == KEEP
    assert s["first"][0] == {
        "uav": "uav1",
        "episode": 0,
        "round": 0,
        "kind": "speed",
        "detail": "20.000 m/s > cap 11 m/s",
    }
    assert s["envelope"]["max_speed_mps"] == 11.0
    assert s["horizon_s"] == H
    with pytest.raises(ValueError, match="horizon_s"):
        EnvelopeCheck(CFG, 0.0)


# ------------------------------------------------------------------ against the gate

finite = st.floats(-1e6, 1e6)
motions = st.one_of(
    st.builds(MoveTo, st.tuples(finite, finite, finite), st.one_of(st.none(), st.floats(0, 500))),
    st.builds(SetVelocity, st.tuples(finite, finite, finite)),
    st.builds(SetVelocity, st.tuples(*[st.floats(-30.0, 30.0)] * 3)),
)


@settings(max_examples=600, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    a=st.tuples(st.floats(-69.0, 69.0), st.floats(-69.0, 69.0), st.floats(-59.0, -3.0)),
    offset=st.tuples(*[st.floats(-12.0, 12.0)] * 3),
    ma=motions,
    mb=motions,
)
def test_the_gate_output_is_never_flagged_and_raw_intents_are(
    a: Vec3, offset: Vec3, ma: Motion, mb: Motion
) -> None:
    """Two independent implementations of one envelope agree: whatever the gate lets two
    neighbouring UAVs fly in one round, the oracle finds nothing wrong with."""
    b = (a[0] + offset[0], a[1] + offset[1], a[2] + offset[2])
    gate = SafetyGate(CFG, H)
    ga, gb = gate.gate(ma, a, [b]), gate.gate(mb, b, [a])
    check = EnvelopeCheck(CFG, H)
    orders = {"a": None if ga.held else ga.vel, "b": None if gb.held else gb.vel}
    found = check.check_round(0, 0, {"a": a, "b": b}, orders, {"a": ["b"], "b": ["a"]})
    assert found == [], (ga, gb, found)
    raw = raw_velocity(ma, a, H)
    if raw is not None and math.hypot(*raw) > CFG.max_speed_mps * 1.001:
        assert "speed" in {k for k, _ in check.judge(a, raw)}
