"""The ``aeroweaver`` program: argument parsing (``main``), checks that run before any work,
the one error path, and the operator commands. ``early`` is imported first, before any
other submodule: a SIGTERM while the CLI is still importing ends it at once (status 0)."""

from aeroweaver_edge.cli import early as early
