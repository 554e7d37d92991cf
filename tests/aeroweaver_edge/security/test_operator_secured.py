"""Operator actions on a secured swarm (TLS + ACL + signatures): the operator identity's
approvals and stops go through (signed, authorised by the operator role's grants); the
observer's are refused by the receivers, and a UAV cannot approve for itself."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from aeroweaver_edge.config import ApprovalConfig
from aeroweaver_edge.contracts.wire import HeaderFactory, Keys
from aeroweaver_edge.mesh.secured import ephemeral_swarm
from aeroweaver_edge.safety.approval import ApprovalGate
from aeroweaver_edge.safety.approval_link import ApprovalLink
from aeroweaver_edge.safety.operator import OperatorError, OperatorLink
from commander.commander import Commander
from commander.harness import plan_for_task
from tests.helpers.secure_net import SecureNet

SWARM = "sec"
pytestmark = pytest.mark.timeout(90)


@pytest.fixture
async def net(tmp_path: Path) -> AsyncIterator[SecureNet]:
    pki = ephemeral_swarm(tmp_path / "pki", SWARM, ["uav0", "uav1", "uav2"])
    n = SecureNet(pki)
    try:
        yield n
    finally:
        await n.aclose()


async def test_only_the_operator_identity_approves_and_stops(net: SecureNet) -> None:
    keys = Keys(SWARM)
    uav = await net.open("uav0")
    gate = ApprovalGate("uav0", ApprovalConfig(), mission=lambda: "m1")
    link = ApprovalLink(uav, keys, "uav0", HeaderFactory("uav0"), gate)
    link.start()
    uav.declare_token(keys.alive_uav("uav0"))  # after the subscriber, as the daemon does
    cmdr_mesh = await net.open("cmdr")
    commander = Commander(cmdr_mesh, SWARM)
    await commander.start()
    commander.publish(plan_for_task("coverage", ["uav0", "uav1", "uav2"], mission_id="m1"))
    operator = OperatorLink(await net.open("operator"), SWARM, person="ana")
    observer = OperatorLink(await net.open("observer"), SWARM, person="eve")
    try:
        # the observer signs nothing and may write nothing: the UAV never hears it
        with pytest.raises(OperatorError, match="did not acknowledge"):
            await observer.approve("uav0", "takeoff", 60, timeout_s=1.5)
        # a UAV cannot approve its own take-off (its key does not cover operator/**)
        selfish = OperatorLink(uav, SWARM, person="uav0")
        with pytest.raises(OperatorError, match="did not acknowledge"):
            await selfish.approve("uav0", "takeoff", 60, timeout_s=1.5)
        assert gate.records() == []
        assert not gate.offer("take_off")
        rec = await operator.approve("uav0", "takeoff", 60)
        assert rec.state == "granted"
        assert rec.sender == "operator"
        assert gate.offer("take_off")
        # the observer still reads everything: it sees the UAV's record
        status = await observer.approval_status("uav0")
        assert status is not None
        assert [r.id for r in status.records] == [rec.id]

        plan = await observer.plan_stop()
        with pytest.raises(OperatorError, match="did not end mission m1"):
            await observer.stop(plan, timeout_s=1.5)
        assert not commander.ended.is_set()
        note = await operator.stop(plan, "secured")
        assert note == "ended: operator stop by ana: secured"
        assert commander.ended.is_set()
    finally:
        await link.aclose()
        await commander.aclose()
