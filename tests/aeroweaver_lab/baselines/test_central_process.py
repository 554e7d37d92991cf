"""``aeroweaver central`` as its own OS process on loopback Zenoh: it answers a UAV's ask
through the fake LLM and exits 0 on SIGTERM, naming what it spent."""

from __future__ import annotations

import asyncio
import signal
import sys

import pytest

from aeroweaver_edge.contracts.wire import (
    Assignment,
    CentralAnswer,
    CentralAsk,
    HeaderFactory,
    Keys,
    MissionContext,
)
from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
from tests.helpers.zenoh_net import ZenohNet

pytestmark = pytest.mark.slow
KEYS = Keys("t")


async def test_central_process_answers_and_stops_cleanly(zenoh_net: ZenohNet) -> None:
    async with FakeProvider(Policy(prefer="B")) as fake:
        uav = await zenoh_net.open("uav0")
        cmdr = await zenoh_net.open("cmdr")
        answers = uav.subscribe(KEYS.central_answer("uav0"), CentralAnswer)
        uav.declare_token(KEYS.alive_uav("uav0"))
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-m",
            "aeroweaver_edge",
            "central",
            "--mode",
            "centralized",
            "--swarm",
            "t",
            "--connect",
            f"tcp/127.0.0.1:{zenoh_net.seed_port}",
            "--namespace",
            zenoh_net.namespace,
            "--llm",
            fake.base_url,
            "--gather",
            "0.5",
            stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
        )
        try:
            assert proc.stderr is not None
            async with asyncio.timeout(60):
                line = await proc.stderr.readline()
            assert b"central node (centralized) up" in line
            h, u = HeaderFactory("cmdr"), HeaderFactory("uav0")
            options = ["A. explore_local()", "B. hold_position()"]
            got: list[CentralAnswer] = []
            async with asyncio.timeout(60):
                rnd = 0
                while not got:  # the process's subscriptions may take a moment to appear
                    cmdr.put(
                        KEYS.context,
                        MissionContext(
                            h=h.next(),
                            mission_id="m",
                            task="coverage",
                            text="t",
                            participants=["uav0"],
                        ),
                        block=True,
                    )
                    cmdr.put(
                        KEYS.assign("uav0"),
                        Assignment(
                            h=h.next(),
                            mission_id="m",
                            uav="uav0",
                            role="searcher",
                            local_goal="g",
                            skills=["explore_local", "hold_position"],
                        ),
                        block=True,
                    )
                    uav.put(
                        KEYS.ask("uav0"),
                        CentralAsk(
                            h=u.next(),
                            uav="uav0",
                            episode=0,
                            round=rnd,
                            observation="o",
                            options=options,
                        ),
                        block=True,
                    )
                    rnd += 1
                    await asyncio.sleep(1.0)
                    got = [a for _k, a in answers.drain()]
            assert got[0].phase == "final"
            assert got[0].label in ("A", "B")
            assert got[0].h.sender == "central"
            proc.send_signal(signal.SIGTERM)
            async with asyncio.timeout(30):
                _out, err = await proc.communicate()
            assert proc.returncode == 0
            assert b"central node stopped:" in err
            assert fake.chat_calls >= 1
        finally:
            if proc.returncode is None:
                proc.kill()
                await proc.wait()
