"""A real HTTP/1.1 server on loopback that answers each request with the next scripted
response, byte for byte: hostile LLM endpoints (a 50 MB body streamed in chunks, JSON
nested 100,000 deep, a lying Content-Length) that a well-behaved fake would never send.

    async with ScriptedHttp([Reply(200, body=b"..."), Reply.stream(50 << 20)]) as srv:
        client = ChatClient(srv.base_url, "m")

When the script runs out, the last reply repeats. ``requests`` holds every request body
(parsed JSON when it is JSON); ``sent`` counts the body bytes each reply really wrote.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any


@dataclass
class Reply:
    status: int = 200
    body: bytes = b""
    headers: dict[str, str] = field(default_factory=dict)
    chunks: Callable[[], Iterator[bytes]] | None = None  # streamed, chunked encoding

    @classmethod
    def json(cls, status: int, obj: Any) -> Reply:
        return cls(status, json.dumps(obj).encode())

    @classmethod
    def stream(cls, total: int, piece: bytes = b" " * 65536) -> Reply:
        """``total`` bytes of (whitespace-padded) JSON, sent in chunks as they are made."""

        def gen() -> Iterator[bytes]:
            yield b'{"choices": ['
            left = total
            while left > 0:
                part = piece[: min(left, len(piece))]
                left -= len(part)
                yield part
            yield b"]}"

        return cls(200, chunks=gen)


def nested_json(depth: int) -> bytes:
    """A chat completion whose ``usage`` holds ``depth`` nested lists."""
    return (
        b'{"choices": [{"message": {"content": "A"}, "finish_reason": "stop"}], "usage": '
        + b"[" * depth
        + b"]" * depth
        + b"}"
    )


class ScriptedHttp:
    def __init__(self, script: list[Reply]) -> None:
        self.script = list(script)
        self.requests: list[Any] = []
        self.sent: list[int] = []
        self._server: asyncio.Server | None = None
        self.port = 0

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}/v1"

    async def __aenter__(self) -> ScriptedHttp:
        self._server = await asyncio.start_server(self._serve, "127.0.0.1", 0)
        self.port = self._server.sockets[0].getsockname()[1]
        return self

    async def __aexit__(self, *exc: object) -> None:
        assert self._server is not None
        self._server.close()
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self._server.wait_closed(), 2.0)

    def _next(self) -> Reply:
        return self.script.pop(0) if len(self.script) > 1 else self.script[0]

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while True:
                head = await reader.readuntil(b"\r\n\r\n")
                lines = head.decode("latin-1").split("\r\n")
                length = 0
                for line in lines[1:]:
                    name, _, value = line.partition(":")
                    if name.strip().lower() == "content-length":
                        length = int(value.strip())
                raw = await reader.readexactly(length)
                try:
                    self.requests.append(json.loads(raw))
                except ValueError:
                    self.requests.append(raw)
                await self._reply(writer, self._next())
        except (asyncio.IncompleteReadError, ConnectionError, asyncio.LimitOverrunError):
            pass
        finally:
            writer.close()
            with contextlib.suppress(Exception):
                await writer.wait_closed()

    async def _reply(self, writer: asyncio.StreamWriter, reply: Reply) -> None:
        headers = {"Content-Type": "application/json", **reply.headers}
        sent = 0
        if reply.chunks is None:
            headers.setdefault("Content-Length", str(len(reply.body)))
            writer.write(self._head(reply.status, headers) + reply.body)
            await writer.drain()
            self.sent.append(len(reply.body))
            return
        headers["Transfer-Encoding"] = "chunked"
        writer.write(self._head(reply.status, headers))
        self.sent.append(0)
        for chunk in reply.chunks():
            writer.write(b"%x\r\n%s\r\n" % (len(chunk), chunk))
            await writer.drain()  # raises once the client hung up: nothing more is made
            sent += len(chunk)
            self.sent[-1] = sent
        writer.write(b"0\r\n\r\n")
        await writer.drain()

    @staticmethod
    def _head(status: int, headers: dict[str, str]) -> bytes:
        lines = [f"HTTP/1.1 {status} X"] + [f"{k}: {v}" for k, v in headers.items()]
        return ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1")
