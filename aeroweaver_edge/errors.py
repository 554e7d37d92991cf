"""The two kinds of failure a command reports to its user, each as one line.

``UserError``: something the user can fix (a bad argument, an unwritable path, a missing
environment variable, a mission or config that cannot be used); the message names the cause
and the fix; exit status 2. It is a ``ValueError`` so library callers that validate input can
catch it as one. ``RunFailed``: the command started but could not finish as asked (a daemon
died, memory could not be written); exit status 1. ``cli_errors`` maps these and the
library's own errors (config, mesh, skills, LLM, memory) to one line each.
"""

from __future__ import annotations


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


__all__ = ["RunFailed", "UserError"]
