"""Schema'd JSON calls against the fake provider over real loopback HTTP: the schema is
sent, an endpoint that refuses it is asked again without (and never again with) it, and a
failed call comes back as an error, never an exception."""

from __future__ import annotations

from aeroweaver_edge.llm.client import CallTag, ChatClient
from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
from aeroweaver_lab.baselines.json_chat import JsonAnswer, JsonMode, extract_object, json_chat
from aeroweaver_lab.baselines.protocol import team_schema

MSGS = [{"role": "user", "content": "choose"}]
SCHEMA = team_schema({"uav0": ["A", "B"], "uav1": ["C"]})


def test_extract_object() -> None:
    assert extract_object('```json\n{"a": 1}\n```') == {"a": 1}
    assert extract_object('noise {bad} then {"b": [1, 2]} tail') == {"b": [1, 2]}
    assert extract_object("[1, 2]") is None
    assert extract_object("no json here") is None


async def test_schema_answer_fits_and_usage_is_counted() -> None:
    async with FakeProvider(Policy(prefer="B")) as fp:
        async with ChatClient(fp.base_url, "fake-model") as client:
            mode = JsonMode()
            ans = await json_chat(
                client,
                MSGS,
                SCHEMA,
                name="plan",
                max_tokens=40,
                tag=CallTag("central"),
                mode=mode,
                slot=3,
            )
        body = fp.chat_bodies()[0]
    assert body["response_format"]["json_schema"]["schema"] == SCHEMA
    assert body["id_slot"] == 3
    assert body["max_tokens"] == 40
    assert ans.error is None
    assert ans.requests == 1
    assert ans.value is not None
    assert set(ans.value) == {"uav0", "uav1"}
    assert ans.value["uav0"] in ("A", "B")
    assert ans.value["uav1"] == "C"
    assert ans.prompt_tokens > 0
    assert ans.completion_tokens > 0


async def test_a_refused_schema_is_retried_without_it_and_remembered() -> None:
    async with FakeProvider(Policy(json_answers="refuse_schema")) as fp:
        async with ChatClient(fp.base_url, "fake-model", retries=0) as client:
            mode = JsonMode()
            first = await json_chat(
                client, MSGS, SCHEMA, name="plan", max_tokens=40, tag=CallTag(), mode=mode
            )
            second = await json_chat(
                client, MSGS, SCHEMA, name="plan", max_tokens=40, tag=CallTag(), mode=mode
            )
        bodies = fp.chat_bodies()
    assert mode.schema_ok is False
    assert ["response_format" in b for b in bodies] == [True, False, False]
    assert first.requests == 2
    assert second.requests == 1
    assert first.error is None  # answered (with a plain letter, which is no JSON object)
    assert first.value is None


async def one_call(policy: Policy) -> JsonAnswer:
    async with FakeProvider(policy) as fp, ChatClient(fp.base_url, "fake-model", retries=0) as c:
        return await json_chat(
            c, MSGS, SCHEMA, name="plan", max_tokens=40, tag=CallTag(), mode=JsonMode()
        )


async def test_garbage_and_failures_come_back_as_values() -> None:
    ans = await one_call(Policy(json_answers="garbage"))
    assert ans.value is None
    assert ans.error is None
    assert ans.text.startswith("Sure!")
    ans = await one_call(Policy(status=503))
    assert ans.value is None
    assert ans.error is not None
    assert "503" in ans.error
    assert ans.requests == 1
    assert ans.prompt_tokens == 0


async def test_foreign_label_mode_breaks_the_enum() -> None:
    ans = await one_call(Policy(json_answers="foreign_label"))
    assert ans.value == {"uav0": "Z", "uav1": "Z"}
