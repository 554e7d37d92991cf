"""Kinematics and sensing of the kinematic world, checked against hand-computed values."""

from __future__ import annotations

import math

import pytest

from aeroweaver_edge.config import SimConfig
from aeroweaver_edge.contracts.wire import Entity
from aeroweaver_edge.world.kinematics import KinematicWorld

# Defaults: 11 m/s cap, 30 m/s² (1.5 m/s per 0.05 s tick), 0.5 s rounds of 10 ticks.


def one_uav(**kwargs: float) -> KinematicWorld:
    world = KinematicWorld(**kwargs)
    world.add_uav("uav0", (0.0, 0.0))
    return world


def test_round_is_ten_ticks_of_50_ms() -> None:
    world = one_uav()
    world.step()
    assert world.ticks == 10
    assert world.time_s == pytest.approx(0.5)


def test_acceleration_is_limited_per_tick() -> None:
    world = one_uav()
    world.set_velocity("uav0", (11.0, 0.0, 0.0))
    world.step(0.05)
    assert world.body("uav0").vel == pytest.approx((1.5, 0.0, 0.0))
    # Oblique: the limit is on the vector, not per axis.
    world2 = one_uav()
    world2.set_velocity("uav0", (6.0, 8.0))
    world2.step(0.05)
    assert world2.body("uav0").speed == pytest.approx(1.5)
    assert world2.body("uav0").vel[:2] == pytest.approx((0.9, 1.2))


def test_first_round_distance_matches_hand_integration() -> None:
    # Velocities per tick 1.5, 3, ..., 10.5, 11, 11, 11 -> (42 + 33) * 0.05 = 3.75 m.
    world = one_uav()
    world.set_velocity("uav0", (11.0, 0.0))
    world.step()
    body = world.body("uav0")
    assert body.north == pytest.approx(3.75)
    assert body.east == 0.0
    assert body.vn == pytest.approx(11.0)


def test_speed_is_capped_even_if_setpoint_bypasses_clamp() -> None:
    world = one_uav()
    world.set_velocity("uav0", (30.0, 40.0))
    assert world.body("uav0").setpoint[:2] == pytest.approx((6.6, 8.8))
    world.step()
    world.step()
    assert world.body("uav0").speed == pytest.approx(11.0)
    # The physics caps speed on its own, whatever the setpoint.
    body = world.body("uav0")
    body.sp_n, body.sp_e = 500.0, 0.0
    for _ in range(5):
        world.step()
        assert body.speed <= 11.0 + 1e-9


def test_velocity_is_kept_until_changed() -> None:
    world = one_uav()
    world.set_velocity("uav0", (0.0, -5.0))
    world.step()
    east_after_1 = world.body("uav0").east
    for _ in range(3):
        world.step()
    body = world.body("uav0")
    assert body.setpoint == (0.0, -5.0, 0.0)
    assert body.vel == pytest.approx((0.0, -5.0, 0.0))
    assert body.east == pytest.approx(east_after_1 - 3 * 2.5)  # 5 m/s for 1.5 s
    world.set_velocity("uav0", (5.0, 0.0))
    world.step()
    assert body.vel == pytest.approx((5.0, 0.0, 0.0))


def test_hold_decelerates_at_the_limit_and_stops() -> None:
    world = one_uav()
    world.set_velocity("uav0", (11.0, 0.0))
    world.step()
    world.step()
    start = world.body("uav0").north
    world.hold("uav0")
    world.step(0.05)
    assert world.body("uav0").vn == pytest.approx(9.5)
    world.step(0.45)
    body = world.body("uav0")
    assert body.vel == (0.0, 0.0, 0.0)
    # Ticks at 9.5, 8, 6.5, 5, 3.5, 2, 0.5, 0, 0, 0 m/s -> 35 * 0.05 = 1.75 m.
    assert body.north - start == pytest.approx(1.75)
    world.step()
    assert body.north - start == pytest.approx(1.75)


