"""The field Clock and Perception: wall-clock rounds, telemetry + peers' beacons."""

from __future__ import annotations

import asyncio

import pytest

from aeroweaver_edge.contracts.ports import RoundTick
from aeroweaver_edge.contracts.wire import Entity, Header, StateBeacon
from aeroweaver_edge.vehicle.field import FieldPerception, NoRewards, WallClock
from tests.helpers.mav import emulated


def beacon(uav: str, seq: int, north: float, east: float) -> StateBeacon:
    h = Header(sender=uav, epoch=1, seq=seq, stamp=0.0)
    return StateBeacon(h=h, uav=uav, round=seq, pos=(north, east, -5.0), vel=(1.0, 0.0, 0.0))


async def test_wall_clock_ticks_and_skips_overrun_rounds() -> None:
    clock = WallClock(round_s=0.02, deadline_s=1.0, rounds=40)
    first = await clock.next_round()
    assert first == RoundTick(0, 0, 1.0)
    assert (await clock.next_round()) == RoundTick(0, 1, 1.0)
    await asyncio.sleep(0.2)  # a slow decision overran about ten rounds
    late = await clock.next_round()
    assert late is not None
    assert late.round >= 8
    assert clock.skipped == late.round - 2
    while (tick := await clock.next_round()) is not None:
        assert tick.round < 40
    with pytest.raises(ValueError, match="must be > 0"):
        WallClock(0.0, 1.0)
    assert NoRewards().drain() == []


async def test_field_perception_from_telemetry_beacons_and_points() -> None:
    now = [100.0]
    async with emulated(1) as (_host, [v]):
        points = [
            Entity(id="W0", kind="waypoint", pos=(10.0, 0.0, -5.0)),
            Entity(id="W1", kind="waypoint", pos=(60.0, 0.0, -5.0)),  # beyond 45 m
        ]
        per = FieldPerception(v, points=points, beacon_max_age_s=3.0, clock=lambda: now[0])
        beacons = {"uav1": beacon("uav1", 1, 20.0, 0.0), "uav2": beacon("uav2", 1, 0.0, 80.0)}
        per.attach(lambda: beacons)
        percept = await per.sense(RoundTick(0, 0, 1.0))
        own, seen = percept.own, list(percept.entities)
        assert dict(percept.facts) == {}
        assert own.pos[:2] == pytest.approx((0.0, 0.0), abs=1e-3)  # from LOCAL_POSITION_NED
        assert not own.in_air
        assert not own.armed
        assert [e.id for e in seen] == ["W0", "uav1"]  # uav2 is out of range
        now[0] += 5.0  # no new beacon from uav1 for 5 s (local receipt time): stale
        seen = list((await per.sense(RoundTick(0, 1, 1.0))).entities)
        assert [e.id for e in seen] == ["W0"]
        beacons["uav1"] = beacon("uav1", 2, 21.0, 0.0)  # a fresh one
        seen = list((await per.sense(RoundTick(0, 2, 1.0))).entities)
        assert [e.id for e in seen] == ["W0", "uav1"]
        assert seen[1].pos[0] == 21.0
