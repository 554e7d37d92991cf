"""Real ArduCopter SITL instances for ``@pytest.mark.sitl`` tests: a binary the user built
(``AEROWEAVER_SITL=/path/to/arducopter``), each instance in its own working directory and
its own network namespace (SITL's listeners bind 0.0.0.0), joined to this one by a veth
link (``netlab``). Instance *i* is system *i+1*; its SERIAL0 sends MAVLink to the daemon's
port on the host end of its link and SERIAL1 to an independent watcher (``mav_watch``).

Nothing here builds ArduPilot or ships any of it: the binary is the user's.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

from aeroweaver_edge.provision import sitl as provision_sitl
from aeroweaver_edge.vehicle.mavlink.geo import GeoOrigin
from tests.helpers.netlab import NetLab, Segment

ENV = "AEROWEAVER_SITL"
SKIP = (
    f"no SITL binary: set {ENV}=/path/to/arducopter (ArduPilot's own SITL build, "
    "./waf configure --board sitl && ./waf copter: build/sitl/bin/arducopter)"
)
DAEMON_PORT = 14550  # on the host end of each instance's link
EARLY_EXIT_S = 3.0  # an instance that dies this soon after start is reported, not waited on


class SitlError(RuntimeError):
    """One line: what is wrong with the SITL binary or an instance."""


def binary_from_env() -> Path | None:
    value = os.environ.get(ENV, "").strip()
    return Path(value) if value else None


def check_binary(path: Path) -> Path:
    """The binary, checked as a user's input: exists, is a file, is executable."""
    if not path.exists():
        raise SitlError(f"{ENV}={path}: no such file")
    if path.is_dir():
        raise SitlError(f"{ENV}={path}: is a directory, not the arducopter binary")
    if not os.access(path, os.X_OK):
        raise SitlError(f"{ENV}={path}: not executable (chmod +x, or point at build/sitl/bin)")
    return path.resolve()


@dataclass
class SitlInstance:
    index: int
    workdir: Path
    segment: Segment
    proc: subprocess.Popen[bytes]
    log: Path

    @property
    def sysid(self) -> int:
        return self.index + 1

    @property
    def daemon_url(self) -> str:
        """Where the daemon listens: the host end of this instance's link."""
        return f"udpin://{self.segment.host_ip}:{DAEMON_PORT}"

    def tail(self, n: int = 5) -> str:
        try:
            lines = self.log.read_text(errors="replace").splitlines()
        except OSError:
            return ""
        return " | ".join(lines[-n:])


@dataclass
class SitlFleet:
    """N instances; ``close`` stops every one and removes every namespace."""

    binary: Path
    root: Path
    watch_port: int | None = None  # SERIAL1 of every instance goes to host_ip:watch_port
    speedup: float = 1.0
    params: dict[str, float] = field(default_factory=dict)
    lab: NetLab = field(default_factory=NetLab)
    instances: list[SitlInstance] = field(default_factory=list)

    def start(self, n: int) -> list[SitlInstance]:
        try:
            for i in range(n):
                self.instances.append(self._start_one(i))
            self._check_alive()
        except BaseException:
            self.close()
            raise
        return self.instances

    def _start_one(self, i: int) -> SitlInstance:
        seg = self.lab.veth()
        workdir = self.root / f"sitl{i}"
        workdir.mkdir(parents=True, exist_ok=True)
        parm = workdir / provision_sitl.PARAMS_FILE
        values = {**provision_sitl.PARAMS, **self.params}
        parm.write_text("".join(f"{k} {v:g}\n" for k, v in values.items()))
        serial1 = None if self.watch_port is None else f"{seg.host_ip}:{self.watch_port}"
        argv = provision_sitl.command(
            i, f"{seg.host_ip}:{DAEMON_PORT}", binary=str(self.binary), defaults=str(parm),
            speedup=self.speedup, serial1=serial1, instance=0,
        )  # fmt: skip
        cmd = [*seg.prefix(), *argv]
        log = workdir / "sitl.log"
        with log.open("wb") as fh:
            proc = subprocess.Popen(
                cmd, cwd=workdir, stdin=subprocess.DEVNULL, stdout=fh, stderr=subprocess.STDOUT,
                start_new_session=True,
            )  # fmt: skip
        return SitlInstance(i, workdir, seg, proc, log)

    def _check_alive(self) -> None:
        """An instance that exits at once is named with its last output, no waiting on it."""
        deadline = time.monotonic() + EARLY_EXIT_S
        while time.monotonic() < deadline:
            for inst in self.instances:
                code = inst.proc.poll()
                if code is not None:
                    raise SitlError(
                        f"{ENV}={self.binary}: SITL instance {inst.index} exited at once "
                        f"(status {code}): {inst.tail() or 'no output'}"
                    )
            time.sleep(0.1)

    def close(self) -> None:
        for inst in self.instances:
            stop(inst.proc)
        self.instances.clear()
        self.lab.close()

    def __enter__(self) -> SitlFleet:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def stop(proc: subprocess.Popen[bytes]) -> None:
    """SIGTERM the instance's process group, then SIGKILL: nothing is left running."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(timeout=5)
    with contextlib.suppress(ProcessLookupError):  # whatever of its group outlived it
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=5)


def unavailable() -> str | None:
    """Why SITL tests cannot run here (None: they can)."""
    if binary_from_env() is None:
        return SKIP
    why = NetLab.unavailable()
    if why is not None:
        return f"SITL instances run in network namespaces: {why}"
    if shutil.which("ip") is None:  # pragma: no cover - NetLab says so first
        return "the ip command (iproute2) is not installed"
    return None


def distance_m(a: GeoOrigin, lat: float, lon: float) -> float:
    n, e, _ = a.to_local(lat, lon, a.alt_m)
    return math.hypot(n, e)
