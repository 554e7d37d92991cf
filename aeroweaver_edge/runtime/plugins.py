"""Extensions found by name, never imported by path: the runtime knows what another
distribution adds (the lab's ``aeroweaver bench`` and ``central`` commands, its baseline
selectors) only through these entry-point groups, so the product never depends on research
code and a companion computer can run without it.

* ``aeroweaver.commands``: ``name = "module:object"``, the object a ``Command``;
* ``aeroweaver.selectors``: ``name = "module:factory"``, a ``SelectorFactory`` for
  ``[agent] selector = "name"``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any, Final

from aeroweaver_edge.contracts.errors import UserError

COMMANDS: Final = "aeroweaver.commands"
SELECTORS: Final = "aeroweaver.selectors"

LAB_HINT: Final = "pip install -e ./lab (from a checkout of the repository)"
"""Where the research tools come from: the ``aeroweaver-lab`` distribution in ``lab/``."""

KNOWN_EXTENSIONS: Final = {
    "bench": "the benchmark and the research experiments",
    "central": "a baseline's central node (Centralized, HMAS-2)",
    "centralized": "the Centralized baseline's UAV side",
    "hmas2": "the HMAS-2 baseline's UAV side",
}
"""Names the lab provides: missing, they are refused with one line saying where to get them."""


@dataclass(frozen=True)
class Command:
    """An ``aeroweaver NAME ...`` command of another distribution: it parses its own
    arguments (everything after NAME) and returns the exit status."""

    help: str
    main: Callable[[Sequence[str], bool], int]  # (argv after NAME, verbose) -> exit status


def names(group: str) -> list[str]:
    """Every name registered in ``group``, sorted."""
    return sorted({ep.name for ep in entry_points(group=group)})


def load(group: str, name: str) -> Any:
    """The object registered as ``name`` in ``group``; a missing one is one line saying
    which distribution provides it (a broken one raises as its import does)."""
    for ep in entry_points(group=group, name=name):
        return ep.load()
    what = KNOWN_EXTENSIONS.get(name)
    if what is None:
        raise UserError(f"{name!r} is not installed (no {group} entry point of that name)")
    raise UserError(f"{name}: {what} is in the aeroweaver-lab distribution", LAB_HINT)


def command(name: str) -> Command | None:
    """The command ``name`` of an installed extension, else None."""
    with contextlib.suppress(UserError):
        found = load(COMMANDS, name)
        if isinstance(found, Command):
            return found
        raise TypeError(f"entry point {COMMANDS}:{name} is not an aeroweaver Command")
    return None


__all__ = ["COMMANDS", "KNOWN_EXTENSIONS", "LAB_HINT", "SELECTORS", "Command", "command",
           "load", "names"]  # fmt: skip
