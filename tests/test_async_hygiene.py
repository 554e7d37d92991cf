"""No ``asyncio.wait_for`` in the product: on Python 3.11 it returns the result and drops a
cancellation that arrives in the same loop iteration as that result (CPython gh-86296,
fixed in 3.12 by rewriting it on ``asyncio.timeout``). A daemon task that loses its cancel
that way runs on, and whoever awaits it on shutdown (``cancel_all``) waits forever: the
shape of stop 26's CI hang. ``async with asyncio.timeout(...)`` has no such window."""

from __future__ import annotations

import ast
import asyncio
from pathlib import Path

import pytest

from aeroweaver_edge.vehicle.mavlink.link import FlightLink

ROOT = Path(__file__).resolve().parent.parent


def wait_for_calls(path: Path) -> list[int]:
    """Lines of ``asyncio.wait_for`` / ``from asyncio import wait_for`` in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    lines = []
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and node.attr == "wait_for"
            and isinstance(node.value, ast.Name)
            and node.value.id == "asyncio"
        ):
            lines.append(node.lineno)
        elif isinstance(node, ast.ImportFrom) and node.module == "asyncio":
            lines.extend(node.lineno for a in node.names if a.name == "wait_for")
    return lines


def test_the_product_never_uses_asyncio_wait_for() -> None:
    found = {
        str(p.relative_to(ROOT)): lines
        for package in ("aeroweaver_edge", "commander")
        for p in sorted((ROOT / package).rglob("*.py"))
        if (lines := wait_for_calls(p))
    }
    assert found == {}, "use `async with asyncio.timeout(...)` (see this module's docstring)"


def test_the_scan_finds_both_spellings(tmp_path: Path) -> None:
    src = tmp_path / "m.py"
    src.write_text("import asyncio\nfrom asyncio import wait_for\nasyncio.wait_for(x, 1)\n")
    assert wait_for_calls(src) == [2, 3]


async def test_a_cancel_arriving_with_the_message_is_not_lost() -> None:
    """The message a link waits for and the task's cancel land in one loop iteration."""
    link = FlightLink("udpin://127.0.0.1:0")
    fut = link.expect("HEARTBEAT")
    waiter = asyncio.create_task(link.wait_future(fut, 5.0))
    await asyncio.sleep(0)  # the waiter is parked on the future
    fut.set_result(object())  # type: ignore[arg-type]
    waiter.cancel()
    with pytest.raises(asyncio.CancelledError):
        await waiter
