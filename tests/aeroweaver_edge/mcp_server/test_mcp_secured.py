"""``aeroweaver mcp --keys DIR --sim-world`` on a secured swarm (TLS, ACL, signatures) from
``aeroweaver keys init``: the SDK's own client plans, dry-runs and starts a mission that the
simulated world flies to its end (the Commander as ``cmdr``, the world as ``world``), and an
approval is spelled ``takeoff`` on the way in (MCP and the CLI, whose ``take_off`` is an
alias), in the UAV's record and in the approvals resource."""

from __future__ import annotations

import asyncio
import os
import sys
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from mcp import Client
from mcp.client.stdio import StdioServerParameters

from aeroweaver_edge.cli.main import main
from aeroweaver_edge.config import AgentConfig, UavConfig, load_config
from aeroweaver_edge.orchestration.daemons import DaemonSet
from aeroweaver_edge.security.identity import SwarmPki, default_members
from aeroweaver_edge.security.router import check_router_config, run_router
from tests.aeroweaver_edge.mcp_server.test_mcp import data, error, resource, until
from tests.helpers.zenoh_net import free_port

pytestmark = pytest.mark.timeout(150)
SWARM = "mcps"
TOKEN = "secured-operator-token"
UAVS = ("uav0", "uav1", "uav2")


@dataclass
class Secured:
    keys: Path
    router: str


@pytest.fixture
async def secured(tmp_path: Path) -> AsyncIterator[Secured]:
    """``keys init`` for three UAVs behind a router, the router and three scripted daemons
    (sim backend: they wait for a world) from the generated configs."""
    keys, router = tmp_path / "keys", f"tls/127.0.0.1:{free_port()}"
    assert main(["keys", "init", "--swarm", SWARM, "--uavs", "3", "--out", str(keys),
                 "--listen", router, "--connect", router, "--mode", "client"]) == 0  # fmt: skip
    conf = check_router_config(keys / "router" / "zenoh.json5")
    hub = asyncio.create_task(run_router(conf))
    configs = [
        load_config(keys / u / "uav.toml", UavConfig).model_copy(
            update={"agent": AgentConfig(selector="scripted")}
        )
        for u in UAVS
    ]
    daemons = DaemonSet(configs, False, tmp_path)
    await daemons.start()
    try:
        yield Secured(keys, router)
    finally:
        await daemons.stop(timeout_s=0.5)
        hub.cancel()
        with pytest.raises(asyncio.CancelledError):
            await hub


def mcp_server(s: Secured, *extra: str, token: str | None = TOKEN) -> StdioServerParameters:
    env = {k: v for k, v in os.environ.items() if k != "AEROWEAVER_OPERATOR_TOKEN"}
    if token is not None:
        env["AEROWEAVER_OPERATOR_TOKEN"] = token
    return StdioServerParameters(
        command=sys.executable,
        args=["-m", "aeroweaver_edge", "mcp", "--swarm", SWARM, "--keys", str(s.keys),
              "--connect", s.router, *extra],
        env=env,
    )  # fmt: skip


async def roster_of(client: Client, n: int) -> None:
    async def up() -> bool:
        r = await resource(client, "aeroweaver://roster")
        return len(r["uavs"]) == n

    await until(up, 40.0)


async def cli(*args: str) -> tuple[int, str, str]:
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "aeroweaver_edge", *args,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    out, err = await asyncio.wait_for(proc.communicate(), 60)
    assert proc.returncode is not None
    return proc.returncode, out.decode(), err.decode()


