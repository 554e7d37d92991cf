"""Record the fidelity cases from a real ArduCopter SITL (your own build) into the committed
fixtures the CI test compares the emulator with:

    AEROWEAVER_SITL=/path/to/arducopter python -m tests.helpers.record_sitl [OUT_DIR]

One instance in its own network namespace and working directory (``sitl.SitlFleet``), at
real time (``--speedup 1``: the companion's 1 Hz heartbeat and the firmware's timeouts are
then on the same clock). Needs root for the namespace. Prints one line per case.
"""

from __future__ import annotations

import asyncio
import sys
import tempfile
import time
from pathlib import Path

from tests.helpers import fidelity, sitl


def main(out: Path) -> int:
    binary = sitl.binary_from_env()
    if binary is None:
        print(sitl.SKIP, file=sys.stderr)
        return 2
    why = sitl.unavailable()
    if why is not None:
        print(why, file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="aw-sitl-") as tmp:
        try:
            fleet = sitl.SitlFleet(sitl.check_binary(binary), Path(tmp))
            with fleet:
                [inst] = fleet.start(1)
                started = time.monotonic()
                traces = asyncio.run(
                    fidelity.fly_cases(inst.daemon_url, "sitl", list(fidelity.CASES))
                )
        except sitl.SitlError as exc:
            print(f"aeroweaver: {exc}", file=sys.stderr)
            return 2
    fidelity.save(traces, out)
    for t in traces:
        print(f"{t.case}: {len(t.events)} events, marks {t.marks}")
    print(f"recorded {len(traces)} cases in {time.monotonic() - started:.0f} s into {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]) if len(sys.argv) > 1 else fidelity.FIXTURES))
