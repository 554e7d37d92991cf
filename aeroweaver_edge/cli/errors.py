"""The CLI's single error path: any exception becomes one line and an exit status.

User errors (bad arguments, config, paths, environment, endpoints in use) exit 2 with the
cause and the fix; a run that could not finish exits 1; anything unexpected exits 1 as an
internal error. Tracebacks only with ``aeroweaver -v``. The wording of each error is its
own (``contracts.errors.describe``), so the MCP server says the same.
"""

from __future__ import annotations

import argparse
import sys
from typing import NoReturn

from aeroweaver_edge.contracts.errors import describe
from aeroweaver_edge.runtime.redact import one_line

PROG = "aeroweaver"


def report(exc: BaseException, *, verbose: bool) -> int:
    """Print the one line (and the traceback when verbose); return the exit status."""
    described = describe(exc)
    if verbose:
        import traceback

        traceback.print_exception(exc)
    if described is None:
        status, message = (
            1,
            (
                f"internal error: {type(exc).__name__}: {exc}"
                + ("" if verbose else " (run with -v for the traceback)")
            ),
        )
    else:
        status, message = described
    print(f"{PROG}: {one_line(message)}", file=sys.stderr)
    return status


class ArgumentParser(argparse.ArgumentParser):
    """argparse with one-line usage errors (exit 2) naming the command's --help."""

    def error(self, message: str) -> NoReturn:
        print(
            f"{PROG}: error: {one_line(message)}; see '{self.prog} --help'",
            file=sys.stderr,
        )
        raise SystemExit(2)
