"""A late joiner's fetch of its role's experience works on a secured swarm (mutual TLS,
ACL, signatures): the ACL lets a UAV serve its own experience key and query its peers',
and the served batch is verified like every payload."""

from __future__ import annotations

import asyncio

from aeroweaver_edge.agent.memory.experience import ExperienceMemory
from aeroweaver_edge.agent.memory.round_sharing import RoundSharing
from aeroweaver_edge.agent.memory.shared_intake import SharedIntake
from aeroweaver_edge.contracts.wire import HeaderFactory, Keys
from tests.aeroweaver_edge.security.conftest import SWARM
from tests.helpers.secure_net import SecureNet


async def test_a_late_joiner_fetches_signed_experience_on_a_secured_swarm(
    secure_net: SecureNet,
) -> None:
    server, joiner_mesh = await secure_net.open("uav0"), await secure_net.open("uav1")
    assert server.security_summary()["signed"] is True
    keys = Keys(SWARM)
    headers = HeaderFactory("uav0")
    sharing = RoundSharing(server, keys, "uav0", headers, SharedIntake("uav0"))
    sharing.start()
    mem = ExperienceMemory(run="r")
    for t in range(3):
        mem.append(
            task="coverage", role="searcher", uav="uav0", episode=0, round=t,
            state_text=f"task coverage landmark L{t}", skill="explore_local",
            invocation="explore_local()",
        )  # fmt: skip
        mem.add_reward("uav0", 0, t, 1.0, "sim")
        rec = mem.get("uav0", 0, t)
        assert rec is not None
        sharing.published(rec.to_wire(headers.next()))
    intake = SharedIntake("uav1")
    joiner = RoundSharing(joiner_mesh, keys, "uav1", HeaderFactory("uav1"), intake)
    taken = 0
    for _ in range(30):  # until the queryable's declaration reached the joiner
        taken = await joiner.fetch("searcher")
        if taken:
            break
        await asyncio.sleep(0.1)
    assert taken == 3
    assert joiner_mesh.codec.stats.total == 0  # nothing refused: signed and allowed
    await sharing.aclose()
    mem.close()
