"""The console against a real simulated swarm: frames over server-sent events, decisions,
operator stop behind the typed confirmation, replay from a trace, read-only refusals."""

from __future__ import annotations

import asyncio
import json
import re
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from aeroweaver_edge.console.server import Console
from aeroweaver_edge.orchestration.swarm import RunSummary, SwarmHandle, SwarmOptions, run_swarm

pytestmark = pytest.mark.timeout(90)


async def sse(resp: httpx.Response) -> AsyncIterator[tuple[str, Any]]:
    """(event, data) pairs of a server-sent event stream."""
    kind, data = "", ""
    async for line in resp.aiter_lines():
        if line.startswith("event: "):
            kind = line[7:]
        elif line.startswith("data: "):
            data = line[6:]
        elif line == "" and kind:
            yield kind, json.loads(data)
            kind, data = "", ""


def token_of(page: str) -> str:
    m = re.search(r'name="aw-token" content="([^"]+)"', page)
    assert m is not None
    return m.group(1)


async def test_live_console_shows_the_run_and_the_operator_stops_it() -> None:
    async with Console("127.0.0.1", 0) as console:

        async def started(h: SwarmHandle) -> None:
            await console.connect(h.mesh_for("operator"), h.swarm)

        run: asyncio.Task[RunSummary] = asyncio.create_task(
            run_swarm(
                SwarmOptions(task="coverage", selector="scripted", max_rounds=300, pace_s=0.1),
                on_started=started,
            )
        )
        try:
            async with httpx.AsyncClient(base_url=console.url, timeout=10) as http:
                token = token_of((await http.get("/")).text)
                frames: list[dict[str, Any]] = []
                async with http.stream("GET", "/api/events") as resp:
                    assert resp.headers["content-type"].startswith("text/event-stream")
                    async for kind, data in sse(resp):
                        if kind == "frame":
                            frames.append(data)
                        if len(frames) == 4:
                            break
                assert [f["i"] for f in frames] == sorted({f["i"] for f in frames})
                for f in frames:
                    assert f["uavs"] == ["uav0", "uav1", "uav2"]
                    assert sorted(b["id"] for b in f["bodies"]) == f["uavs"]
                    assert f["stamp"] > 0
                moved = {
                    b["id"]: b["pos"] != a["pos"]
                    for a, b in zip(frames[0]["bodies"], frames[-1]["bodies"], strict=True)
                }
                assert any(moved.values())
                every = (await http.get("/api/frames")).json()["frames"]
                joined = [f for f in every if len(f["decisions"]) == 3]
                assert joined, "no frame got every UAV's decision"
                d = joined[-1]["decisions"]["uav0"]
                labels = [o.split(".", 1)[0] for o in d["options"]]
                assert d["chosen"] in labels
                assert d["role"] == "searcher"
                meta = (await http.get("/api/meta")).json()
                assert meta["mode"] == "live"
                assert meta["task"] == "coverage"
                assert meta["roles"] == {"uav0": "searcher", "uav1": "searcher", "uav2": "searcher"}
                assert meta["operator"] == {"enabled": True, "read_only": ""}

                # operator stop: token, JSON and the typed phrase are all required
                auth = {"X-AW-Token": token}
                plan = (await http.get("/api/operator/stop", headers=auth)).json()
                assert plan["confirm"] == "stop coverage-s1"
                assert "uav0, uav1, uav2 hold, then land or return" in plan["will"]
                r = await http.post("/api/operator/stop", json={"confirm": plan["confirm"]})
                assert r.status_code == 403
                r = await http.post("/api/operator/stop", json={"confirm": "stop"}, headers=auth)
                assert r.status_code == 400
                assert "type 'stop coverage-s1' to confirm" in r.json()["error"]
                r = await http.post(
                    "/api/operator/stop", content=plan["confirm"],
                    headers={**auth, "Content-Type": "text/plain"},
                )  # fmt: skip
                assert r.status_code == 415
                assert not run.done()
                r = await http.post(
                    "/api/operator/stop", json={"confirm": plan["confirm"], "reason": "test"},
                    headers=auth,
                )  # fmt: skip
                assert r.status_code == 200, r.text
                assert r.json()["stopped"] == "coverage-s1"
                assert "operator stop by" in r.json()["commander"]
                bad_host = await http.get("/api/meta", headers={"Host": "evil.example"})
                assert bad_host.status_code == 400
            summary = await asyncio.wait_for(run, 30)
        finally:
            run.cancel()
    assert summary.stopped is not None
    assert summary.stopped.startswith("operator stop by")
    assert summary.stopped.endswith(": test")
    assert summary.episodes == []  # the episode was cut short, not finished


async def test_replay_serves_a_trace_and_is_read_only(tmp_path: Path) -> None:
    trace = tmp_path / "run.jsonl"
    summary = await run_swarm(
        SwarmOptions(task="pursuit_evasion", selector="scripted", max_rounds=4, trace_path=trace)
    )
    console = Console("127.0.0.1", 0)
    console.replay(trace)
    async with console, httpx.AsyncClient(base_url=console.url, timeout=10) as http:
        token = token_of((await http.get("/")).text)
        frames = (await http.get("/api/frames")).json()["frames"]
        assert [f["round"] for f in frames] == list(range(summary.as_dict()["rounds"]))
        assert len(frames[0]["bodies"]) == 4  # three pursuers and the world's evader
        assert frames[0]["uavs"] == ["uav0", "uav1", "uav2"]
        assert all(sorted(f["decisions"]) == ["uav0", "uav1", "uav2"] for f in frames)
        total = sum(f["team_reward"] for f in frames)
        assert total == pytest.approx(summary.as_dict()["team_return"], abs=1e-4)
        assert (await http.get("/api/frames?since=2")).json()["frames"][0]["round"] == 2
        assert (await http.get("/api/frames?since=x")).status_code == 400
        meta = (await http.get("/api/meta")).json()
        assert meta["mode"] == "replay"
        assert meta["operator"] == {"enabled": False, "read_only": "a replay"}
        auth = {"X-AW-Token": token}
        r = await http.post("/api/operator/stop", json={"confirm": "x"}, headers=auth)
        assert r.status_code == 403
        assert "read-only (a replay)" in r.json()["error"]
        js = await http.get("/static/console.js")
        assert js.status_code == 200
        assert "EventSource" in js.text
