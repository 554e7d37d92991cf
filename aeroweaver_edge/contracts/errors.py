"""The two kinds of failure a command reports to its user, each as one line.

``UserError``: something the user can fix (a bad argument, an unwritable path, a missing
environment variable, a mission or config that cannot be used); the message names the cause
and the fix; exit status 2. It is a ``ValueError`` so library callers that validate input can
catch it as one. ``RunFailed``: the command started but could not finish as asked (a daemon
died, memory could not be written); exit status 1.

Any other error a user can meet (a broken skill package, a mesh that cannot open, a vehicle
link, an unset API-key variable, an unwritable memory) explains itself: its class has an
``explain()`` giving the exit status and the line, written where the error is raised, so
every front end (the CLI, the MCP server) says the same through ``describe`` and none of
them needs to know the library's error classes.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable


class UserError(ValueError):
    """A mistake the user can fix: ``cause``, then ``fix``; exit status 2. Never a bug: the
    CLI prints it without a traceback."""

    exit_status = 2

    def __init__(self, cause: str, fix: str = "") -> None:
        self.cause = cause
        self.fix = fix
        super().__init__(f"{cause}; {fix}" if fix else cause)


class RunFailed(Exception):
    """The command ran but did not finish as asked; exit status 1."""

    exit_status = 1


@runtime_checkable
class Explained(Protocol):
    def explain(self) -> tuple[int, str]:
        """(exit status, the one line a user reads: cause and fix)."""
        ...


def describe(exc: BaseException) -> tuple[int, str] | None:
    """(exit status, message) for the errors a user can meet; ``None`` for a bug."""
    if isinstance(exc, Explained):
        return exc.explain()
    if isinstance(exc, UserError):
        return 2, str(exc)
    if isinstance(exc, RunFailed):
        return 1, f"run failed: {exc}"
    return None


__all__ = ["Explained", "RunFailed", "UserError", "describe"]
