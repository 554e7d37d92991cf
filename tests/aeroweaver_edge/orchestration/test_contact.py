"""The Commander's contact watch over real liveliness tokens: a UAV whose token goes is
lost (where, from the board), back when it returns (rejoined), and the mission's guard fires
only once every participant has been out of contact for the grace."""

from __future__ import annotations

import asyncio
import time

from aeroweaver_edge.contracts.wire import Keys
from aeroweaver_edge.orchestration.contact import ContactWatch
from tests.helpers.zenoh_net import ZenohNet, eventually

KEYS = Keys("ct")


async def test_lost_rejoined_and_all_lost_after_the_grace(zenoh_net: ZenohNet) -> None:
    cmdr = await zenoh_net.open("cmdr")
    uavs = {u: await zenoh_net.open(u) for u in ("uav0", "uav1")}
    tokens = {u: m.declare_token(KEYS.alive_uav(u)) for u, m in uavs.items()}
    watch = ContactWatch(cmdr, "ct", ["uav0", "uav1"], lambda uav: (0, 7))
    watch.start()
    try:
        assert await eventually(lambda: watch.alive == {"uav0", "uav1"}, 5)
        await tokens["uav0"].aclose()
        assert await eventually(lambda: "uav0" in watch.lost, 5)
        assert watch.lost == {"uav0": [0, 7]}
        assert watch.out_of_contact == ["uav0"]
        guard = asyncio.create_task(watch.wait_all_lost(0.5))
        await asyncio.sleep(0.8)
        assert not guard.done()  # uav1 is still in contact
        tokens["uav0"] = uavs["uav0"].declare_token(KEYS.alive_uav("uav0"))
        assert await eventually(lambda: watch.rejoined == {"uav0": 1}, 5)
        assert watch.out_of_contact == []
        t0 = time.monotonic()
        for u in ("uav0", "uav1"):
            await tokens[u].aclose()
        await asyncio.wait_for(guard, 10)
        assert time.monotonic() - t0 >= 0.5
        assert watch.out_of_contact == ["uav0", "uav1"]
    finally:
        await watch.aclose()
