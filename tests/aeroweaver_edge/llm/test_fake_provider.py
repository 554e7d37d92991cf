"""The fake provider behaves like a real HTTP server (sockets, framing, JSON, keep-alive)."""

from __future__ import annotations

import asyncio
import json

import httpx
import pytest

from aeroweaver_edge.llm.fake_provider import QUIRKS, FakeProvider, Policy

CHAT = {
    "model": "m",
    "messages": [{"role": "user", "content": "A. x\nB. y\nC. z\nAnswer."}],
    "max_tokens": 1,
    "logprobs": True,
    "top_logprobs": 20,
}


async def raw_exchange(port: int, request: bytes) -> bytes:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(request)
    await writer.drain()
    data = await asyncio.wait_for(reader.read(65536), 2)
    writer.close()
    await writer.wait_closed()
    return data


async def test_http_framing_on_a_raw_socket() -> None:
    async with FakeProvider() as fp:
        body = json.dumps(CHAT).encode()
        request = (
            b"POST /v1/chat/completions HTTP/1.1\r\nHost: x\r\nConnection: close\r\n"
            b"Content-Type: application/json\r\nContent-Length: "
            + str(len(body)).encode()
            + b"\r\n\r\n"
            + body
        )
        data = await raw_exchange(fp.port, request)
    head, _, payload = data.partition(b"\r\n\r\n")
    lines = head.decode().split("\r\n")
    assert lines[0] == "HTTP/1.1 200 OK"
    headers = dict(line.split(": ", 1) for line in lines[1:])
    assert int(headers["Content-Length"]) == len(payload)
    assert headers["Content-Type"] == "application/json"
    answer = json.loads(payload)
    assert answer["object"] == "chat.completion"
    assert answer["choices"][0]["finish_reason"] == "length"


async def test_keep_alive_serves_many_requests_on_one_connection() -> None:
    async with FakeProvider() as fp, httpx.AsyncClient(base_url=fp.base_url) as http:
        for _ in range(3):
            assert (await http.post("/chat/completions", json=CHAT)).status_code == 200
        assert len(fp.requests) == 3
        assert fp.connections == 1  # one TCP connection served all three


async def test_routes() -> None:
    async with FakeProvider(model="fm") as fp, httpx.AsyncClient() as http:
        assert (await http.get(f"{fp.root_url}/health")).json() == {"status": "ok"}
        models = (await http.get(f"{fp.base_url}/models")).json()
        assert models["data"][0]["id"] == "fm"
        assert (await http.post(f"{fp.root_url}/tokenize", json={"content": " A"})).json() == {
            "tokens": [49 + 281]
        }
        assert (await http.get(f"{fp.root_url}/nope")).status_code == 404


async def test_policy_switches_at_run_time_and_is_seeded() -> None:
    async with (
        FakeProvider(Policy(prefer="A")) as fp,
        httpx.AsyncClient(base_url=fp.base_url) as http,
    ):
        first = (await http.post("/chat/completions", json=CHAT)).json()
        again = (await http.post("/chat/completions", json=CHAT)).json()
        assert first["choices"][0]["logprobs"] == again["choices"][0]["logprobs"]
        assert first["choices"][0]["message"]["content"] == "A"
        fp.policy = Policy(prefer="C")
        switched = (await http.post("/chat/completions", json=CHAT)).json()
        assert switched["choices"][0]["message"]["content"] == "C"
        fp.policy = Policy(prefer="C", seed=7)
        reseeded = (await http.post("/chat/completions", json=CHAT)).json()
        assert reseeded["choices"][0]["logprobs"] != switched["choices"][0]["logprobs"]


async def test_top_list_length_follows_the_request() -> None:
    async with FakeProvider() as fp, httpx.AsyncClient(base_url=fp.base_url) as http:
        for n in (1, 5, 20):
            body = {**CHAT, "top_logprobs": n}
            row = (await http.post("/chat/completions", json=body)).json()["choices"][0]
            assert len(row["logprobs"]["content"][0]["top_logprobs"]) == n


async def test_status_times_then_recovers_and_retry_after_header() -> None:
    async with (
        FakeProvider(Policy(status=429, status_times=2, retry_after=1.5)) as fp,
        httpx.AsyncClient(base_url=fp.base_url) as http,
    ):
        codes = []
        for _ in range(3):
            r = await http.post("/chat/completions", json=CHAT)
            codes.append(r.status_code)
        assert codes == [429, 429, 200]
        fp.policy = QUIRKS["rate_limited"]
        r = await http.post("/chat/completions", json=CHAT)
        assert r.headers["retry-after"] == "0"


