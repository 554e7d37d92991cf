"""Start and stop a swarm's daemons: as tasks in this event loop or as OS processes.

A process is started with ``aeroweaver daemon --config <json>`` through ``spawn``-style
``asyncio.create_subprocess_exec`` (never fork after a Zenoh session). Its peak resident
memory (``VmHWM``) can be read while it runs, for the scale benchmark.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import sys
from collections.abc import Awaitable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from aeroweaver_edge.agent import choices
from aeroweaver_edge.config import UavConfig
from aeroweaver_edge.runtime.run_dir import ENV_DIR, ENV_PARENT, LOCK_NAME

if TYPE_CHECKING:
    from aeroweaver_edge.skills import SkillRegistry

T = TypeVar("T")
FAILURE_POLL_S = 0.1


class DaemonsFailed(RuntimeError):
    """Daemons ended while the run was waiting for them; the message is one line per
    daemon: its exit status (or exception type) and the last line it wrote."""

    def __init__(self, failed: dict[str, str]) -> None:
        self.failed = failed
        parts = []
        for uav, why in sorted(failed.items()):
            head, _, rest = why.partition(": ")
            lines = [ln.strip() for ln in rest.splitlines() if ln.strip()]
            parts.append(f"{uav} ({head}): {lines[-1] if lines else rest.strip()}")
        super().__init__("; ".join(parts))


def peak_rss_kb(pid: int) -> int | None:
    """``VmHWM`` of a live process in kB (Linux), or None if it cannot be read."""
    try:
        text = Path(f"/proc/{pid}/status").read_text(encoding="ascii", errors="replace")
    except OSError:
        return None
    for line in text.splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    return None


class DaemonSet:
    """The daemons of one run; in-process tasks share one skill registry."""

    def __init__(self, configs: list[UavConfig], processes: bool, workdir: Path) -> None:
        self.configs = configs
        self.processes = processes
        self.workdir = workdir
        self.tasks: dict[str, asyncio.Task[Any]] = {}
        self.procs: dict[str, asyncio.subprocess.Process] = {}
        self.killed: set[str] = set()  # by fault injection: lost on purpose, not failed
        self._registry: SkillRegistry | None = None

    async def start(self) -> None:
        if not self.processes:
            from aeroweaver_edge.skills import load_skills

            self._registry = load_skills()
            for cfg in self.configs:
                self._start_task(cfg)
            return
        for cfg in self.configs:
            path = self.workdir / f"{cfg.uav}.json"
            path.write_text(cfg.model_dump_json(indent=2), encoding="utf-8")
            self.procs[cfg.uav] = await self._spawn(cfg.uav, "wb")

    def _start_task(self, cfg: UavConfig) -> None:
        from aeroweaver_edge.daemon.app import run_daemon

        self.tasks[cfg.uav] = asyncio.create_task(
            run_daemon(cfg, registry=self._registry), name=cfg.uav
        )

    async def _spawn(self, uav: str, log_mode: str) -> asyncio.subprocess.Process:
        """``aeroweaver daemon`` for ``uav``: it dies with this process (Linux), and it holds
        the run directory's lock while it runs (``run_dir``), so it is never left behind."""
        env = {**os.environ, ENV_PARENT: str(os.getpid())}
        for name in choices.ENV.values():  # the run resolved them into the config it wrote
            env.pop(name, None)
        if (self.workdir / LOCK_NAME).exists():
            env[ENV_DIR] = str(self.workdir)
        log = (self.workdir / f"{uav}.log").open(log_mode)  # the child inherits it
        try:
            return await asyncio.create_subprocess_exec(
                sys.executable,
                "-m",
                "aeroweaver_edge",
                "daemon",
                "--config",
                str(self.workdir / f"{uav}.json"),
                stdin=asyncio.subprocess.DEVNULL,
                stdout=log,
                stderr=log,
                env=env,
            )
        finally:
            log.close()

    def peak_rss_kb(self) -> dict[str, int]:
        """Peak resident memory of every daemon process still running (processes mode)."""
        out: dict[str, int] = {}
        for uav, p in self.procs.items():
            kb = peak_rss_kb(p.pid) if p.returncode is None else None
            if kb is not None:
                out[uav] = kb
        return out

    async def kill(self, uav: str) -> None:
        """Fault injection: the daemon dies abruptly (process SIGKILL, or task cancelled)."""
        self.killed.add(uav)
        if uav in self.procs:
            proc = self.procs[uav]
            if proc.returncode is None:
                proc.kill()
            await proc.wait()
        elif uav in self.tasks:
            self.tasks[uav].cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self.tasks[uav]

    async def restart(self, uav: str) -> None:
        """Fault injection: start a killed daemon again from its config; it rejoins the
        swarm (the world flies its body again once its token is back)."""
        if uav not in self.killed:
            raise RuntimeError(f"{uav} is running; kill it before restarting it")
        if self.processes:
            self.procs[uav] = await self._spawn(uav, "ab")  # its log keeps every life
        else:
            self._start_task(next(c for c in self.configs if c.uav == uav))
        self.killed.discard(uav)

    def failed(self) -> dict[str, str]:
        """Daemons that ended before the run did, with the reason."""
        out: dict[str, str] = {}
        for uav, t in self.tasks.items():
            if uav not in self.killed and t.done() and not t.cancelled() and t.exception():
                out[uav] = f"{type(t.exception()).__name__}: {t.exception()}"
        for uav, p in self.procs.items():
            if uav not in self.killed and p.returncode not in (None, 0):
                tail = (self.workdir / f"{uav}.log").read_text(errors="replace")[-4000:]
                # The CLI's one-line error, not the INFO lines a daemon logs as it goes.
                why = [ln for ln in tail.splitlines() if ln.startswith("aeroweaver:")]
                out[uav] = f"exit {p.returncode}" + (f": {why[-1]}" if why else "")
        return out

    async def unless_one_fails(self, aw: Awaitable[T]) -> T:
        """``aw``'s result, or DaemonsFailed as soon as a daemon has failed: a daemon that
        exits at start-up (a bad memory path, a full disk) is reported within
        ``FAILURE_POLL_S`` of its exit, not after the whole start-up wait."""
        task = asyncio.ensure_future(aw)
        try:
            while not task.done():
                failed = self.failed()
                if failed:
                    raise DaemonsFailed(failed)
                await asyncio.wait({task}, timeout=FAILURE_POLL_S)
            return task.result()
        finally:
            if not task.done():
                task.cancel()
                await asyncio.gather(task, return_exceptions=True)

    def terminate(self) -> None:
        """Ask every daemon still running to stop now (SIGTERM: it holds, closes its
        session, exits 0; a task is cancelled), so that ``stop`` does not wait its whole
        timeout for daemons nobody will ever give a mission (a failed start-up)."""
        for p in self.procs.values():
            if p.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    p.terminate()
        for t in self.tasks.values():
            t.cancel()

    async def stop(self, timeout_s: float = 15.0) -> None:
        waits = [*self.tasks.values()]
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                await asyncio.gather(
                    *waits, *(p.wait() for p in self.procs.values()), return_exceptions=True
                )
        for t in self.tasks.values():
            t.cancel()
        await asyncio.gather(*self.tasks.values(), return_exceptions=True)
        for p in self.procs.values():
            if p.returncode is None:
                p.kill()
                await p.wait()


__all__ = ["DaemonSet", "DaemonsFailed", "peak_rss_kb"]
