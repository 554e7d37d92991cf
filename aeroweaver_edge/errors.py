"""The one base class for bad input that a command reports as one line and exit status 2."""

from __future__ import annotations


class UserError(ValueError):
    """The operator's input (arguments, config, mission text) cannot be used; the message
    says why. Never a bug: the CLI prints it without a traceback."""


__all__ = ["UserError"]