def test_altitude_is_fixed_and_down_command_ignored() -> None:
    world = one_uav(altitude_m=12.0)
    world.set_velocity("uav0", (3.0, 4.0, -9.0))
    world.step()
    assert world.body("uav0").pos[2] == -12.0
    assert world.body("uav0").vel[2] == 0.0
    assert world.body("uav0").setpoint == (3.0, 4.0, 0.0)


def test_step_is_deterministic() -> None:
    def run() -> list[tuple[float, float, float]]:
        world = KinematicWorld()
        for i in range(4):
            world.add_uav(f"uav{i}", (-30.0 + 7.3 * i, 11.1 * i))
        trace: list[tuple[float, float, float]] = []
        for r in range(12):
            for i in range(4):
                world.set_velocity(f"uav{i}", (math.sin(r + i) * 13, math.cos(r * i) * 7))
            world.step()
            trace.extend(b.pos for b in world.bodies())
        return trace

    assert run() == run()


def test_absent_uav_holds_and_ignores_commands() -> None:
    world = one_uav()
    world.set_velocity("uav0", (10.0, 0.0))
    world.step()
    world.mark_absent("uav0")
    assert world.set_velocity("uav0", (10.0, 0.0)) is False
    world.step()
    assert world.body("uav0").vel == (0.0, 0.0, 0.0)
    world.mark_present("uav0")
    assert world.set_velocity("uav0", (10.0, 0.0)) is True
    world.step()
    assert world.body("uav0").vn == pytest.approx(10.0)


def test_bad_input_is_rejected() -> None:
    world = one_uav()
    with pytest.raises(ValueError, match="non-finite"):
        world.set_velocity("uav0", (math.nan, 0.0))
    with pytest.raises(KeyError, match="uav9"):
        world.hold("uav9")
    with pytest.raises(ValueError, match="duplicate"):
        world.add_uav("uav0", (1.0, 1.0))
    with pytest.raises(ValueError, match="max_speed_mps"):
        KinematicWorld(max_speed_mps=0.0)


def test_from_config_uses_its_limits() -> None:
    world = KinematicWorld.from_config(SimConfig(max_speed_mps=4.0, max_accel_mps2=10.0))
    world.add_uav("uav0", (0.0, 0.0))
    world.set_velocity("uav0", (9.0, 0.0))
    world.step(0.05)
    assert world.body("uav0").vn == pytest.approx(0.5)
    world.step()
    assert world.body("uav0").vn == pytest.approx(4.0)


def test_sensing_radius_is_horizontal_and_inclusive() -> None:
    world = KinematicWorld()
    world.add_uav("uav0", (10.0, 10.0))
    world.add_uav("uav1", (10.0 + 27.0, 10.0 + 36.0))  # exactly 45 m away
    world.add_uav("uav2", (10.0, 10.0 - 45.01))
    world.add_entity(Entity(id="L0", kind="landmark", pos=(10.0 + 44.9, 10.0, -5.0)))
    world.add_entity(Entity(id="L1", kind="landmark", pos=(10.0, 10.0 + 45.1, -5.0)))
    world.add_entity(Entity(id="L2", kind="landmark", pos=(10.0, 10.0, -100.0)))  # above
    seen = world.sense("uav0")
    assert [e.id for e in seen] == ["L0", "L2", "uav1"]
    peer = seen[-1]
    assert peer.kind == "uav"
    assert peer.pos == world.body("uav1").pos
    assert [e.id for e in world.sense("uav0", radius_m=1.0)] == ["L2"]
    assert "uav1" not in [e.id for e in world.sense("uav1")]
    assert "uav0" in [e.id for e in world.sense("uav1")]  # symmetric at exactly 45 m


def test_near_collisions_counts_pairs_under_2_m() -> None:
    world = KinematicWorld()
    world.add_uav("uav0", (0.0, 0.0))
    world.add_uav("uav1", (1.9, 0.0))
    world.add_uav("uav2", (0.0, 1.99))
    world.add_uav("uav3", (0.0, -2.0))
    # Pairs 0-1 (1.9 m) and 0-2 (1.99 m); 1-2 is 2.75 m and 0-3 exactly 2 m (not closer).
    assert world.near_collisions() == 2
    assert world.near_collisions(ids=["uav1", "uav2", "uav3"]) == 0
