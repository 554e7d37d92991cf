"""The companion-loss failsafe: set at preflight, refused when it cannot be set, and a
killed or stopped daemon process leaves a vehicle that lands and disarms by itself."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aeroweaver_edge.sim.emulator.autopilot import Faults
from aeroweaver_edge.sim.emulator.host import EmulatorOptions
from aeroweaver_edge.vehicle.errors import VehicleError
from aeroweaver_edge.vehicle.mavlink import companion_failsafe
from tests.helpers.mav import ThreadedEmulator, emulated, free_udp_ports
from tests.helpers.mav_watch import MavWatcher, Watch

ROOT = Path(__file__).resolve().parents[4]
ARM = 400


@pytest.mark.parametrize(
    ("personality", "expected"),
    [
        (
            "ardupilot",  # and the fence it uploads, on (ArduCopter ships FENCE_ENABLE 0)
            {"MAV_GCS_SYSID": 1.0, "FS_GCS_ENABLE": 5.0, "FS_GCS_TIMEOUT": 3.0, "FENCE_ENABLE": 1},
        ),
        ("px4", {"COM_OBL_RC_ACT": 4.0, "COM_OF_LOSS_T": 1.0}),
    ],
)
async def test_preflight_sets_the_companion_loss_failsafe_and_says_so(
    personality: str, expected: dict[str, float], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level("INFO")
    async with emulated(1, personality=personality) as (host, [v]):
        ap = host.vehicles[0]
        assert v.refused is None
        for name, value in expected.items():
            assert ap.param(name) == value, name
        fs = v.preflight.companion_failsafe
        assert fs is not None
        assert fs.ok
        assert "lands" in fs.summary
        line = next(r.message for r in caplog.records if "companion-loss failsafe" in r.message)
        if personality == "ardupilot":  # the firmware defaults were changed, and it says how
            assert "MAV_GCS_SYSID 255 -> 1" in line
            assert "FS_GCS_ENABLE 0 -> 5" in line
            assert "lands 3 s after the daemon's last heartbeat" in line
        else:
            assert "COM_OBL_RC_ACT 0 -> 4" in line
            assert "lands 1 s after the daemon's last setpoint" in line


async def test_return_is_set_when_configured() -> None:
    async with emulated(1, personality="ardupilot", vehicle={"companion_failsafe": "return"}) as (
        host,
        [v],
    ):
        assert host.vehicles[0].param("FS_GCS_ENABLE") == 1.0
        assert v.preflight.companion_failsafe is not None
        assert "returns (RTL)" in v.preflight.companion_failsafe.summary


async def test_a_failsafe_the_autopilot_will_not_take_refuses_arming_by_name() -> None:
    locked = Faults(locked_params=frozenset({"FS_GCS_ENABLE"}))
    async with emulated(1, personality="ardupilot", faults=[locked]) as (host, [v]):
        assert v.refused is not None
        assert "FS_GCS_ENABLE stays 0 after setting 5" in v.refused
        with pytest.raises(VehicleError, match="refusing to arm: companion-loss failsafe"):
            await v.arm()
        assert not any(r.command == ARM for r in host.vehicles[0].log)


async def test_an_unreadable_failsafe_refuses_arming() -> None:
    async with emulated(1, faults=[Faults(no_params=True)]) as (_host, [v]):
        assert v.refused is not None
        assert "COM_OF_LOSS_T could not be read" in v.refused


def test_the_summary_names_what_the_autopilot_does() -> None:
    d = companion_failsafe.describe
    assert d("ardupilot", {"FS_GCS_ENABLE": 1, "FS_GCS_TIMEOUT": 4}) == (
        "the autopilot returns (RTL) 4 s after the daemon's last heartbeat"
    )
    assert d("px4", {}) == "companion-loss failsafe unknown"


def start_flier(url: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-m", "tests.helpers.flier", url, "5", "1.0"],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip


def wait_flying(proc: subprocess.Popen[str], timeout_s: float) -> None:
    """Read the flier's output until ``flying`` (bounded: a reader thread, not a hang)."""
    import queue
    import threading

    lines: queue.Queue[str] = queue.Queue()
    assert proc.stdout is not None
    out = proc.stdout

    def pump() -> None:
        for x in out:
            lines.put(x)

    threading.Thread(target=pump, daemon=True).start()
    seen: list[str] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            line = lines.get(timeout=0.2)
        except queue.Empty:
            if proc.poll() is not None:
                break
            continue
        seen.append(line)
        if line.strip() == "flying":
            return
    raise AssertionError("the flier did not reach the mission phase:\n" + "".join(seen[-20:]))


def wait(cond: object, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():  # type: ignore[operator]
            return True
        time.sleep(0.02)
    return False


def kill_and_time(proc: subprocess.Popen[str], sig: int, w: Watch, mode: str, bound_s: float):  # type: ignore[no-untyped-def]
    """Send ``sig`` to the flier; seconds until the vehicle left ``mode`` and until disarmed."""
    killed = time.monotonic()
    os.kill(proc.pid, sig)
    try:
        assert wait(lambda: w.first(killed, "mode_left", mode) is not None, bound_s + 2.0), (
            f"still {w.mode} {bound_s + 2:g} s after the daemon got signal {sig}"
        )
        left = w.first(killed, "mode_left", mode)
        after = w.mode
        assert wait(lambda: w.first(killed, "armed", False) is not None, 60.0), (
            f"still armed ({w.mode}, {w.alt_m:.1f} m) 60 s after the failsafe"
        )
        disarmed = w.first(killed, "armed", False)
        return left, after, disarmed
    finally:
        proc.kill()
        proc.wait(timeout=10)


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGSTOP], ids=["SIGKILL", "SIGSTOP"])
@pytest.mark.parametrize(
    ("personality", "flying", "landing"),
    [("ardupilot", "GUIDED", "LAND"), ("px4", "OFFBOARD", "AUTO.LAND")],
)
def test_a_dead_daemon_leaves_a_vehicle_that_lands_and_disarms(
    personality: str, flying: str, landing: str, sig: int
) -> None:
    [port] = free_udp_ports(1)
    with MavWatcher() as watcher:
        opts = EmulatorOptions(
            uavs=1, personality=personality, local_base=0, remote_ports=[port],
            time_scale=4.0, gcs_port=watcher.port,
        )  # fmt: skip
        with ThreadedEmulator(opts):
            proc = start_flier(f"udpin://127.0.0.1:{port}")
            try:
                wait_flying(proc, 60.0)
            except BaseException:
                proc.kill()
                proc.wait(timeout=10)
                raise
            w = watcher.watch(1)
            assert w.mode == flying
            assert w.armed
            left, after, disarmed = kill_and_time(proc, sig, w, flying, 5.0)
    print(f"\n{personality} {signal.Signals(sig).name}: left {flying} after {left:.2f} s "
          f"({after}), disarmed after {disarmed:.2f} s (emulator, time scale 4)")  # fmt: skip
    assert left is not None
    assert left <= 5.0
    assert after == landing
