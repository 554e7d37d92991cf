"""Every failure of an MCP tool reaches the client as a tool error (``isError``) carrying one
readable line, never the SDK's bare "Error executing tool X" with the cause on our stderr.

* a refusal the tool raised (``ToolError``): its own message, without the SDK's prefix;
* arguments that fail the input schema: ``invalid arguments for X: field: why (got ...)``,
  one clause per field, no pydantic banner, error codes or documentation links;
* an error a user can meet (``UserError``, config, mesh, mission text, ...): the CLI's own
  one line for it (``contracts.errors.describe``), e.g. the known tasks for an unknown one;
* anything else: ``internal error: Type: message``, and the traceback in the server's log.
"""

from __future__ import annotations

import logging
from typing import Any

from mcp.server.mcpserver import MCPServer
from mcp.server.mcpserver.context import Context
from mcp.server.mcpserver.exceptions import ToolError, UnexpectedToolError
from mcp.shared.exceptions import MCPError
from mcp.types import CallToolResult, InputRequiredResult
from pydantic import ValidationError

from aeroweaver_edge.contracts.errors import describe
from aeroweaver_edge.runtime.redact import one_line

log = logging.getLogger(__name__)
MAX_INPUT_CHARS = 40  # an echoed argument value is cut to this many characters


def validation_line(tool: str, exc: ValidationError) -> str:
    """``invalid arguments for plan_mission: text: Field required``, one clause per error."""
    parts = []
    for err in exc.errors(include_url=False):
        loc = ".".join(str(p) for p in err["loc"]) or "arguments"
        clause = f"{loc}: {err['msg']}"
        if err["type"] != "missing":
            shown = repr(err.get("input"))
            if len(shown) > MAX_INPUT_CHARS:
                shown = shown[: MAX_INPUT_CHARS - 3] + "..."
            clause += f" (got {shown})"
        parts.append(clause)
    return f"invalid arguments for {tool}: " + "; ".join(parts)


def failure_line(tool: str, exc: ToolError) -> str:
    """The one line for what ``MCPServer.call_tool`` raised (see the module docstring)."""
    cause = exc.__cause__
    if isinstance(cause, ValidationError):
        return one_line(validation_line(tool, cause))
    if isinstance(exc, UnexpectedToolError) and cause is not None:
        described = describe(cause)
        if described is not None:
            return one_line(described[1])
        log.error("tool %s failed", tool, exc_info=cause)
        text = f": {cause}" if str(cause) else ""
        return one_line(f"internal error: {type(cause).__name__}{text} (see the server's log)")
    if isinstance(cause, ToolError):  # raised by the tool: the SDK only added its prefix
        return one_line(str(cause))
    return one_line(str(exc))  # the SDK's own (an unknown tool name)


class AgentServer(MCPServer[Any]):
    """``MCPServer`` whose tool failures are one line each (``failure_line``)."""

    async def call_tool(
        self, name: str, arguments: dict[str, Any], context: Context[Any, Any] | None = None
    ) -> CallToolResult | InputRequiredResult:
        try:
            return await super().call_tool(name, arguments, context)
        except MCPError:
            raise
        except ToolError as exc:
            cause = exc.__cause__ if isinstance(exc.__cause__, ValidationError) else None
            # from the ValidationError: the SDK then logs the field names, not the values
            raise ToolError(failure_line(name, exc)) from cause


__all__ = ["AgentServer", "failure_line", "validation_line"]
