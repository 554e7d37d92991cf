"""Where a hung async test waits: each running loop's tasks down their await chains.

pytest-timeout dumps threads only; a hung async test's main thread is always in ``select``,
which says nothing. ``tests/conftest.py`` calls this shortly before the timeout fires.
"""

from __future__ import annotations

import asyncio
import gc
import sys
from types import FrameType
from typing import TextIO

import pytest


def timeout_s(item: pytest.Item) -> float:
    """The test's pytest-timeout budget: its marker's, else the ini's (0: none)."""
    marker = item.get_closest_marker("timeout")
    if marker is not None and marker.args:
        return float(marker.args[0])
    return float(item.config.getini("timeout") or 0)


def _await_chain(obj: object) -> list[str]:
    """``file:line in name`` down a suspended coroutine's await chain (``Task.get_stack``
    stops at the outermost frame)."""
    out: list[str] = []
    frame_attrs = ("cr_frame", "ag_frame", "gi_frame")
    await_attrs = ("cr_await", "ag_await", "gi_yieldfrom")
    for _ in range(64):
        kind = next((a for a in frame_attrs if hasattr(obj, a)), None)
        if kind is None:  # not a coroutine: the future (or task) it waits on
            out.append(f"waits on {obj!r}"[:300])
            break
        frame: FrameType | None = getattr(obj, kind)
        if frame is not None:
            out.append(f"{frame.f_code.co_filename}:{frame.f_lineno} in {frame.f_code.co_name}")
        obj = next((getattr(obj, a) for a in await_attrs if hasattr(obj, a)), None)
        if obj is None:
            break
    return out


def dump_asyncio_tasks(nodeid: str, file: TextIO | None = None) -> None:
    """Print where every task of every running loop waits. Called from another thread
    while the loop runs, so it is best effort: it reads, never touches, the loop."""
    loops = [o for o in gc.get_objects() if isinstance(o, asyncio.AbstractEventLoop)]
    lines = [f"+++ {nodeid}: about to time out; asyncio tasks of each running loop +++"]
    for loop in loops:
        if not loop.is_running():
            continue
        try:
            tasks = list(asyncio.all_tasks(loop))
        except RuntimeError:  # the set changed under us: this is a best-effort dump
            continue
        for task in tasks:
            lines.append(f"--- {task.get_name()}")
            lines.extend(f"    {where}" for where in _await_chain(task.get_coro()))
    print("\n".join(lines), file=file or sys.stderr, flush=True)
