"""``python -m aeroweaver_edge``: the ``aeroweaver`` program, for environments without the
console script (and for tests that start it with the interpreter they run under)."""

import sys

from aeroweaver_edge.cli.main import main

sys.exit(main())
