"""``aeroweaver mcp`` with the official SDK's own client, over streamable HTTP and stdio,
against running UAV daemons on a real loopback mesh: resources, the plan -> confirm ->
start flow, approvals, the trace, the stop; every refusal and failure is a tool error
(``isError``) carrying its one line (wrong or missing token, unknown plan or task, a UAV
not on the mesh, arguments that fail the schema)."""

from __future__ import annotations

import asyncio
import json
import os
import sys
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from mcp import Client
from mcp.client.stdio import StdioServerParameters

from aeroweaver_edge.config import AgentConfig, MeshConfig, UavConfig
from aeroweaver_edge.mcp_server.server import McpOptions, serve
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.orchestration.daemons import DaemonSet
from tests.helpers.zenoh_net import free_port, unique_namespace

pytestmark = pytest.mark.timeout(120)
SWARM = "mcpt"
TOKEN = "s3cret-operator-token"
TOOLS = {"plan_mission", "start_mission", "stop_mission", "approve_action", "uav_trace"}


@pytest.fixture
async def swarm(tmp_path: Path) -> AsyncIterator[MeshConfig]:
    """Three scripted daemons (no Commander, no world yet) around a loopback router."""
    ns, port = unique_namespace("mcp"), free_port()
    router = MeshConfig(mode="router", listen=[f"tcp/127.0.0.1:{port}"], namespace=ns)
    client = MeshConfig(mode="client", listen=[], connect=[f"tcp/127.0.0.1:{port}"], namespace=ns)
    mesh = await Mesh.open(router, node_id="router")
    configs = [
        UavConfig(uav=f"uav{i}", swarm=SWARM, mesh=client, agent=AgentConfig(selector="scripted"))
        for i in range(3)
    ]
    daemons = DaemonSet(configs, False, tmp_path)
    await daemons.start()
    try:
        yield client
    finally:
        await daemons.stop(timeout_s=0.1)  # no world to end their run: cancel them
        await mesh.aclose()


def error(result: Any) -> str:
    """The one line of a tool error (``isError``)."""
    assert result.is_error, result
    [content] = result.content
    text: str = content.text
    assert "\n" not in text, text
    return text


def data(result: Any) -> dict[str, Any]:
    assert not result.is_error, result
    if result.structured_content is not None:
        out: dict[str, Any] = result.structured_content
        return out.get("result", out) if set(out) == {"result"} else out
    return json.loads(result.content[0].text)  # type: ignore[no-any-return]


async def resource(client: Client, uri: str) -> Any:
    got = await client.read_resource(uri)
    return json.loads(got.contents[0].text)  # type: ignore[union-attr]


async def until(fn: Any, timeout_s: float = 20.0) -> Any:
    """Poll remote state (another process's view) until ``fn`` is truthy, bounded."""
    async with asyncio.timeout(timeout_s):
        while not (value := await fn()):  # noqa: ASYNC110 - no local event to wait on
            await asyncio.sleep(0.1)
    return value


async def test_mcp_over_http_plans_starts_approves_and_stops(swarm: MeshConfig) -> None:
    port = free_port()
    # Paced so the mission is still flying when the test reaches its approval and stop
    # steps on a loaded machine (scripted coverage may complete in ~30 rounds).
    opts = McpOptions(swarm=SWARM, mesh=swarm, operator_token=TOKEN, sim_world=True,
                      pace_s=0.5, max_rounds=400)  # fmt: skip
    server = asyncio.create_task(serve(opts, "http", "127.0.0.1", port))
    try:
        await asyncio.sleep(0)  # the server binds before the client dials

        async def reachable() -> bool:
            try:
                _r, w = await asyncio.open_connection("127.0.0.1", port)
            except OSError:
                return False
            w.close()
            return True

        await until(reachable)
        async with Client(f"http://127.0.0.1:{port}/mcp") as client:
            tools = {t.name for t in (await client.list_tools()).tools}
            assert tools == TOOLS

            async def three_up() -> bool:
                r = await resource(client, "aeroweaver://roster")
                return [u["id"] for u in r["uavs"]] == ["uav0", "uav1", "uav2"]

            await until(three_up)
            roster = await resource(client, "aeroweaver://roster")
            assert roster["commander"] is False  # nobody commands yet
            await refusals_are_tool_errors(client)

            huge = error(await client.call_tool("plan_mission", {"text": "Cover. " * 10_000}))
            assert "at most 8192 bytes" in huge  # the one mission-text check, a tool error
            text = "Cover the three landmarks"
            plan = data(await client.call_tool("plan_mission", {"text": text}))
            assert plan["plan"]["task"] == "coverage"
            assert sorted(plan["plan"]["assignments"]) == ["uav0", "uav1", "uav2"]
            pid = plan["plan_id"]
            assert plan["confirm"] == f"start {pid}"
            dry = data(await client.call_tool("start_mission", {"plan_id": pid}))
            assert dry["done"] is False
            assert dry["will"].startswith(f"become the Commander of mission {pid} (coverage)")
            bad = error(await client.call_tool(
                "start_mission", {"plan_id": pid, "confirm": dry["confirm"],
                                  "operator_token": "guess"}))  # fmt: skip
            assert bad == "wrong operator token"
            assert (await resource(client, "aeroweaver://mission"))["mission"] is None
            go = data(await client.call_tool(
                "start_mission", {"plan_id": pid, "confirm": dry["confirm"],
                                  "operator_token": TOKEN}))  # fmt: skip
            assert go == {"done": True, "started": pid, "participants": ["uav0", "uav1", "uav2"]}

            async def decided() -> Any:
                last = await resource(client, "aeroweaver://decisions/last")
                return last if len(last["decisions"]) == 3 else None

            last = await until(decided)
            d = last["decisions"]["uav1"]
            assert d["chosen"] in [o.split(".", 1)[0] for o in d["options"]]
            state = await resource(client, "aeroweaver://uav/uav1/state")
            assert state["role"] == "searcher"
            assert state["alive"] is True
            assert len(state["pos_m"]) == 2

            async def three_rounds() -> Any:
                got = data(await client.call_tool("uav_trace", {"uav": "uav1", "rounds": 3}))
                return got if len(got["rounds"]) == 3 else None

            trace = await until(three_rounds)
            assert all(r["invocation"] for r in trace["rounds"][:2])

            ask = data(await client.call_tool("approve_action", {"uav": "uav2", "action": "land"}))
            assert ask["done"] is False
            assert ask["confirm"] == "approve uav2 land"
            assert ask["level"] == "normal"
            args = {"uav": "uav2", "action": "land", "ttl_s": 30, "confirm": ask["confirm"],
                    "operator_token": TOKEN}  # fmt: skip
            ok = data(await client.call_tool("approve_action", args))
            assert ok["done"] is True
            assert ok["approval"]["action"] == "land"
            assert ok["approval"]["state"] == "granted"
            again = await client.call_tool("start_mission", {"plan_id": pid})
            assert error(again) == f"this server already runs mission {pid}; stop it first " \
                "(stop_mission)"  # fmt: skip

            stop = data(await client.call_tool("stop_mission", {}))
            assert stop["confirm"] == f"stop {pid}"
            assert "hold, then land or return home" in stop["will"]
            done = data(await client.call_tool(
                "stop_mission", {"confirm": stop["confirm"], "reason": "test over",
                                 "operator_token": TOKEN}))  # fmt: skip
            assert done["done"] is True
            assert done["commander"].startswith("ended: operator stop by mcp:operator")
            mission = await resource(client, "aeroweaver://mission")
            assert mission["mission"]["state"] == "ended"
    finally:
        server.cancel()
        with pytest.raises(asyncio.CancelledError):
            await server


