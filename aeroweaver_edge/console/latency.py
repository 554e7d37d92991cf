"""Console update latency, world round -> pixel, in a real browser (prints figures).

    python -m aeroweaver_edge.console.latency --uavs 3 50 --rounds 20 [--screenshot PATH]

For each swarm size: a simulated run (scripted selector, paced at the paper's 0.5 s rounds)
with the console joined to its mesh, and Debian's headless Chromium on the page. The world
stamps each round's snapshot when it publishes it (wall clock); the page records when it
first painted that round (``performance.timeOrigin + performance.now()``, same machine).
Latency = painted - stamped, per round. Also printed: the page's animation-frame intervals
during the run (smoothness: share of frames slower than 50 ms).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

from aeroweaver_edge.console.server import Console
from aeroweaver_edge.orchestration.swarm import SwarmHandle, SwarmOptions, percentiles, run_swarm

CHROMIUM = "/usr/bin/chromium"
FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]  # fmt: skip
RAF_PROBE = """
window.__awRaf = []; let last = performance.now();
(function loop(t) { window.__awRaf.push(t - last); last = t; requestAnimationFrame(loop); })(last);
"""


async def measure(
    uavs: int, rounds: int, task: str, screenshot: Path | None = None, processes: bool = False
) -> dict[str, Any]:
    from playwright.async_api import async_playwright

    async with Console("127.0.0.1", 0) as console:

        async def started(h: SwarmHandle) -> None:
            await console.connect(h.mesh_for("operator"), h.swarm)

        opts = SwarmOptions(task=task, uavs=uavs, selector="scripted", max_rounds=rounds,
                            episodes=1000, pace_s=0.5, processes=processes)  # fmt: skip
        run = asyncio.create_task(run_swarm(opts, on_started=started))
        try:
            async with async_playwright() as pw:
                with tempfile.TemporaryDirectory(prefix="aw-chromium-") as profile:
                    ctx = await pw.chromium.launch_persistent_context(
                        profile, executable_path=CHROMIUM, args=FLAGS, headless=True,
                        viewport={"width": 1280, "height": 760},
                    )  # fmt: skip
                    page = ctx.pages[0] if ctx.pages else await ctx.new_page()
                    await page.goto(console.url)
                    await page.wait_for_function(
                        f"window.__aw.markers.filter(m => m.ours).length === {uavs}",
                        timeout=120_000,
                    )
                    await page.evaluate(RAF_PROBE)
                    first = await page.evaluate("window.__aw.drawn.length")
                    await page.wait_for_function(
                        f"window.__aw.drawn.length >= {first + rounds}", timeout=300_000,
                        polling=500,
                    )  # fmt: skip
                    drawn = (await page.evaluate("window.__aw.drawn"))[first:]
                    raf = await page.evaluate("window.__awRaf.slice(1)")
                    if screenshot is not None:
                        await page.screenshot(path=str(screenshot))
                    await ctx.close()
        finally:
            run.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await run
    lat = [d["drawn"] - d["stamp"] for d in drawn if d.get("stamp")]
    wire = [d["recv"] - d["stamp"] for d in drawn if d.get("stamp") and d.get("recv")]
    paint = [d["drawn"] - d["recv"] for d in drawn if d.get("recv")]
    slow = sum(1 for x in raf if x > 50.0)
    return {
        "uavs": uavs,
        "task": task,
        "daemons": "processes" if processes else "in-process",
        "rounds": len(lat),
        "latency_s": percentiles(lat),
        "to_browser_s": percentiles(wire),  # world publish -> the page received the event
        "in_browser_s": percentiles(paint),  # received -> first painted
        "frame_interval_ms": {k: round(v, 1) for k, v in percentiles(raf).items()},
        "frames_over_50ms": f"{slow}/{len(raf)}",
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m aeroweaver_edge.console.latency",
                                description=__doc__.split("\n")[0])  # fmt: skip
    p.add_argument("--uavs", type=int, nargs="+", default=[3, 50])
    p.add_argument("--rounds", type=int, default=20, help="rounds measured per size")
    p.add_argument("--task", default="coverage")
    p.add_argument("--screenshot", type=Path, help="save the page (last size) here")
    p.add_argument("--json", action="store_true", help="print JSON lines")
    p.add_argument("--processes", action="store_true", help="one OS process per daemon")
    args = p.parse_args(argv)
    if not Path(CHROMIUM).exists():
        print(f"{CHROMIUM} is missing: apt-get install chromium", file=sys.stderr)
        return 2
    for i, n in enumerate(args.uavs):
        shot = args.screenshot if i == len(args.uavs) - 1 else None
        out = asyncio.run(measure(n, args.rounds, args.task, shot, args.processes))
        if args.json:
            print(json.dumps(out))
            continue
        lat, fi = out["latency_s"], out["frame_interval_ms"]
        wire, paint = out["to_browser_s"], out["in_browser_s"]
        print(
            f"{n:3d} UAVs ({args.task}, {out['daemons']} daemons): world round -> pixel "
            f"p50 {lat['p50'] * 1e3:.1f} ms, "
            f"p95 {lat['p95'] * 1e3:.1f} ms, max {lat['max'] * 1e3:.1f} ms over {out['rounds']} "
            f"rounds (to the page p50 {wire['p50'] * 1e3:.1f} ms, in the page p50 "
            f"{paint['p50'] * 1e3:.1f} ms); animation frames p50 {fi['p50']} ms, p95 "
            f"{fi['p95']} ms, {out['frames_over_50ms']} over 50 ms"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
