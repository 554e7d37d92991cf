"""The emulator held to recorded firmware behaviour, in CI, without SITL.

``tests/fixtures/sitl/*.json`` were recorded from real ArduCopter SITL
(``python -m tests.helpers.record_sitl``, docs/flight.md); each case here flies the same
MAVLink commands against the emulator's ArduPilot personality and compares what a client
can rely on: the modes and armed states the HEARTBEAT shows, every COMMAND_ACK, the landed
states, the STATUSTEXT lines that matter (arming, failsafes, fence), the case's own checks,
and the firmware timers' bounds. ``KNOWN`` lists each aspect where the emulator still
differs, with why; anything else that differs fails, and so does a known difference that
has gone away (update the table in docs/flight.md).
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest

from aeroweaver_edge.sim.emulator.host import EmulatorHost, EmulatorOptions
from tests.helpers import fidelity
from tests.helpers.mav import free_udp_ports

TIME_SCALE = 4.0  # climbs and descents 4x faster; the firmware timers are not scaled
PREARM_S = 1.5  # the emulator's EKF/GPS warm-up for the first case
# (case, first mark, second mark, tolerance s): spans set by firmware timers, comparable
SPANS = {
    "companion_loss_lands": ("silenced", "failsafe_mode", 1.2),  # FS_GCS_TIMEOUT 3 s
    "velocity_target_expires": ("stream_stopped", "stopped", 1.5),  # GUID_TIMEOUT 3 s
}
CHECKS = (
    "mode_after_stop", "mode_after_hold", "held_within_1m", "landed_near_home",
    "velocity_stopped_inside", "target_beyond_ignored", "mode_after_push",
)  # fmt: skip
KNOWN: dict[tuple[str, str], str] = {
    ("arm_refused_before_ekf", "texts"): (
        "ArduCopter names every check failing at that instant (1 s after boot: 4 of them; "
        "20 s: 'Arm: Gyros inconsistent'); the emulator names one, 'Arm: AHRS: waiting for "
        "home', which SITL sends too"
    ),
    ("arm_refused_before_ekf", "landed"): (
        "1 s after boot SITL had not yet started the EXTENDED_SYS_STATE stream it was asked "
        "for; the emulator answers at once (ON_GROUND)"
    ),
}


def aspects(trace: fidelity.Trace) -> dict[str, Any]:
    out: dict[str, Any] = {
        "modes": trace.values("mode"),
        "armed": trace.values("armed"),
        "acks": trace.values("ack"),
        "landed": trace.values("landed"),
        "texts": sorted({t for t in trace.values("text") if fidelity.TEXT_KEEP.search(t)}),
        "checks": [(k, v) for _t, k, v in trace.events if k in CHECKS],
    }
    span = SPANS.get(trace.case)
    if span is not None:
        a, b, _tol = span
        out["timing"] = round(trace.marks[b] - trace.marks[a], 2)
    return out


def same(aspect: str, case: str, sitl: Any, emu: Any) -> bool:
    if aspect == "timing":
        return bool(abs(sitl - emu) <= SPANS[case][2])
    return bool(sitl == emu)


async def fly_emulated(case: str) -> fidelity.Trace:
    [port] = free_udp_ports(1)
    opts = EmulatorOptions(
        uavs=1, personality="ardupilot", local_base=0, remote_ports=[port],
        time_scale=TIME_SCALE, prearm_s=PREARM_S if case == "arm_refused_before_ekf" else 0.0,
    )  # fmt: skip
    host = EmulatorHost(opts)
    await host.start()
    try:
        async with asyncio.timeout(120):
            [trace] = await fidelity.fly_cases(f"udpin://127.0.0.1:{port}", "emulator", [case])
    finally:
        await host.aclose()
    return trace


def compare(case: str, sitl: fidelity.Trace, emu: fidelity.Trace) -> list[tuple[str, bool]]:
    a, b = aspects(sitl), aspects(emu)
    return [(k, same(k, case, a[k], b[k])) for k in a]


@pytest.mark.parametrize("case", list(fidelity.CASES))
async def test_the_emulator_matches_recorded_arducopter(case: str) -> None:
    recorded = fidelity.load(case)
    assert recorded.target == "sitl"
    emulated = await fly_emulated(case)
    a, b = aspects(recorded), aspects(emulated)
    problems = []
    for aspect, ok in compare(case, recorded, emulated):
        known = KNOWN.get((case, aspect))
        if not ok and known is None:
            problems.append(f"{aspect}: SITL {a[aspect]!r} != emulator {b[aspect]!r}")
        if ok and known is not None:
            problems.append(f"{aspect} now matches: drop it from KNOWN ({known})")
    assert not problems, "\n".join(problems)


def test_every_case_has_a_recording() -> None:
    recorded = {p.stem for p in Path(fidelity.FIXTURES).glob("*.json")}
    assert recorded == set(fidelity.CASES)
