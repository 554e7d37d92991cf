"""On real ArduCopter SITL (``pytest -m sitl``, AEROWEAVER_SITL=/path/to/arducopter): a
daemon's vehicle half (``tests/helpers/flier.py``: the real backend and flight phases) sets
the companion-loss failsafe at preflight, flies in GUIDED, and is killed or stopped; the
firmware itself lands the vehicle and disarms it. Timed from an independent watcher on the
instance's SERIAL1."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from tests.aeroweaver_edge.vehicle.mavlink.test_companion_failsafe import (
    kill_and_time,
    start_flier,
    wait_flying,
)
from tests.helpers import sitl
from tests.helpers.mav_watch import MavWatcher

pytestmark = [pytest.mark.sitl, pytest.mark.slow, pytest.mark.timeout(300)]


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGSTOP], ids=["SIGKILL", "SIGSTOP"])
def test_a_dead_daemon_leaves_a_sitl_copter_that_lands_and_disarms(
    tmp_path: Path, sig: int
) -> None:
    binary = sitl.check_binary(sitl.binary_from_env() or Path())
    with (
        MavWatcher(host="0.0.0.0") as watcher,
        sitl.SitlFleet(binary, tmp_path, watch_port=watcher.port) as fleet,
    ):
        [inst] = fleet.start(1)
        proc = start_flier(inst.daemon_url)
        try:
            wait_flying(proc, 150.0)
        except BaseException:
            proc.kill()
            proc.wait(timeout=10)
            raise
        w = watcher.watch(inst.sysid)
        assert w.mode == "GUIDED"
        assert w.armed
        left, after, disarmed = kill_and_time(proc, sig, w, "GUIDED", 5.0)
        texts = [t for _at, t in w.texts]
    print(f"\nSITL {signal.Signals(sig).name}: left GUIDED after {left:.2f} s ({after}), "
          f"disarmed after {disarmed:.2f} s; texts: {texts[-6:]}")  # fmt: skip
    assert left is not None
    assert left <= 5.0
    assert after == "LAND"
    assert any("GCS" in t and "ailsafe" in t for t in texts)