async def test_deepseek_rules_on_top_logprobs_without_logprobs() -> None:
    async with FakeProvider() as fp, httpx.AsyncClient(base_url=fp.base_url) as http:
        r = await http.post("/chat/completions", json={**CHAT, "logprobs": False})
        assert r.status_code == 400
        assert "Invalid top_logprobs" in r.text


async def test_reasoning_shape() -> None:
    async with (
        FakeProvider(QUIRKS["reasoning"]) as fp,
        httpx.AsyncClient(base_url=fp.base_url) as http,
    ):
        answer = (await http.post("/chat/completions", json=CHAT)).json()
    choice = answer["choices"][0]
    assert choice["message"]["reasoning_content"]
    assert len(choice["logprobs"]["reasoning_content"]) == 3
    assert answer["usage"]["completion_tokens_details"]["reasoning_tokens"] == 3


async def test_close_ends_hanging_requests() -> None:
    fp = await FakeProvider(QUIRKS["hang"]).start()
    http = httpx.AsyncClient(base_url=fp.base_url, timeout=5)
    task = asyncio.create_task(http.post("/chat/completions", json=CHAT))
    for _ in range(200):  # until the request hangs in the server (bounded: 2 s)
        if fp.chat_bodies():
            break
        await asyncio.sleep(0.01)
    assert fp.chat_bodies()
    await asyncio.wait_for(fp.close(), 2)
    with pytest.raises(httpx.TransportError):
        await task
    await http.aclose()


async def test_hang_ends_when_the_client_gives_up() -> None:
    async with FakeProvider(QUIRKS["hang"]) as fp:
        async with httpx.AsyncClient(base_url=fp.base_url, timeout=0.2) as http:
            with pytest.raises(httpx.ReadTimeout):
                await http.post("/chat/completions", json=CHAT)
        for _ in range(50):
            if fp.open_connections == 0:
                break
            await asyncio.sleep(0.02)
        assert fp.open_connections == 0


def test_runs_in_a_thread_for_sync_code() -> None:
    with FakeProvider(Policy(prefer="B")).in_thread() as fp:
        r = httpx.post(f"{fp.base_url}/chat/completions", json=CHAT, timeout=5)
        assert r.json()["choices"][0]["message"]["content"] == "B"
        fp.policy = Policy(prefer="C")
        r = httpx.post(f"{fp.base_url}/chat/completions", json=CHAT, timeout=5)
        assert r.json()["choices"][0]["message"]["content"] == "C"
    with pytest.raises(httpx.ConnectError):
        httpx.get(f"{fp.root_url}/health", timeout=1)


def _chat(prefix: str, tail: str, slot: int | None = None) -> dict[str, object]:
    body: dict[str, object] = {**CHAT, "messages": [{"role": "user", "content": prefix + tail}]}
    if slot is not None:
        body["id_slot"] = slot
    return body


async def test_cache_slots_like_llama_server() -> None:
    a, b = "A" * 400, "B" * 400  # two agents' prefixes, nothing in common
    hit = (len("[user]\n") + 400) // 4  # the fake renders "[role]\n" headers, 4 chars a token
    policy = Policy(usage="llama", llama_extras=True)
    async with FakeProvider(policy, n_slots=2) as fp, httpx.AsyncClient() as http:

        async def cached(body: dict[str, object]) -> tuple[int, int]:
            answer = (await http.post(f"{fp.base_url}/chat/completions", json=body)).json()
            usage, timings = answer["usage"], answer["timings"]
            assert timings["cache_n"] + timings["prompt_n"] == usage["prompt_tokens"]
            return usage["prompt_tokens_details"]["cached_tokens"], timings["cache_n"]

        # Pinned: each agent finds its own prefix in its slot, whatever came in between.
        assert await cached(_chat(a, "1", slot=0)) == (0, 0)
        assert await cached(_chat(b, "1", slot=1)) == (0, 0)
        assert (await cached(_chat(a, "2", slot=0)))[0] == hit
        assert (await cached(_chat(b, "2", slot=3)))[0] == hit  # slot ids wrap, as in llama.cpp
        # Unpinned: the most similar slot, else the least recently used one.
        assert (await cached(_chat(a, "3")))[0] == hit
        assert (await cached(_chat("C" * 400, "1")))[0] == len("[user]\n") // 4
        assert fp.slots_served == [0, 1, 0, 1, 0, 1]  # "C" evicted b's slot (LRU)
        assert fp.chat_bodies()[3]["id_slot"] == 3  # every request is recorded as sent


def test_slot_count_must_be_positive() -> None:
    with pytest.raises(ValueError, match="n_slots"):
        FakeProvider(n_slots=0)