async def test_sim_world_mission_flies_on_a_secured_swarm(secured: Secured) -> None:
    async with Client(mcp_server(secured, "--sim-world")) as client:
        await roster_of(client, 3)
        plan = data(await client.call_tool("plan_mission", {"text": "Cover the three landmarks"}))
        pid = plan["plan_id"]
        dry = data(await client.call_tool("start_mission", {"plan_id": pid}))
        assert dry["will"].endswith("and fly the simulated world; each UAV then decides for "
                                    "itself. Stop it with stop_mission.")  # fmt: skip
        go = data(await client.call_tool(
            "start_mission", {"plan_id": pid, "confirm": dry["confirm"],
                              "operator_token": TOKEN}))  # fmt: skip
        assert go == {"done": True, "started": pid, "participants": list(UAVS)}

        async def ended() -> Any:
            run = (await resource(client, "aeroweaver://mission"))["run"]
            return run if run["state"] not in ("starting", "running") else None

        run = await until(ended, 90.0)
        assert run["state"] == "ended", run
        assert run["ended"] in ("complete", "horizon")  # the world flew it to its end
        [episode] = run["episodes"]
        assert episode["rounds"] > 10
        assert sorted(episode["agent_returns"]) == list(UAVS)
        last = await resource(client, "aeroweaver://decisions/last")
        assert sorted(last["decisions"]) == list(UAVS)  # every UAV decided for itself
        roster = await resource(client, "aeroweaver://roster")
        assert roster["commander"] is False  # the mission's Commander left with it
    for name in ("cmdr", "world"):  # the sessions were the swarm's own identities
        assert (secured.keys / "state" / f"{name}.boot").read_text() == "1\n"


async def test_approvals_are_spelled_takeoff_in_and_out(secured: Secured) -> None:
    async with Client(mcp_server(secured)) as client:
        await roster_of(client, 3)
        ask = data(await client.call_tool("approve_action", {"uav": "uav0", "action": "takeoff"}))
        assert ask["confirm"] == "approve uav0 takeoff"
        assert "to takeoff within 300 s" in ask["will"]
        alias = await client.call_tool("approve_action", {"uav": "uav0", "action": "take_off"})
        assert "Input should be 'takeoff', 'land' or 'return_home'" in error(alias)
        args = {"uav": "uav0", "action": "takeoff", "ttl_s": 60, "confirm": ask["confirm"],
                "operator_token": TOKEN}  # fmt: skip
        ok = data(await client.call_tool("approve_action", args))
        assert ok["approval"]["action"] == "takeoff"
        assert ok["approval"]["sender"] == "operator"  # signed by the operator identity
        assert ok["approval"]["state"] == "granted"
        # the CLI's old spelling is read as the one spelling, and so recorded
        flags = ["--swarm", SWARM, "--keys", str(secured.keys), "--connect", secured.router]
        code, out, err = await cli("approve", *flags, "--uav", "uav1", "--action", "take_off",
                                   "--by", "ana")  # fmt: skip
        assert code == 0, err
        assert out.startswith("uav1: takeoff approved by ana (id ")
        code, out, err = await cli("approve", *flags, "--uav", "uav2", "--action", "takeoff")
        assert code == 0, err
        assert out.startswith("uav2: takeoff approved by ")

        async def recorded() -> Any:
            a = await resource(client, "aeroweaver://approvals")
            return a if all(a.get(u, {}).get("records") for u in UAVS) else None

        approvals = await until(recorded)
        actions = {r["action"] for u in UAVS for r in approvals[u]["records"]}
        assert actions == {"takeoff"}


async def test_an_observer_identity_cannot_promise_to_act(secured: Secured) -> None:
    async with Client(mcp_server(secured, "--identity", "observer")) as client:
        await roster_of(client, 3)
        why = ("this server joined the secured swarm as 'observer' (observer), which may not "
               "act: start it with --identity operator")  # fmt: skip
        ask = await client.call_tool("approve_action", {"uav": "uav0", "action": "land"})
        assert error(ask) == why  # the dry run already says so
        assert error(await client.call_tool("stop_mission", {})) == why

        # reading still works: the observer reads everything
        async def levels() -> bool:
            a = await resource(client, "aeroweaver://approvals")
            return sorted(a) == list(UAVS)

        await until(levels)


async def test_sim_world_without_a_world_identity_is_refused_at_once(tmp_path: Path) -> None:
    keys = tmp_path / "keys"
    SwarmPki.create(keys, SWARM, default_members(1, world=False))
    code, _out, err = await cli("mcp", "--swarm", SWARM, "--keys", str(keys), "--sim-world")
    assert code == 2
    assert err.strip().splitlines() == [
        f"aeroweaver: config error: --keys {keys}: --sim-world needs the 'world' identity; "
        "provision it with aeroweaver keys init, or drop --sim-world"
    ]
    code, _out, err = await cli("mcp", "--swarm", "other", "--keys", str(keys))
    assert code == 2
    assert f"--keys {keys} is for swarm {SWARM!r}, not 'other'; pass --swarm {SWARM}" in err
