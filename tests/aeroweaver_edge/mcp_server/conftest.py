"""The MCP server needs its optional extra (``pip install -e '.[mcp]'``; .ci/run has it)."""

import pytest

pytest.importorskip("mcp", reason="the mcp extra is not installed (.[mcp])")
