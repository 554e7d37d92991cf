"""``aeroweaver emulator``: emulated autopilots on UDP for a daemon, QGroundControl or MAVProxy.

Vehicle i is system id i+1; it sends to HOST:port_base+i (where ``aeroweaver daemon`` with
``url = "udpin://0.0.0.0:<port_base+i>"`` listens) from local port local_base+i, and
answers anyone who talks to it there (``udpout://HOST:<local_base+i>``, MAVProxy
``--master udpout:...``). ``--gcs-port 14550`` also sends to QGroundControl.
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import sys
from pathlib import Path

from aeroweaver_edge.sim.emulator.autopilot import Faults
from aeroweaver_edge.sim.emulator.host import EmulatorHost, EmulatorOptions


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    e = sub.add_parser("emulator", help="run emulated PX4/ArduPilot autopilots on UDP")
    e.add_argument("--uavs", type=int, default=1)
    e.add_argument("--personality", choices=["px4", "ardupilot"], default="px4")
    e.add_argument("--port-base", type=int, default=14540, help="vehicle i sends to this + i")
    e.add_argument("--local-base", type=int, default=None,
                   help="vehicle i listens on this + i (default port-base + 40)")  # fmt: skip
    e.add_argument("--host", default="127.0.0.1", help="address to bind and send to")
    e.add_argument("--gcs-port", type=int, default=None, help="also send to HOST:PORT (QGC: 14550)")
    e.add_argument("--time-scale", type=float, default=1.0, help="speed of the physics")
    e.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="override an autopilot parameter, e.g. COM_OBL_RC_ACT=0")  # fmt: skip
    e.add_argument("--signing-key-dir", metavar="DIR",
                   help="require MAVLink 2 signing with DIR/uav<i>.key per vehicle")  # fmt: skip
    e.add_argument("--drop", type=float, default=0.0, help="percent of datagrams lost each way")
    e.add_argument("--status-every", type=float, default=5.0, help="seconds; 0: quiet")
    e.set_defaults(func=cmd_emulator)


def _options(args: argparse.Namespace) -> tuple[EmulatorOptions, list[Faults]]:
    params: dict[str, float] = {}
    for item in args.param:
        name, sep, value = item.partition("=")
        try:
            params[name.strip()] = float(value)
        except ValueError:
            sep = ""
        if not sep or not name.strip():
            raise ValueError(f"--param {item!r}: expected NAME=NUMBER")
    if not 0 <= args.drop < 100:
        raise ValueError(f"--drop {args.drop}: expected a percentage in [0, 100)")
    keys: list[bytes | None] = []
    if args.signing_key_dir:
        from aeroweaver_edge.vehicle.mavlink.signing import load_key

        keys = [load_key(Path(args.signing_key_dir) / f"uav{i}.key") for i in range(args.uavs)]
    opts = EmulatorOptions(
        uavs=args.uavs, personality=args.personality, port_base=args.port_base,
        local_base=args.local_base, host=args.host, gcs_port=args.gcs_port,
        time_scale=args.time_scale, params=params, signing_keys=keys,
    )  # fmt: skip
    drop = args.drop / 100.0
    return opts, [Faults(drop_rx=drop, drop_tx=drop) for _ in range(args.uavs)]


async def _serve(opts: EmulatorOptions, faults: list[Faults], status_every: float) -> None:
    host = EmulatorHost(opts, faults=faults)
    try:
        await host.start()
    except OSError as exc:
        raise ValueError(f"cannot bind the emulator's UDP ports: {exc.strerror or exc}") from None
    try:
        for i, v in enumerate(host.vehicles):
            print(
                f"{v.uav}: system {v.sysid} ({opts.personality}) listens on "
                f"{opts.host}:{host.local_port(i)}, sends to "
                + ", ".join(f"{h}:{p}" for h, p in host._fixed[i])
                + (" (signing required)" if opts.signing_keys else ""),
                flush=True,
            )
        while True:
            await asyncio.sleep(status_every if status_every > 0 else 3600)
            if status_every > 0:
                for v in host.vehicles:
                    b = host.world.body(v.uav)
                    print(
                        f"{v.uav}: {v.mode:<12} {'armed' if v.armed else 'disarmed':8} "
                        f"alt {v.alt:5.1f} m  N {b.north:7.1f} E {b.east:7.1f}  "
                        f"commands {len(v.log)} setpoints {v.setpoints}",
                        flush=True,
                    )
    finally:
        await host.aclose()


def cmd_emulator(args: argparse.Namespace) -> int:
    from aeroweaver_edge.runtime.signals import Stopped
    from aeroweaver_edge.runtime.signals import run_until_signal as _run

    try:
        opts, faults = _options(args)
    except ValueError as exc:
        print(f"aeroweaver emulator: {exc}", file=sys.stderr)
        return 2
    try:
        _run(_serve(opts, faults, args.status_every))
    except ValueError as exc:
        print(f"aeroweaver emulator: {exc}", file=sys.stderr)
        return 2
    except Stopped as stop:  # a service's normal end: SIGTERM is 0, Ctrl-C 130
        return 0 if stop.signum == signal.SIGTERM else 130
    except (KeyboardInterrupt, asyncio.CancelledError):
        return 130
    return 0
