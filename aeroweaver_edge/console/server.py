"""Run the console: uvicorn on this event loop, next to the mesh observer (or a replay).

``Console`` is an async context manager: it binds the HTTP port (a taken port is one clear
error), serves until closed, and closes the mesh session it opened. Signals stay with the
caller (the CLI's handler cancels the run; uvicorn's own handlers are not installed).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Generator
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Self

import uvicorn

from aeroweaver_edge.config import MeshConfig
from aeroweaver_edge.console.app import ConsoleApp
from aeroweaver_edge.console.frames import FrameStore, load_trace
from aeroweaver_edge.console.observer import SwarmObserver
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.mesh.session import Mesh
from aeroweaver_edge.runtime.lifecycle import cancel_all
from aeroweaver_edge.safety.operator import OPERATOR, OperatorLink

if TYPE_CHECKING:
    from aeroweaver_edge.orchestration.swarm import RunSummary, SwarmHandle, SwarmOptions
    from aeroweaver_edge.orchestration.view import LiveView

log = logging.getLogger(__name__)
DEFAULT_PORT = 8765


class _Server(uvicorn.Server):
    """uvicorn without its signal handlers: the embedding program owns SIGINT/SIGTERM."""

    @contextlib.contextmanager
    def capture_signals(self) -> Generator[None, None, None]:
        yield


def bind(host: str, port: int) -> socket.socket:
    """The listening socket, or a UserError naming the address (port 0: any free one)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(64)
    except OSError as exc:
        sock.close()
        raise UserError(
            f"console: cannot listen on {host}:{port}: {exc.strerror or exc}",
            "choose another --console-port / --port (0: any free port)",
        ) from None
    sock.setblocking(False)
    return sock


class Console:
    """The web console for one swarm (``connect``) or one finished run (``replay``)."""

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT) -> None:
        self.host = host
        self.port = port
        self.store = FrameStore()
        self.app: ConsoleApp | None = None
        self._sock: socket.socket | None = None
        self._server: _Server | None = None
        self._tasks: list[asyncio.Task[Any]] = []
        self._mesh: Mesh | None = None
        self._observer: SwarmObserver | None = None
        self._operator: OperatorLink | None = None
        self._read_only = "not connected to a swarm"

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    # -- sources --------------------------------------------------------------------------

    async def connect(self, mesh_cfg: MeshConfig, swarm: str, *, act: bool = True) -> None:
        """Join ``swarm`` as an observer; with ``act`` and an operator identity (or a
        plain loopback mesh) the page may also stop the mission and approve actions."""
        identity = mesh_cfg.security.identity if mesh_cfg.security is not None else "console"
        self._mesh = await Mesh.open(mesh_cfg, node_id=identity)
        role = _role_of(self._mesh)
        if act and role in (None, "operator"):
            self._operator = OperatorLink(self._mesh, swarm, identity=OPERATOR)
            self._read_only = ""
        else:
            self._read_only = (
                f"identity {identity!r} has the {role} role" if act else "read-only by choice"
            )
        self._observer = SwarmObserver(self._mesh, swarm, self.store)
        await self._observer.start()
        if self.app is not None:
            self.app.operator, self.app.read_only = self._operator, self._read_only

    async def disconnect(self) -> None:
        """Leave the swarm (the page keeps its frames; actions become unavailable)."""
        if self._observer is not None:
            await self._observer.aclose()
            self._observer = None
        if self._mesh is not None:
            await self._mesh.aclose()
            self._mesh = None
        self._operator = None
        self._read_only = "the run has ended"
        if self.app is not None:
            self.app.operator, self.app.read_only = None, self._read_only
        self.store.update_meta(ended=True)

    def replay(self, path: Path) -> None:
        """Serve a finished run from its trace (docs/traces.md); TraceError if unusable."""
        header, frames = load_trace(path)
        for frame in frames:
            self.store.add_frame(frame)
        mission = header.get("mission") or {}
        assignments = mission.get("assignments") or {}
        self.store.update_meta(
            mode="replay",
            trace=str(path),
            task=header.get("task"),
            seed=header.get("seed"),
            selector=header.get("selector"),
            note=header.get("note"),
            arena_half_m=header.get("arena_half_m"),
            comm_radius_m=header.get("comm_radius_m"),
            sensing_radius_m=header.get("sensing_radius_m"),
            round_s=header.get("round_s"),
            roles=header.get("roles") or {},
            goals={u: a.get("local_goal", "") for u, a in assignments.items()},
            skills={u: a.get("skills", []) for u, a in assignments.items()},
            mission={"id": mission.get("mission_id"), "task": header.get("task"),
                     "text": mission.get("text", ""), "state": "replay"},
        )  # fmt: skip
        self._read_only = "a replay"

    # -- serving --------------------------------------------------------------------------

    async def __aenter__(self) -> Self:
        self._sock = bind(self.host, self.port)
        self.port = int(self._sock.getsockname()[1])
        self.app = ConsoleApp(
            self.store, operator=self._operator, read_only=self._read_only,
            allowed_hosts=["127.0.0.1", "localhost", "::1", self.host],
        )  # fmt: skip
        config = uvicorn.Config(
            self.app.starlette(), log_level="warning", lifespan="off",
            timeout_graceful_shutdown=1, access_log=False,
        )  # fmt: skip
        self._server = _Server(config)
        self._tasks.append(
            asyncio.create_task(self._server.serve(sockets=[self._sock]), name="console-http")
        )
        while not self._server.started:
            if self._tasks[0].done():
                self._tasks[0].result()  # raises what stopped it
                raise UserError(f"console: the web server on {self.url} stopped at start-up")
            await asyncio.sleep(0.01)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.aclose()

    async def aclose(self) -> None:
        self.store.close()  # ends every event stream
        if self._server is not None:
            self._server.should_exit = True
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(3.0):
                    await asyncio.gather(*self._tasks, return_exceptions=True)
        await cancel_all(self._tasks)
        await self.disconnect()
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    async def serve_forever(self) -> None:
        """Until cancelled (Ctrl-C) or the web server stops."""
        await asyncio.gather(*self._tasks)


def _role_of(mesh: Mesh) -> str | None:
    """The mesh identity's role when secured (None: a plain loopback mesh)."""
    sec = mesh.security
    return None if sec is None else sec.role.value


async def with_console(
    opts: SwarmOptions, host: str, port: int, view: LiveView | None = None
) -> RunSummary:
    """``aeroweaver sim --console``: the run, with the console joined to its mesh (as the
    operator: the page can stop the mission and approve vehicle actions) before round one."""
    from aeroweaver_edge.orchestration.swarm import run_swarm

    async with Console(host, port) as console:
        print(f"console: {console.url}", flush=True)

        async def started(handle: SwarmHandle) -> None:
            await console.connect(handle.mesh_for(OPERATOR), handle.swarm)

        try:
            return await run_swarm(
                opts, on_round=view.on_round if view else None, on_started=started
            )
        finally:
            await console.disconnect()


__all__ = ["DEFAULT_PORT", "Console", "bind", "with_console"]
