"""What the ``aeroweaver`` process does before anything else: a SIGTERM while the CLI is
still importing (a daemon stopped 0.2 s after it was started: ``systemctl stop`` right
after ``start``, a run torn down early) ends it at once with status 0. Nothing has started
then, so there is nothing to close; the command installs its own handler when it runs.

Only in the ``aeroweaver`` process itself (the console script or ``python -m
aeroweaver_edge``): a program that imports the CLI keeps its own signal handling.
"""

from __future__ import annotations

import os
import signal
import sys


def exit_early(signum: int, _frame: object) -> None:
    os._exit(0)


def is_cli_process(argv0: str, main_module: str) -> bool:
    return os.path.basename(argv0) == "aeroweaver" or main_module in (
        "aeroweaver_edge.__main__",
        "aeroweaver_edge.cli.main",
    )


_main = sys.modules.get("__main__")
_spec = getattr(_main, "__spec__", None)
if is_cli_process(sys.argv[0] if sys.argv else "", getattr(_spec, "name", "") or ""):
    signal.signal(signal.SIGTERM, exit_early)
