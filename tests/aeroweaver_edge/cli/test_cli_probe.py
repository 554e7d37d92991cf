"""``aeroweaver probe``: its exit status follows the verdict (real loopback fake)."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest

from aeroweaver_edge.cli.main import main
from aeroweaver_edge.llm.fake_provider import QUIRKS, FakeProvider, Policy


@pytest.fixture(scope="module")
def fake() -> Iterator[FakeProvider]:
    with FakeProvider(model="fake-model").in_thread() as fp:
        yield fp


@pytest.mark.parametrize(
    ("policy", "model", "status", "kind"),
    [
        (Policy(), "fake-model", 0, "ok"),
        (QUIRKS["reject_logprobs"], "fake-model", 3, "rejected"),
        (QUIRKS["degenerate"], "fake-model", 3, "degenerate"),
        (QUIRKS["unauthorized"], "fake-model", 4, "auth"),
        (QUIRKS["wrong_model"], "gpt-nonexistent", 5, "not_found"),
        (QUIRKS["hang"], "fake-model", 7, "timeout"),
        (QUIRKS["server_error"], "fake-model", 8, "server_error"),
        (QUIRKS["context_length"], "fake-model", 8, "bad_request"),
    ],
)
def test_probe_exit_status_follows_the_verdict(
    fake: FakeProvider,
    capsys: pytest.CaptureFixture[str],
    policy: Policy,
    model: str,
    status: int,
    kind: str,
) -> None:
    fake.policy = policy
    argv = ["probe", "--llm", fake.base_url, "--model", model, "--llm-deadline", "0.5"]
    assert main(argv) == status
    out = capsys.readouterr().out
    assert out.startswith(f"LLM probe [{kind}] {model} @ http://127.0.0.1:{fake.port}/v1")
    assert out.count("\n") == 1


def test_probe_unreachable_exits_6(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert main(["probe", "--llm", f"http://127.0.0.1:{port}/v1", "--llm-deadline", "1"]) == 6
    assert "[unreachable]" in capsys.readouterr().out


def test_probe_never_prints_credentials(
    fake: FakeProvider, capsys: pytest.CaptureFixture[str]
) -> None:
    fake.policy = Policy()
    url = f"http://ops:pa55word-x@127.0.0.1:{fake.port}/v1?api_key=sk-live-123456"
    assert main(["probe", "--llm", url, "--model", "fake-model"]) == 0
    out, err = capsys.readouterr()
    assert "pa55word-x" not in out + err
    assert "sk-live-123456" not in out + err
    assert "http://***@127.0.0.1" in out
