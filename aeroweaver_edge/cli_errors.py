"""The CLI's single error path: any exception becomes one line and an exit status.

User errors (bad arguments, config, paths, environment, endpoints in use) exit 2 with the
cause and the fix; a run that could not finish exits 1; anything unexpected exits 1 as an
internal error. Tracebacks only with ``aeroweaver -v``.
"""

from __future__ import annotations

import argparse
import sys
from typing import NoReturn

from aeroweaver_edge.errors import RunFailed, UserError
from aeroweaver_edge.redact import redact_text

PROG = "aeroweaver"


def one_line(text: str) -> str:
    """Whitespace and newlines collapsed: a message is one line, whatever produced it."""
    return " ".join(redact_text(text).split())


def describe(exc: BaseException) -> tuple[int, str] | None:
    """(exit status, message) for the errors a user can meet; ``None`` for a bug."""
    from aeroweaver_edge.agent.memory import MemoryUnavailable
    from aeroweaver_edge.config import ConfigError
    from aeroweaver_edge.llm.client import LLMConfigError
    from aeroweaver_edge.mesh import MeshError
    from aeroweaver_edge.skills import SkillError
    from commander.mission_parser import MissionParseError

    if isinstance(exc, ConfigError):  # a UserError too: its fix has a default
        fix = (
            exc.fix or "correct that setting (keys: configs/uav.toml; bounds: docs/reliability.md)"
        )
        return 2, f"config error: {exc}; {fix}"
    if isinstance(exc, MissionParseError):  # a UserError too
        return 2, f"cannot understand the mission: {exc}"
    if isinstance(exc, UserError):
        return 2, str(exc)
    if isinstance(exc, RunFailed):
        return 1, f"run failed: {exc}"
    if isinstance(exc, SkillError):
        first = str(exc.problems[0]) if exc.problems else str(exc)
        more = f" (and {len(exc.problems) - 1} more problems)" if len(exc.problems) > 1 else ""
        return 2, (
            f"broken skill package: {first}{more}; fix that file, or point "
            "AEROWEAVER_SKILLS_DIR at a valid skills directory"
        )
    if isinstance(exc, MeshError):
        text = str(exc)
        if "already in use" in text.lower():
            return 2, (
                f"a listen endpoint is already in use ({text}); choose a free port in "
                "mesh.listen / --listen, or stop the process that holds it"
            )
        return 2, f"{text}; check mesh.listen, mesh.connect and mesh.namespace"
    from aeroweaver_edge.vehicle.errors import VehicleError
    from aeroweaver_edge.vehicle.mavlink.signing import SigningError

    if isinstance(exc, VehicleError):  # the vehicle link could not be brought up
        return 1, f"vehicle: {exc}"
    if isinstance(exc, SigningError):
        return 2, f"signing: {exc}"
    if isinstance(exc, LLMConfigError):
        return 2, f"{exc}; export it, or drop --api-key-env / llm.api_key_env"
    if isinstance(exc, MemoryUnavailable):
        if exc.during == "open":
            return 2, (
                f"{exc}; choose a writable --memory-dir / agent.memory_path, or set "
                "agent.memory_required = false to fly without persistent memory"
            )
        return 1, f"{exc}; the daemon held and stopped (agent.memory_required = true)"
    return None


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
