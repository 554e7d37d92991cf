"""Field frames: with no simulated world the console samples the UAVs' round reports into
frames (over a real Zenoh mesh), hostile vehicle values never break a frame, the new
optional ``ProgressReport.vehicle`` leaves older readers working, and every event stream
learns that the console ended before it closes."""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path
from typing import Any

import httpx
import msgspec

from aeroweaver_edge.console.field import FieldView
from aeroweaver_edge.console.frames import FrameStore, encode
from aeroweaver_edge.console.observer import SwarmObserver
from aeroweaver_edge.console.server import Console
from aeroweaver_edge.contracts.wire import (
    Codec,
    Entity,
    Header,
    HeaderFactory,
    Keys,
    ProgressReport,
    VehicleStatus,
)
from tests.aeroweaver_edge.console.test_console_live import sse
from tests.helpers.zenoh_net import ZenohNet

L0 = Entity(id="L0", kind="landmark", pos=(12.0, 8.0, -5.0))


def report(
    h: Header, uav: str, rnd: int, vehicle: VehicleStatus | None, **kw: Any
) -> ProgressReport:
    fields: dict[str, Any] = {
        "mission_id": "m1", "episode": 0, "round": rnd, "role": "searcher",
        "skill": "cover_landmark", "invocation": "cover_landmark(target_id=L0)", "label": "A",
        "held": False, **kw,
    }  # fmt: skip
    return ProgressReport(h=h, uav=uav, vehicle=vehicle, **fields)


def status(north: float, east: float, **kw: Any) -> VehicleStatus:
    fields: dict[str, Any] = {
        "vel": (1.0, 0.5, 0.0), "armed": True, "in_air": True, "mode": "OFFBOARD",
        "battery_pct": 90.0, "heartbeat_age_s": 0.4, "phase": "mission", "points": [L0], **kw,
    }  # fmt: skip
    return VehicleStatus(pos=(north, east, -5.0), **fields)


async def test_the_observer_draws_reports_without_a_world(zenoh_net: ZenohNet) -> None:
    console_mesh = await zenoh_net.open("console")
    uav_mesh = await zenoh_net.open("uav0")
    store = FrameStore()
    observer = SwarmObserver(console_mesh, "fieldtest", store, field_period_s=0.1)
    await observer.start()
    try:
        await asyncio.sleep(0.3)  # the subscription reaches the publisher's session
        hf, keys = HeaderFactory("uav0"), Keys("fieldtest")
        for rnd in range(4):
            uav_mesh.put(
                keys.report("uav0"), report(hf.next(), "uav0", rnd, status(rnd, 2.0 * rnd))
            )
            await asyncio.sleep(0.15)
        async with asyncio.timeout(5):
            while not store.frames or store.frames[-1]["bodies"][0]["pos"] != [3.0, 6.0]:
                await store.wait_change(1.0)
    finally:
        await observer.aclose()
        await uav_mesh.aclose()
        await console_mesh.aclose()
    f = store.frames[-1]
    assert f["source"] == "field"
    assert f["uavs"] == ["uav0"]
    assert f["held"] == []
    assert f["bodies"] == [{"id": "uav0", "kind": "uav", "pos": [3.0, 6.0], "vel": [1.0, 0.5],
                            "role": "searcher"}]  # fmt: skip
    assert f["entities"] == [{"id": "L0", "kind": "landmark", "pos": [12.0, 8.0]}]
    v = f["vehicles"]["uav0"]
    assert (v["mode"], v["armed"], v["alt_m"], v["battery_pct"], v["phase"], v["round"]) == (
        "OFFBOARD", True, 5.0, 90.0, "mission", 3,
    )  # fmt: skip
    assert f["decisions"]["uav0"]["invocation"] == "cover_landmark(target_id=L0)"
    assert store.meta["source"] == "field"
    assert store.patch_seq == 0  # field frames carry their decisions: nothing patched by round


