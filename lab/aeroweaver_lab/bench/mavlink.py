"""``aeroweaver bench mavlink``: what the MAVLink link achieves on this machine.

An emulated PX4 runs on its own thread (as a real autopilot would run elsewhere); the
daemon's ``mavlink`` backend connects over loopback UDP and we measure:

* command round trip: COMMAND_LONG out to COMMAND_ACK back (first tries only), p50/p99;
* the setpoint stream: rate and largest gap *as received by the autopilot* while flying
  offboard, against the configured rate (the autopilot's offboard-loss timer sees gaps);
* connect time (heartbeat discovery, telemetry, failsafe params, fence upload).

Figures from a shared, loaded machine are rough; re-run idle to compare.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import statistics
import sys
import time
from collections.abc import Sequence
from typing import Any

from aeroweaver_edge.config import SafetyConfig, VehicleConfig
from aeroweaver_edge.sim.emulator.host import EmulatorOptions
from aeroweaver_edge.sim.emulator.thread import ThreadedEmulator
from aeroweaver_edge.vehicle.mavlink.backend import MavlinkVehicle
from aeroweaver_edge.vehicle.mavlink.codec import mavlink


def _pct(xs: list[float], q: float) -> float:
    ys = sorted(xs)
    return ys[min(len(ys) - 1, round(q * (len(ys) - 1)))]


async def _bench(args: argparse.Namespace) -> dict[str, Any]:
    cfg = VehicleConfig(
        backend="mavlink", url="udpin://127.0.0.1:0", setpoint_hz=args.rate,
        lease_s=max(2.0, args.seconds + 1),
    )  # fmt: skip
    v = MavlinkVehicle(cfg, SafetyConfig(), "bench")
    await v.link.open()  # bind first, then tell the emulator where we listen
    opts = EmulatorOptions(uavs=1, local_base=0, remote_ports=[v.link.local_port], time_scale=4.0)
    try:
        with ThreadedEmulator(opts) as host:
            ap = host.vehicles[0]
            t0 = time.monotonic()
            await v.start()
            connect_s = time.monotonic() - t0
            v.commands.stats.rtt_s.clear()
            for _ in range(args.commands):
                await v.commands.send(
                    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                    float(mavlink.MAVLINK_MSG_ID_HOME_POSITION), 1_000_000.0,
                )  # fmt: skip
            rtt = list(v.commands.stats.rtt_s)
            await v.arm()
            await v.takeoff(5.0)
            await v.wait_until(lambda: v.in_air and v.mode_role == "hold", 30.0, "take-off")
            await v.set_velocity(1.0, 0.0, 0.0)
            n0, t1 = ap.setpoints, time.monotonic()
            arrivals: list[float] = []
            last = n0
            while time.monotonic() - t1 < args.seconds:
                await asyncio.sleep(0.001)
                if ap.setpoints != last:
                    arrivals.append(time.monotonic())
                    last = ap.setpoints
            received = ap.setpoints - n0
            elapsed = time.monotonic() - t1
            gaps = [b - a for a, b in itertools.pairwise(arrivals)]
            await v.land()
    finally:
        await v.aclose()
    return {
        "connect_s": round(connect_s, 3),
        "command_rtt_ms": {
            "n": len(rtt),
            "p50": round(statistics.median(rtt) * 1e3, 3),
            "p99": round(_pct(rtt, 0.99) * 1e3, 3),
            "max": round(max(rtt) * 1e3, 3),
        },
        "setpoints": {
            "configured_hz": args.rate,
            "received_hz": round(received / elapsed, 2),
            "max_gap_ms": round(max(gaps) * 1e3, 1) if gaps else None,
            "seconds": round(elapsed, 2),
        },
        "note": "emulated PX4 on a thread of the same process, loopback UDP; "
        "figures from a shared machine are rough",
    }


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="aeroweaver bench mavlink", description=__doc__)
    p.add_argument("--seconds", type=float, default=5.0, help="offboard streaming time")
    p.add_argument("--rate", type=float, default=20.0, help="setpoint rate, Hz (10-100)")
    p.add_argument("--commands", type=int, default=200, help="acked commands to time")
    p.add_argument("--json", metavar="PATH", help="also write the figures as JSON")
    args = p.parse_args(argv)
    if not 10 <= args.rate <= 100 or args.seconds <= 0 or args.commands < 1:
        print("aeroweaver bench mavlink: need 10 <= --rate <= 100, --seconds > 0, --commands >= 1",
              file=sys.stderr)  # fmt: skip
        return 2
    out = asyncio.run(_bench(args))
    rtt, sp = out["command_rtt_ms"], out["setpoints"]
    print(f"connect (discovery, telemetry, failsafe params, fence): {out['connect_s']:.3f} s")
    print(
        f"command round trip (COMMAND_LONG -> COMMAND_ACK, n={rtt['n']}): "
        f"p50 {rtt['p50']:.3f} ms, p99 {rtt['p99']:.3f} ms, max {rtt['max']:.3f} ms"
    )
    print(
        f"setpoint stream: {sp['received_hz']:.2f} Hz received by the autopilot "
        f"(configured {sp['configured_hz']:g} Hz), largest gap {sp['max_gap_ms']} ms "
        f"over {sp['seconds']} s"
    )
    print(f"note: {out['note']}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(out, f, indent=2)
            f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