async def refusals_are_tool_errors(client: Client) -> None:
    """Each refusal or failure, before anything is started: isError and its one line."""
    tools = {t.name: t for t in (await client.list_tools()).tools}
    assert tools["approve_action"].input_schema["properties"]["action"]["enum"] == [
        "takeoff", "land", "return_home"]  # fmt: skip
    moon = error(await client.call_tool("plan_mission", {"text": "Juggle the moon"}))
    assert moon.startswith("cannot understand the mission: no task type recognised in "
                           "'Juggle the moon'; known tasks: coverage, ")  # fmt: skip
    tasks = await resource(client, "aeroweaver://tasks")
    assert moon.endswith(", ".join(tasks))  # every known task, in the resource's order
    assert tasks["coverage"]["example"]
    assert error(await client.call_tool("plan_mission", {})) == (
        "invalid arguments for plan_mission: text: Field required")  # fmt: skip
    arm = error(await client.call_tool("approve_action", {"uav": "uav0", "action": "arm"}))
    assert arm == ("invalid arguments for approve_action: action: Input should be 'takeoff', "
                   "'land' or 'return_home' (got 'arm')")  # fmt: skip
    ttl: dict[str, Any] = {"uav": "uav0", "action": "land", "ttl_s": "soon"}
    assert error(await client.call_tool("approve_action", ttl)) == (
        "invalid arguments for approve_action: ttl_s: Input should be a valid number, unable "
        "to parse string as a number (got 'soon')")  # fmt: skip
    ttl["ttl_s"] = 0
    assert error(await client.call_tool("approve_action", ttl)) == (
        "ttl_s 0: must be within (0, 86400] seconds")  # fmt: skip
    away = error(await client.call_tool("approve_action", {"uav": "uav7", "action": "land"}))
    assert away == "uav7 is not on the mesh (UAVs up: uav0, uav1, uav2)"
    nope = error(await client.call_tool("start_mission", {"plan_id": "nope"}))
    assert nope == "unknown plan 'nope' (planned here: none yet); call plan_mission first"
    stop = error(await client.call_tool("stop_mission", {}))
    assert stop == "the Commander is not on the mesh (waited 3 s)"
    assert error(await client.call_tool("fly_to_the_moon", {})) == "Unknown tool: fly_to_the_moon"


async def test_mcp_over_stdio_is_read_only_without_a_token(swarm: MeshConfig) -> None:
    env = {k: v for k, v in os.environ.items() if k != "AEROWEAVER_OPERATOR_TOKEN"}
    params = StdioServerParameters(
        command=sys.executable,
        args=["-m", "aeroweaver_edge", "mcp", "--swarm", SWARM, "--connect",
              swarm.connect[0], "--namespace", str(swarm.namespace)],
        env=env,
    )  # fmt: skip
    async with Client(params) as client:
        assert {t.name for t in (await client.list_tools()).tools} == TOOLS

        async def three_up() -> bool:
            r = await resource(client, "aeroweaver://roster")
            return len(r["uavs"]) == 3

        await until(three_up)
        plan = data(await client.call_tool("plan_mission", {"text": "Form a circle"}))
        assert plan["plan"]["task"] == "circular_formation"
        read_only = "this MCP server is read-only: no operator token is configured"
        go = await client.call_tool(
            "start_mission", {"plan_id": plan["plan_id"], "confirm": plan["confirm"],
                              "operator_token": "anything"})  # fmt: skip
        assert error(go) == read_only
        # a dry run never promises what the real call refuses
        dry = await client.call_tool("start_mission", {"plan_id": plan["plan_id"]})
        assert error(dry) == read_only
        assert error(await client.call_tool("stop_mission", {})) == read_only
        ask = await client.call_tool("approve_action", {"uav": "uav0", "action": "land"})
        assert error(ask) == read_only
