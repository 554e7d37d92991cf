"""``AgentServer``: each kind of tool failure reaches the SDK's own client (in-process) as
``isError`` with one line; a crash's traceback stays in the server's log, its line does not."""

from __future__ import annotations

import logging

import pytest
from mcp import Client
from mcp.server.mcpserver.exceptions import ToolError

from aeroweaver_edge.config import ConfigError
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.mcp_server.errors import AgentServer
from tests.aeroweaver_edge.mcp_server.test_mcp import error


def server() -> AgentServer:
    s = AgentServer("t")

    @s.tool()
    def refuse() -> str:
        raise ToolError("not now:\nthe Commander is busy")

    @s.tool()
    def user() -> str:
        raise UserError("no such swarm", "pass --swarm field")

    @s.tool()
    def config() -> str:
        raise ConfigError("mesh.listen: bad endpoint")

    @s.tool()
    def crash() -> str:
        raise RuntimeError("boom\n  at line 3")

    @s.tool()
    def silent() -> str:
        raise TimeoutError

    @s.tool()
    def typed(n: int, name: str) -> str:
        return f"{name}{n}"

    return s


async def test_every_failure_is_one_line(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    async with Client(server()) as c:
        assert error(await c.call_tool("refuse", {})) == "not now: the Commander is busy"
        assert error(await c.call_tool("user", {})) == "no such swarm; pass --swarm field"
        assert error(await c.call_tool("config", {})).startswith(
            "config error: mesh.listen: bad endpoint; correct that setting"
        )
        assert error(await c.call_tool("crash", {})) == (
            "internal error: RuntimeError: boom at line 3 (see the server's log)"
        )
        assert error(await c.call_tool("silent", {})) == (
            "internal error: TimeoutError (see the server's log)"
        )
        long = "x" * 100
        assert error(await c.call_tool("typed", {"n": "many", "name": long})) == (
            "invalid arguments for typed: n: Input should be a valid integer, unable to parse "
            "string as an integer (got 'many')"
        )
        cut = repr([1] * 50)[:37] + "..."  # an echoed value: 40 characters at most
        assert error(await c.call_tool("typed", {"n": [1] * 50})) == (
            f"invalid arguments for typed: n: Input should be a valid integer (got {cut}); "
            "name: Field required"
        )
    crashes = [r for r in caplog.records if r.exc_info and r.name.endswith("mcp_server.errors")]
    assert [str(r.exc_info[1]) for r in crashes if r.exc_info] == ["boom\n  at line 3", ""]
