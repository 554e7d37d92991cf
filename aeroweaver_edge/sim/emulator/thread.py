"""Run an emulator on its own thread and event loop.

Benchmarks and stall tests need the vehicle to keep ticking while the daemon's loop is
busy or blocked, as a real autopilot would."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Sequence

from aeroweaver_edge.sim.emulator.autopilot import Faults
from aeroweaver_edge.sim.emulator.host import EmulatorHost, EmulatorOptions


class ThreadedEmulator:
    def __init__(self, opts: EmulatorOptions, faults: Sequence[Faults] | None = None) -> None:
        self.opts = opts
        self._faults = faults
        self.host: EmulatorHost | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=self._main, name="emulator", daemon=True)

    def _main(self) -> None:
        async def run() -> None:
            self._loop = asyncio.get_running_loop()
            self._stop = asyncio.Event()
            self.host = EmulatorHost(self.opts, faults=self._faults)
            try:
                await self.host.start()
            except BaseException as exc:
                self._error = exc
                self._ready.set()
                return
            self._ready.set()
            try:
                await self._stop.wait()
            finally:
                await self.host.aclose()

        asyncio.run(run())

    def __enter__(self) -> EmulatorHost:
        self._thread.start()
        if not self._ready.wait(10):
            raise RuntimeError("emulator thread did not start")
        if self._error is not None:
            raise self._error
        assert self.host is not None
        return self.host

    def __exit__(self, *exc: object) -> None:
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(10)
