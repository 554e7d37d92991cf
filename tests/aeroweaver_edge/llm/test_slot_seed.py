"""Seeding cache slots: one computation of a shared prefix, copied into the other slots."""

from __future__ import annotations

import logging

import httpx
import pytest

from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
from aeroweaver_edge.llm.slot_seed import SlotGroup, seed_slots

PREFIX = [{"role": "system", "content": "S" * 800}, {"role": "user", "content": "You are UAV "}]


async def ask(fp: FakeProvider, slot: int, tail: str) -> int:
    user = {"role": "user", "content": "You are UAV " + tail}
    body = {"model": "m", "messages": [PREFIX[0], user], "max_tokens": 1, "id_slot": slot}
    async with httpx.AsyncClient() as http:
        answer = (await http.post(f"{fp.base_url}/chat/completions", json=body)).json()
    return int(answer["usage"]["prompt_tokens_details"]["cached_tokens"])


async def test_a_group_prefix_is_computed_once_and_restored_into_its_other_slots() -> None:
    other = [{"role": "system", "content": "O" * 400}]
    async with FakeProvider(Policy(), n_slots=4) as fp:
        seeded = await seed_slots(
            fp.root_url, "m", [SlotGroup(PREFIX, [1, 0, 2]), SlotGroup(other, [3])]
        )
        chats = len(fp.chat_bodies())
        first_decisions = [await ask(fp, s, "uav9.\nround 0") for s in (0, 1, 2)]
    assert seeded == 4
    assert chats == 2  # one prefill per group, not per slot
    assert fp.chat_bodies()[0]["id_slot"] == 1  # computed in the group's first slot
    assert set(fp.slot_files) == {"seed-0.bin"}  # a single-slot group needs no file
    shared = (len("[system]\n") + 800 + len("\n[user]\nYou are UAV ")) // 4
    assert first_decisions == [shared] * 3  # every slot of the group starts warm


async def test_a_server_without_slot_files_is_logged_not_raised(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with FakeProvider(Policy(), n_slots=2) as fp:
        url = fp.root_url
    with caplog.at_level(logging.WARNING):
        seeded = await seed_slots(url, "m", [SlotGroup(PREFIX, [0, 1])], timeout_s=2.0)
    assert seeded == 0
    assert "could not seed cache slots [0, 1]" in caplog.text


async def test_a_failed_restore_keeps_the_slots_already_seeded(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with FakeProvider(Policy(), n_slots=2) as fp:

        class NoSave(httpx.AsyncBaseTransport):
            """Lets chat through but loses every save, as a server without a save path."""

            def __init__(self) -> None:
                self.inner = httpx.AsyncHTTPTransport()

            async def handle_async_request(self, request: httpx.Request) -> httpx.Response:
                if request.url.params.get("action") == "save":
                    return httpx.Response(200, json={})
                return await self.inner.handle_async_request(request)

        with caplog.at_level(logging.WARNING):
            seeded = await seed_slots(
                fp.root_url, "m", [SlotGroup(PREFIX, [0, 1])], transport=NoSave()
            )
    assert seeded == 1  # slot 0 holds the prefix; slot 1 will compute its own
    assert "not found" in caplog.text
