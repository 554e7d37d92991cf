"""The safety gate: unit cases plus an envelope property checked by an independent oracle.

The oracle does not reuse any of the gate's arithmetic: it only checks the outcome
(finite, within the speed cap, and the position one horizon ahead inside the geofence and
altitude band) against the config, as DESIGN §4 step 5 and docs/notes/safety.md test 4 ask.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aeroweaver_edge.config import SafetyConfig
from aeroweaver_edge.contracts.actions import Hold, Motion, MoveTo, SetVelocity
from aeroweaver_edge.contracts.wire import Vec3
from aeroweaver_edge.safety.gate import GatedCommand, SafetyGate

CFG = SafetyConfig()  # fence ±70 m, altitude 2..60 m (down -60..-2), 11 m/s, 2 m separation
H = 0.5
GATE = SafetyGate(CFG, horizon_s=H)
HOME: Vec3 = (0.0, 0.0, -5.0)
NAN = math.nan
INF = math.inf


def speed(v: Sequence[float]) -> float:
    return math.sqrt(sum(x * x for x in v))


def ahead(pos: Vec3, vel: Vec3, horizon: float = H) -> Vec3:
    return (pos[0] + vel[0] * horizon, pos[1] + vel[1] * horizon, pos[2] + vel[2] * horizon)


def inside(cfg: SafetyConfig, p: Sequence[float], tol: float = 1e-6) -> bool:
    """Independent envelope check: altitude is ``-down``."""
    (n_lo, n_hi), (e_lo, e_hi) = cfg.geofence_north_m, cfg.geofence_east_m
    a_lo, a_hi = cfg.altitude_band_m
    return (
        n_lo - tol <= p[0] <= n_hi + tol
        and e_lo - tol <= p[1] <= e_hi + tol
        and a_lo - tol <= -p[2] <= a_hi + tol
    )


def assert_hold(out: GatedCommand, why: str | None = None) -> None:
    assert out.held
    assert out.vel == (0.0, 0.0, 0.0)
    if why is not None:
        assert any(why in v for v in out.violations), out.violations


# ------------------------------------------------------------------ unit cases


def test_hold_is_zero_velocity() -> None:
    out = GATE.gate(Hold(), HOME)
    assert_hold(out)
    assert out.violations == ()


def test_move_to_near_target_arrives_in_one_horizon() -> None:
    out = GATE.gate(MoveTo((2.0, 0.0, -5.0)), HOME)
    assert not out.held
    assert out.vel == pytest.approx((4.0, 0.0, 0.0))
    assert out.violations == ()


def test_move_to_far_target_flies_at_the_cap() -> None:
    out = GATE.gate(MoveTo((30.0, 40.0, -5.0)), HOME)
    assert speed(out.vel) == pytest.approx(11.0)
    assert out.vel == pytest.approx((6.6, 8.8, 0.0))


def test_move_to_honours_a_lower_requested_speed() -> None:
    out = GATE.gate(MoveTo((30.0, 0.0, -5.0), speed=3.0), HOME)
    assert out.vel == pytest.approx((3.0, 0.0, 0.0))


def test_move_to_target_outside_is_clamped_into_the_geofence() -> None:
    pos: Vec3 = (69.0, -69.5, -5.0)
    out = GATE.gate(MoveTo((500.0, -500.0, -5.0)), pos)
    assert not out.held
    assert "target clamped into envelope" in out.violations
    assert out.vel == pytest.approx((2.0, -1.0, 0.0))  # exactly onto the corner (70, -70)
    assert inside(CFG, ahead(pos, out.vel))


def test_move_to_below_the_floor_is_clamped_into_the_altitude_band() -> None:
    out = GATE.gate(MoveTo((0.0, 0.0, 0.0)), HOME)  # target on the ground
    assert "target clamped into envelope" in out.violations
    assert ahead(HOME, out.vel)[2] == pytest.approx(-2.0)


def test_move_to_target_at_own_position_is_zero_velocity_not_hold() -> None:
    out = GATE.gate(MoveTo(HOME), HOME)
    assert out == GatedCommand((0.0, 0.0, 0.0), held=False)


def test_velocity_is_speed_capped_along_its_direction() -> None:
    out = GATE.gate(SetVelocity((30.0, 40.0, 0.0)), HOME)
    assert not out.held
    assert out.vel == pytest.approx((6.6, 8.8, 0.0))
    assert "speed capped" in out.violations


def test_velocity_under_the_cap_passes_unchanged() -> None:
    out = GATE.gate(SetVelocity((3.0, -4.0, 0.5)), HOME)
    assert out == GatedCommand((3.0, -4.0, 0.5), held=False)


def test_velocity_is_clamped_at_the_fence_edge() -> None:
    pos: Vec3 = (69.0, 0.0, -5.0)
    out = GATE.gate(SetVelocity((10.0, 0.0, 0.0)), pos)
    assert not out.held
    assert out.vel == pytest.approx((2.0, 0.0, 0.0))
    assert "velocity clamped at envelope edge" in out.violations
    assert ahead(pos, out.vel)[0] == pytest.approx(70.0)


def test_velocity_along_the_fence_keeps_the_parallel_component() -> None:
    pos: Vec3 = (70.0, 0.0, -5.0)
    out = GATE.gate(SetVelocity((5.0, 5.0, 0.0)), pos)
    assert out.vel == pytest.approx((0.0, 5.0, 0.0))


def test_descent_is_clamped_at_the_altitude_floor() -> None:
    out = GATE.gate(SetVelocity((0.0, 0.0, 10.0)), HOME)  # +down: toward the ground
    assert out.vel == pytest.approx((0.0, 0.0, 6.0))
    assert ahead(HOME, out.vel)[2] == pytest.approx(-2.0)


def test_climb_is_clamped_at_the_ceiling() -> None:
    pos: Vec3 = (0.0, 0.0, -59.0)
    out = GATE.gate(SetVelocity((0.0, 0.0, -10.0)), pos)
    assert ahead(pos, out.vel)[2] == pytest.approx(-60.0)


@pytest.mark.parametrize(
    "motion",
    [
        SetVelocity((NAN, 0.0, 0.0)),
        SetVelocity((0.0, INF, 0.0)),
        SetVelocity((0.0, 0.0, -INF)),
        MoveTo((NAN, 0.0, -5.0)),
        MoveTo((0.0, INF, -5.0)),
        MoveTo((1.0, 1.0, -5.0), speed=NAN),
        MoveTo((1.0, 1.0, -5.0), speed=INF),
    ],
)
def test_non_finite_commands_hold(motion: Motion) -> None:
    assert_hold(GATE.gate(motion, HOME), "non-finite")


@pytest.mark.parametrize("pos", [(NAN, 0.0, -5.0), (0.0, INF, -5.0), (0.0, 0.0, NAN)])
def test_non_finite_own_position_holds(pos: Vec3) -> None:
    assert_hold(GATE.gate(SetVelocity((1.0, 0.0, 0.0)), pos), "own position")


def test_negative_speed_holds_instead_of_flying_away() -> None:
    """MoveTo(speed < 0) used to fly *away* from the target at |speed| (a best-effort
    repair of invalid input); invalid input must become a hold (docs/notes/safety.md layer 2)."""
    out = GATE.gate(MoveTo((0.0, 0.0, -5.0), speed=-5.0), (0.0, 10.0, -5.0))
    assert_hold(out, "speed")


def test_separation_slows_a_fast_approach_to_half_the_spare_gap() -> None:
    """3 m away, 2 m minimum: at most (3 - 2) / 2 = 0.5 m closer this horizon, so 1 m/s."""
    out = GATE.gate(SetVelocity((4.0, 0.0, 0.0)), HOME, neighbours=[(3.0, 0.0, -5.0)])
    assert not out.held
    assert out.vel == pytest.approx((1.0, 0.0, 0.0), abs=1e-12)
    assert any("separation" in v for v in out.violations)
    slow = GATE.gate(SetVelocity((1.0, 0.0, 0.0)), HOME, neighbours=[(3.0, 0.0, -5.0)])
    assert (slow.vel, slow.violations) == ((1.0, 0.0, 0.0), ())  # exactly the allowance: as is


def test_separation_hold_when_no_spare_gap_is_left() -> None:
    at_minimum: Vec3 = (2.0, 0.0, -5.0)
    assert_hold(GATE.gate(SetVelocity((0.1, 0.0, 0.0)), HOME, [at_minimum]), "separation")
    sideways = GATE.gate(SetVelocity((0.0, 4.0, 0.0)), HOME, [at_minimum])
    assert (sideways.held, sideways.vel) == (False, (0.0, 4.0, 0.0))  # not closing in


def test_a_separation_hold_keeps_what_was_noted_before_it() -> None:
    """The hold names separation and the earlier repairs, not the slide it replaces."""
    out = GATE.gate(SetVelocity((20.0, 0.0, 0.0)), HOME, [(2.0, 0.0, -5.0)])
    assert (out.held, out.vel) == (True, (0.0, 0.0, 0.0))
    assert out.violations == ("speed capped", "separation: 2.0 m, minimum 2.0 m")


def test_a_diagonal_approach_slides_past_keeping_the_rest_of_the_velocity() -> None:
    """Only the approach beyond the allowance is taken away, along the line to the
    neighbour: 4 m/s north past a neighbour north-east keeps the closing speed at the
    allowance and gains a westward component."""
    peer: Vec3 = (3.0, 3.0, -5.0)
    out = GATE.gate(SetVelocity((4.0, 0.0, 0.0)), HOME, [peer])
    gap = math.dist(HOME, peer)
    u = ((peer[0] - HOME[0]) / gap, (peer[1] - HOME[1]) / gap, 0.0)
    allowed = (gap - CFG.min_separation_m) / 2  # metres closer within one horizon
    excess = (4.0 * u[0]) * H - allowed
    want = (4.0 - excess / H * u[0], -excess / H * u[1], 0.0)
    assert not out.held
    assert out.vel == pytest.approx(want, abs=1e-12)
    assert out.vel[1] < 0  # it slid west, it did not just slow down
    assert out.violations == ("slid past for separation (4.2 m, minimum 2.0 m)",)


def test_a_body_that_runs_no_gate_may_be_approached_to_the_minimum() -> None:
    """An evader the world flies keeps no half of the gap: the pursuer may use all of it."""
    evader: Vec3 = (6.0, 0.0, -5.0)
    out = GATE.gate(SetVelocity((11.0, 0.0, 0.0)), HOME, others=[evader])
    assert out.vel == pytest.approx((8.0, 0.0, 0.0))  # (6 - 2) m in 0.5 s
    assert math.dist(ahead(HOME, out.vel), evader) == pytest.approx(2.0)
    as_peer = GATE.gate(SetVelocity((11.0, 0.0, 0.0)), HOME, neighbours=[evader])
    assert as_peer.vel == pytest.approx((4.0, 0.0, 0.0))  # a gated peer: half of it
    assert_hold(GATE.gate(SetVelocity((1.0, 0.0, 0.0)), HOME, others=[(2.0, 0.0, -5.0)]))


def test_two_uavs_flying_at_each_other_end_the_round_apart() -> None:
    """Each judges only the other's last known position, yet the pair keeps the minimum:
    the old rule let both take the full step and meet (0.4 m in a swarm test)."""
    a: Vec3 = (0.0, 0.0, -5.0)
    b: Vec3 = (7.5, 0.0, -5.0)
    va = GATE.gate(MoveTo(b, speed=155.0), a, [b]).vel
    vb = GATE.gate(MoveTo(a, speed=155.0), b, [a]).vel
    assert math.dist(ahead(a, va), ahead(b, vb)) == pytest.approx(2.0)
    assert va[0] > 0 > vb[0]  # both still closed in as far as the pair allows


def test_separation_hold_when_move_to_targets_a_neighbour() -> None:
    peer: Vec3 = (1.5, 0.0, -5.0)
    assert_hold(GATE.gate(MoveTo(peer), HOME, neighbours=[peer]), "separation")


def test_separation_allows_moving_away_from_a_too_close_neighbour() -> None:
    out = GATE.gate(SetVelocity((-1.0, 0.0, 0.0)), HOME, neighbours=[(1.0, 0.0, -5.0)])
    assert not out.held  # 1.5 m afterwards: still too close, but no longer closing in
    assert out.vel == (-1.0, 0.0, 0.0)


def test_separation_allows_passing_a_neighbour_at_a_safe_distance() -> None:
    out = GATE.gate(SetVelocity((4.0, 0.0, 0.0)), HOME, neighbours=[(3.0, 5.0, -5.0)])
    assert not out.held


def test_separation_ignores_non_finite_neighbours_and_can_be_disabled() -> None:
    out = GATE.gate(SetVelocity((4.0, 0.0, 0.0)), HOME, neighbours=[(NAN, 0.0, -5.0)])
    assert not out.held
    no_sep = SafetyGate(CFG.model_copy(update={"min_separation_m": 0.0}), H)
    out = no_sep.gate(SetVelocity((4.0, 0.0, 0.0)), HOME, [(2.0, 0.0, -5.0)], [(1.0, 0.0, -5.0)])
    assert (out.held, out.vel, out.violations) == (False, (4.0, 0.0, 0.0), ())  # untouched


def test_separation_checks_every_neighbour() -> None:
    far: Vec3 = (-40.0, 0.0, -5.0)
    near: Vec3 = (2.5, 0.0, -5.0)
    out = GATE.gate(SetVelocity((2.0, 0.0, 0.0)), HOME, [far, near])
    assert out.vel == pytest.approx((0.5, 0.0, 0.0))  # the near one binds: 0.25 m closer
    assert_hold(GATE.gate(SetVelocity((2.0, 0.0, 0.0)), HOME, [far, (1.5, 0.0, -5.0)]))


def test_huge_finite_velocity_keeps_its_direction() -> None:
    """Squares of 1e200 overflow to inf; the cap must still scale along the direction."""
    out = GATE.gate(SetVelocity((1e200, 1e200, 0.0)), HOME)
    assert speed(out.vel) == pytest.approx(11.0)
    assert out.vel[0] == pytest.approx(out.vel[1])


def test_position_outside_the_envelope_returns_within_the_speed_cap() -> None:
    """A UAV found outside the fence (GPS jump, wind) must not be told to jump back
    at (distance / horizon) m/s: it heads back at the cap at most."""
    pos: Vec3 = (100.0, 0.0, -5.0)
    out = GATE.gate(SetVelocity((0.0, 0.0, 0.0)), pos)
    assert not out.held
    assert speed(out.vel) <= CFG.max_speed_mps + 1e-9
    assert out.vel[0] < 0  # back toward the fence


def test_horizon_scales_the_edge_clamp() -> None:
    gate = SafetyGate(CFG, horizon_s=2.0)
    out = gate.gate(SetVelocity((10.0, 0.0, 0.0)), (60.0, 0.0, -5.0))
    assert out.vel == pytest.approx((5.0, 0.0, 0.0))


# ------------------------------------------------------------------ property


finite = st.floats(allow_nan=False, allow_infinity=False)
unit = st.floats(0.0, 1.0)


@st.composite
def envelopes(draw: st.DrawFn) -> SafetyConfig:
    def band(lo: float, hi: float) -> tuple[float, float]:
        a = draw(st.floats(lo, hi))
        return a, a + draw(st.floats(0.5, 500.0))

    if draw(st.booleans()):
        return CFG
    return SafetyConfig(
        geofence_north_m=band(-1000.0, 1000.0),
        geofence_east_m=band(-1000.0, 1000.0),
        altitude_band_m=band(0.0, 200.0),
        max_speed_mps=draw(st.floats(0.1, 60.0)),
        min_separation_m=draw(st.floats(0.5, 10.0)),
    )


def point_in(cfg: SafetyConfig, fn: float, fe: float, fa: float) -> Vec3:
    (n_lo, n_hi), (e_lo, e_hi) = cfg.geofence_north_m, cfg.geofence_east_m
    a_lo, a_hi = cfg.altitude_band_m
    return (
        min(n_hi, n_lo + fn * (n_hi - n_lo)),
        min(e_hi, e_lo + fe * (e_hi - e_lo)),
        -min(a_hi, a_lo + fa * (a_hi - a_lo)),
    )


vec = st.tuples(finite, finite, finite)
small_vec = st.tuples(*[st.floats(-50.0, 50.0)] * 3)
motions = st.one_of(
    st.just(Hold()),
    st.builds(MoveTo, vec, st.one_of(st.none(), finite)),
    st.builds(MoveTo, small_vec, st.one_of(st.none(), st.floats(0.0, 30.0))),
    st.builds(SetVelocity, vec),
    st.builds(SetVelocity, small_vec),
)


@settings(max_examples=2000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    cfg=envelopes(),
    frac=st.tuples(unit, unit, unit),
    motion=motions,
    offsets=st.lists(st.tuples(*[st.floats(-6.0, 6.0)] * 3), max_size=3),
    wild=st.lists(st.tuples(*[st.floats(allow_nan=True)] * 3), max_size=1),
    horizon=st.floats(0.05, 5.0),
)
def test_gated_command_always_fits_the_envelope(
    cfg: SafetyConfig,
    frac: tuple[float, float, float],
    motion: Motion,
    offsets: list[Vec3],
    wild: list[Vec3],
    horizon: float,
) -> None:
    pos = point_in(cfg, *frac)
    neighbours = [(pos[0] + a, pos[1] + b, pos[2] + c) for a, b, c in offsets] + wild
    out = SafetyGate(cfg, horizon).gate(motion, pos, neighbours)

    assert all(math.isfinite(v) for v in out.vel)
    assert speed(out.vel) <= cfg.max_speed_mps + 1e-9
    assert inside(cfg, ahead(pos, out.vel, horizon)), (pos, out)
    if out.held:
        assert out.vel == (0.0, 0.0, 0.0)
    else:
        # Never closer than the minimum separation to a neighbour we are closing in on.
        nxt = ahead(pos, out.vel, horizon)
        for other in neighbours:
            if all(math.isfinite(x) for x in other):
                d_now, d_next = math.dist(pos, other), math.dist(nxt, other)
                assert not (d_next < cfg.min_separation_m and d_next < d_now - 1e-9)


@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    cfg=envelopes(),
    frac=st.tuples(unit, unit, unit),
    offset=st.tuples(*[st.floats(-15.0, 15.0)] * 3),
    motions=st.tuples(motions, motions),
    horizon=st.floats(0.05, 5.0),
)
def test_two_gated_uavs_never_close_in_below_the_minimum_together(
    cfg: SafetyConfig,
    frac: tuple[float, float, float],
    offset: Vec3,
    motions: tuple[Motion, Motion],
    horizon: float,
) -> None:
    """Both decide at once on each other's last known position (the lockstep round)."""
    a = point_in(cfg, *frac)
    b = (a[0] + offset[0], a[1] + offset[1], a[2] + offset[2])
    gate = SafetyGate(cfg, horizon)
    va = gate.gate(motions[0], a, [b]).vel
    vb = gate.gate(motions[1], b, [a]).vel
    d_now = math.dist(a, b)
    d_next = math.dist(ahead(a, va, horizon), ahead(b, vb, horizon))
    assert d_next >= min(cfg.min_separation_m, d_now) - 1e-6
