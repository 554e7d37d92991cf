"""``aeroweaver sim --link mavlink|mavsdk``: the same mission through real MAVLink bytes to
emulated autopilots gives the returns of the in-process link (scripted selector)."""

from __future__ import annotations

import pytest

from aeroweaver_edge.orchestration.swarm import RunSummary, SwarmOptions, run_swarm

SCRIPTED = {"selector": "scripted", "uavs": 3, "seed": 1, "max_rounds": 12}


async def run(link: str, **over: object) -> RunSummary:
    return await run_swarm(SwarmOptions(task="coverage", link=link, **{**SCRIPTED, **over}))  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def reference() -> dict[str, object]:
    import asyncio

    return asyncio.run(run("sim")).as_dict()


def assert_same_returns(ref: dict[str, object], got: dict[str, object]) -> None:
    assert got["rounds"] == ref["rounds"]
    assert got["team_return"] == pytest.approx(ref["team_return"], rel=0.01)
    for uav, r in ref["agent_returns"].items():  # type: ignore[attr-defined]
        assert got["agent_returns"][uav] == pytest.approx(r, rel=0.01)  # type: ignore[index]


@pytest.mark.slow
@pytest.mark.parametrize("personality", ["px4", "ardupilot"])
async def test_mavlink_link_matches_the_sim_link(
    reference: dict[str, object], personality: str
) -> None:
    got = (await run("mavlink", personality=personality)).as_dict()
    assert_same_returns(reference, got)
    link = got["link"]
    assert link["settle_mismatches"] == 0  # every declared setpoint arrived over MAVLink
    assert got["envelope_violations"]["total"] == 0  # what the autopilots flew, judged
    for uav, v in link["vehicles"].items():
        # each daemon went through the flight phases on its autopilot
        assert v["commands"]["COMPONENT_ARM_DISARM"] == 1, uav
        assert v["commands"]["NAV_TAKEOFF"] == 1, uav
        assert v["setpoints"] > 0
        assert v["failsafes"] == []


@pytest.mark.slow
@pytest.mark.mavsdk
async def test_mavsdk_link_matches_the_sim_link(reference: dict[str, object]) -> None:
    got = (await run("mavsdk")).as_dict()
    assert_same_returns(reference, got)
    assert got["link"]["settle_mismatches"] == 0
    # MAVSDK uploaded the fence around the local origin: nobody breached it
    assert all(v["failsafes"] == [] for v in got["link"]["vehicles"].values())


async def test_in_lockstep_the_lease_covers_the_worlds_round_deadline() -> None:
    """A UAV that decided early waits for the slowest one while the world is frozen; its
    command must still stand when the world steps (found with the embedded model)."""
    from aeroweaver_edge.config import SimConfig
    from aeroweaver_edge.sim.emulator.swarm_link import emulated_swarm
    from aeroweaver_edge.tasks import create

    cfg = SimConfig(uavs=2, deadline_s=12.0)
    async with emulated_swarm("mavlink", create("coverage", 2), cfg) as linked:
        for v in linked.vehicles.values():
            assert v.sim_world
            assert v.lease_s > cfg.deadline_s
        assert [v.sysid for v in linked.vehicles.values()] == [1, 2]
