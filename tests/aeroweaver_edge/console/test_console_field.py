"""The console on a field swarm, in a real browser: no simulated world, every part a real
process. ``aeroweaver emulator --uavs 3`` (real MAVLink bytes over loopback UDP), a plain
loopback router (``aeroweaver router --insecure``), three ``aeroweaver daemon``s with the
``mavlink`` backend, ``aeroweaver console`` and ``aeroweaver mission start`` (the Commander,
no ``--sim-world``). The page must show three UAV rows with the flight mode, armed and
altitude the vehicles report, markers that move, the landmarks the daemons know with their
coverage, and, once the mission is over, the ENDED badge with the stop button disabled and
a replay of what it saw; when the console process stops, the page keeps its frames."""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import signal
import socket
import sys
from collections.abc import AsyncIterator
from pathlib import Path
from typing import IO, Any

import pytest

from tests.aeroweaver_edge.console.test_console_browser import CHROMIUM, FLAGS, browser_or_skip
from tests.helpers.zenoh_net import free_port

pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]

SWARM = "fieldview"
MISSION = "Cover the three landmarks with three drones"
POINTS = """points = [
  { id = "L0", kind = "landmark", north = 12.0, east = 8.0 },
  { id = "L1", kind = "landmark", north = -6.0, east = 20.0 },
  { id = "L2", kind = "landmark", north = 18.0, east = -10.0 },
]
"""


def udp_base(n: int) -> int:
    """A port base P with P..P+n-1 and P+40..P+40+n-1 free (the emulator's send/listen)."""
    for _ in range(200):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            base = int(s.getsockname()[1])
        if base + 40 + n >= 65535:
            continue
        socks: list[socket.socket] = []
        try:
            for port in [*range(base, base + n), *range(base + 40, base + 40 + n)]:
                t = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(t)
                t.bind(("127.0.0.1", port))
            return base
        except OSError:
            continue
        finally:
            for t in socks:
                t.close()
    raise RuntimeError("no free UDP port range")


def daemon_toml(i: int, router: int, udp: int) -> str:
    return (
        f'uav = "uav{i}"\nswarm = "{SWARM}"\nround_s = 0.5\n'
        f'[mesh]\nlisten = ["tcp/127.0.0.1:0"]\nconnect = ["tcp/127.0.0.1:{router}"]\n'
        '[agent]\nselector = "scripted"\nbeta = 0.0\n'
        f'[vehicle]\nbackend = "mavlink"\nurl = "udpin://127.0.0.1:{udp + i}"\n'
        'altitude_m = 5.0\nfailsafe_policy = "refuse"\nend_action = "land"\n'
        f"[field]\n{POINTS}"
    )