def test_hostile_vehicle_values_never_break_a_frame() -> None:
    now = [100.0]
    view = FieldView(clock=lambda: now[0])
    hf = HeaderFactory("x")
    bad = status(math.nan, 1.0, battery_pct=math.inf, heartbeat_age_s=-math.inf,
                 vel=(1e308, math.nan, 0.0), points=[Entity(id="far", kind="landmark",
                 pos=(1e308, 0.0, 0.0))])  # fmt: skip
    view.on_report(report(hf.next(), "uav0", 0, bad, held=True, hold_cause="deadline"))
    view.on_report(report(hf.next(), "uav1", 0, status(1e12, 1e12)))
    view.on_report(report(hf.next(), "uav2", 0, None))  # a daemon without a vehicle link
    f = view.frame("coverage")
    assert f is not None
    json.loads(encode(f))  # strict JSON: no NaN or Infinity reaches the page
    assert f["uavs"] == ["uav0", "uav1"]
    assert f["bodies"] == []  # no place to draw them
    assert f["held"] == ["uav0"]
    assert [e["id"] for e in f["entities"]] == ["L0"]  # not the one at 1e308 m
    assert f["vehicles"]["uav0"]["battery_pct"] is None
    assert view.frame("coverage") is None  # nothing new: no frame
    now[0] += 5.0
    f2 = view.frame("coverage")  # but a UAV going quiet is news
    assert f2 is not None
    assert f2["absent"] == ["uav0", "uav1"]


class OldReport(msgspec.Struct, frozen=True, kw_only=True, tag="report"):
    """A reader built before ``vehicle`` existed (a subset of the fields)."""

    h: Header
    uav: str
    round: int
    held: bool


def test_the_vehicle_field_is_optional_both_ways() -> None:
    codec = Codec()
    hf = HeaderFactory("uav0")
    new = codec.encode(report(hf.next(), "uav0", 7, status(1.0, 2.0)))
    old = msgspec.msgpack.decode(new, type=OldReport)
    assert (old.uav, old.round, old.held) == ("uav0", 7, False)
    plain = codec.encode(report(hf.next(), "uav0", 8, None))
    back = codec.decode(plain, ProgressReport)
    assert back is not None
    assert back.vehicle is None
    too_many = status(0.0, 0.0, points=[L0] * 33)
    assert (
        codec.decode(codec.encode(report(hf.next(), "uav0", 9, too_many)), ProgressReport) is None
    )


async def test_every_stream_hears_that_the_console_ended(tmp_path: Path) -> None:
    trace = tmp_path / "t.jsonl"
    rows = [
        {"type": "run", "task": "coverage", "roles": {"uav0": "r"}},
        {"type": "round", "episode": 0, "round": 0, "bodies": [], "commands": {"uav0": {}}},
    ]
    trace.write_text("".join(json.dumps(r) + "\n" for r in rows), encoding="utf-8")
    console = Console("127.0.0.1", 0)
    console.replay(trace)
    metas: list[dict[str, Any]] = []
    async with console, httpx.AsyncClient(base_url=console.url, timeout=10) as http:  # noqa: SIM117 - the url is known once the console is up
        async with http.stream("GET", "/api/events") as resp:
            events = sse(resp)
            async for kind, data in events:
                if kind == "meta":
                    metas.append(data)
                    break
            closing = asyncio.create_task(console.aclose())
            async for kind, data in events:
                if kind == "meta":
                    metas.append(data)
            await closing
    assert metas[0].get("ended") is None
    assert metas[-1]["ended"] is True


async def test_field_samples_and_world_rounds_never_collide() -> None:
    store = FrameStore()
    hf = HeaderFactory("uav0")
    view = FieldView()
    view.on_report(report(hf.next(), "uav0", 0, status(1.0, 1.0)))
    sample = view.frame("coverage")
    assert sample is not None
    assert (sample["episode"], sample["round"]) == (0, 0)
    assert store.add_frame(sample) == 0
    assert store.add_frame({"episode": 0, "round": 0, "decisions": {}}) == 1  # a world round
    store.add_decision(0, 0, "uav0", {"chosen": "B"})  # patches the world round only
    assert store.frame(1) == {
        "episode": 0,
        "round": 0,
        "i": 1,
        "decisions": {"uav0": {"chosen": "B"}},
    }
    assert store.frame(0)["decisions"]["uav0"]["invocation"] == "cover_landmark(target_id=L0)"  # type: ignore[index]