class Procs:
    """The test's processes: each logs to a file; all are stopped (SIGTERM, then SIGKILL)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.procs: dict[str, asyncio.subprocess.Process] = {}
        self._logs: list[IO[bytes]] = []

    async def start(self, name: str, *args: str) -> asyncio.subprocess.Process:
        out = (self.root / f"{name}.out").open("wb")
        self._logs.append(out)
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "aeroweaver_edge", *args,
            stdout=out, stderr=asyncio.subprocess.STDOUT, env=env, cwd=self.root,
        )  # fmt: skip
        self.procs[name] = proc
        return proc

    def log(self, name: str) -> str:
        return (self.root / f"{name}.out").read_text(errors="replace")

    async def wait_line(self, name: str, pattern: str, timeout_s: float) -> re.Match[str]:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while True:
            m = re.search(pattern, self.log(name))
            if m is not None:
                return m
            proc = self.procs[name]
            if proc.returncode is not None or loop.time() > deadline:
                raise AssertionError(f"{name}: no {pattern!r}; its output:\n{self.log(name)}")
            await asyncio.sleep(0.1)

    async def stop(self, name: str) -> int:
        proc = self.procs[name]
        if proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(signal.SIGTERM)
            try:
                await asyncio.wait_for(proc.wait(), 15)
            except TimeoutError:
                proc.kill()
                await proc.wait()
        return proc.returncode if proc.returncode is not None else -1

    async def aclose(self) -> None:
        for name in reversed(list(self.procs)):
            await self.stop(name)
        for f in self._logs:
            f.close()


@contextlib.asynccontextmanager
async def processes(root: Path) -> AsyncIterator[Procs]:
    procs = Procs(root)
    try:
        yield procs
    finally:
        await procs.aclose()


ROWS_FLYING = """() => {
  const rows = [...document.querySelectorAll('#uavs tbody tr[data-uav]')];
  const text = (r, c) => (r.querySelector('td.' + c) || {}).textContent || '';
  return rows.length === 3 && rows.every((r) => text(r, 'mode') === 'OFFBOARD'
    && text(r, 'armed') === 'armed' && parseFloat(text(r, 'alt')) > 3);
}"""


async def test_the_console_draws_a_field_swarm_of_emulated_vehicles(tmp_path: Path) -> None:
    async_playwright = browser_or_skip()
    router, udp = free_port(), udp_base(3)
    (tmp_path / "router.json5").write_text(
        f'{{ mode: "router", listen: {{ endpoints: ["tcp/127.0.0.1:{router}"] }},\n'
        "  scouting: { multicast: { enabled: false } } }\n",
        encoding="utf-8",
    )
    async with processes(tmp_path) as p:
        await p.start("emulator", "emulator", "--uavs", "3", "--port-base", str(udp),
                      "--time-scale", "4", "--status-every", "0")  # fmt: skip
        await p.start("router", "router", "--config", "router.json5", "--insecure")
        for i in range(3):
            (tmp_path / f"uav{i}.toml").write_text(daemon_toml(i, router, udp), encoding="utf-8")
            await p.start(f"uav{i}", "daemon", "--config", f"uav{i}.toml")
        await p.start("console", "console", "--swarm", SWARM, "--connect",
                      f"tcp/127.0.0.1:{router}", "--port", "0")  # fmt: skip
        url = (await p.wait_line("console", r"console: (http://\S+) ", 60)).group(1)
        async with async_playwright() as pw:
            ctx = await pw.chromium.launch_persistent_context(
                str(tmp_path / "profile"), executable_path=str(CHROMIUM), args=FLAGS,
                headless=True, viewport={"width": 1280, "height": 760},
            )  # fmt: skip
            try:
                page = ctx.pages[0] if ctx.pages else await ctx.new_page()
                errors: list[str] = []
                page.on("pageerror", lambda e: errors.append(str(e)))
                await page.goto(url)
                mission = await p.start(
                    "mission", "mission", "start", MISSION, "--swarm", SWARM,
                    "--connect", f"tcp/127.0.0.1:{router}", "--no-llm", "--rounds", "60",
                    "--roster-wait", "8", "--json", "m1.json",
                )  # fmt: skip
                await page.wait_for_function(
                    "window.__aw.markers.filter(m => m.ours).length === 3", timeout=60_000
                )
                spawn = await page.evaluate(MARKERS)  # on the ground, before the mission
                await page.wait_for_function(ROWS_FLYING, timeout=90_000)
                await check_flying(page, spawn)
                await page.click('#uavs tr[data-uav="uav1"]')  # its last decision, on the side
                await page.wait_for_selector("#decision tr.chosen", timeout=10_000)
                shot = os.environ.get("AEROWEAVER_CONSOLE_FIELD_SCREENSHOT")  # docs/console.png
                await page.screenshot(path=shot or str(tmp_path / "field.png"))
                rc = await asyncio.wait_for(mission.wait(), 120)
                assert rc == 0, p.log("mission")
                await check_ended(page)
                assert await p.stop("console") == 0
                await page.wait_for_function(
                    "document.getElementById('conn').textContent.includes('server stopped')",
                    timeout=15_000,
                )
                assert await page.text_content("#mode") == "ended"
                assert await page.evaluate("window.__aw.frames.length") > 10  # kept
                await page.screenshot(path=str(tmp_path / "ended.png"))
                assert errors == []
            finally:
                await ctx.close()


MARKERS = "Object.fromEntries(window.__aw.markers.map(m => [m.id, [m.x, m.y]]))"


async def check_flying(page: Any, spawn: dict[str, list[float]]) -> None:
    """Markers for the three UAVs that move; the landmarks the daemons fly by, covered."""
    ids = await page.evaluate("window.__aw.markers.filter(m => m.ours).map(m => m.id).sort()")
    assert ids == ["uav0", "uav1", "uav2"]
    first = await page.evaluate("window.__aw.frames[window.__aw.cur - window.__aw.base]")
    assert first["source"] == "field"
    assert {v["phase"] for v in first["vehicles"].values()} == {"mission"}
    assert all(v["battery_pct"] == 90 for v in first["vehicles"].values())  # SYS_STATUS
    assert all(0 <= v["heartbeat_age_s"] < 3 for v in first["vehicles"].values())
    await page.wait_for_function(
        """(b) => window.__aw.markers.filter((m) => m.ours).every(
             (m) => Math.hypot(m.x - b[m.id][0], m.y - b[m.id][1]) > 4)""",
        arg=spawn,
        timeout=30_000,
    )  # every marker moved from where it stood (the vehicles fly toward their landmarks)
    targets = await page.eval_on_selector_all(
        "#targets tr[data-target]", "rs => rs.map(r => r.dataset.target)"
    )
    assert targets == ["L0", "L1", "L2"]
    await page.wait_for_selector("#targets tr.covered", timeout=60_000)
    legend = await page.eval_on_selector_all(
        "#legend [data-glyph]", "s => s.map(x => x.dataset.glyph)"
    )
    assert {"k:landmark", "k:landmark:c", "held", "trail", "stale"} <= set(legend)


async def check_ended(page: Any) -> None:
    """After the mission: ENDED and the stop button disabled, while the page still follows
    the UAVs (they land); "replay" plays what it saw from the first frame."""
    await page.wait_for_function(
        "document.getElementById('mode').textContent === 'ended'", timeout=15_000
    )
    assert await page.is_disabled("#stop")
    assert await page.evaluate("window.__aw.follow")  # still connected: the landing shows
    await page.wait_for_function(
        "(() => { const S = window.__aw; const f = S.frames[S.cur - S.base];"
        " return Object.values(f.vehicles).every(v => v.phase !== 'mission'); })()",
        timeout=30_000,
    )  # the flight phases left the mission (landing, then on the ground)
    last = await page.evaluate("window.__aw.cur")
    await page.click("#replay")
    await page.wait_for_function(
        f"window.__aw.cur > window.__aw.base && window.__aw.cur < {last} && !window.__aw.follow"
    )
    assert await page.evaluate("window.__aw.playing")
