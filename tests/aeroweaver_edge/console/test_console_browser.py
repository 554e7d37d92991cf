"""The console in a real browser (Debian's headless Chromium driven by Playwright) during a
simulated run: three UAV markers appear and move between rounds, clicking one shows its
decision (options, scores, the pick), the stop needs the typed phrase, and a screenshot is
saved. Skips, saying why, only where Chromium cannot be installed (.ci/run installs it)."""

from __future__ import annotations

import asyncio
import os
import shutil
from pathlib import Path
from typing import Any

import pytest

from aeroweaver_edge.console.server import Console
from aeroweaver_edge.orchestration.swarm import RunSummary, SwarmHandle, SwarmOptions, run_swarm

CHROMIUM = Path("/usr/bin/chromium")
FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]  # fmt: skip

pytestmark = pytest.mark.timeout(120)


def browser_or_skip() -> Any:
    if not CHROMIUM.exists():
        pytest.skip(
            f"browser test skipped: Chromium is not installed at {CHROMIUM} (.ci/run installs "
            "Debian's chromium with apt-get; this machine could not)"
        )
    try:
        from playwright.async_api import async_playwright
    except ImportError:
        pytest.skip("browser test skipped: the 'browser' extra (playwright) is not installed")
    return async_playwright


async def test_console_in_chromium(tmp_path: Path) -> None:
    async_playwright = browser_or_skip()
    async with Console("127.0.0.1", 0) as console:

        async def started(h: SwarmHandle) -> None:
            await console.connect(h.mesh_for("operator"), h.swarm)

        opts = SwarmOptions(task="coverage", selector="scripted", episodes=30, pace_s=0.25)
        run: asyncio.Task[RunSummary] = asyncio.create_task(run_swarm(opts, on_started=started))
        try:
            async with async_playwright() as pw:
                ctx = await pw.chromium.launch_persistent_context(
                    str(tmp_path / "profile"), executable_path=str(CHROMIUM), args=FLAGS,
                    headless=True, viewport={"width": 1280, "height": 760},
                )  # fmt: skip
                page = ctx.pages[0] if ctx.pages else await ctx.new_page()
                errors: list[str] = []
                page.on("pageerror", lambda e: errors.append(str(e)))
                await page.goto(console.url)
                await page.wait_for_function(
                    "window.__aw.markers.filter(m => m.ours).length === 3", timeout=30_000
                )
                ids = await page.evaluate("window.__aw.markers.map(m => m.id).sort()")
                assert ids == ["uav0", "uav1", "uav2"]
                before = await page.evaluate("JSON.stringify(window.__aw.markers)")
                cur = await page.evaluate("window.__aw.cur")
                await page.wait_for_function(f"window.__aw.cur >= {cur + 2}", timeout=20_000)
                await page.wait_for_function(
                    "b => JSON.stringify(window.__aw.markers) !== b", arg=before, timeout=5_000
                )  # the markers moved between rounds

                await page.click("#play")  # pause: the map holds still for the click
                xy = await page.evaluate("window.__aw.markerAt('uav1')")
                await page.mouse.click(xy[0], xy[1])
                await page.wait_for_selector("#decision tr.chosen", timeout=10_000)
                shown = await page.get_attribute("#decision tr.chosen", "data-label")
                want = await page.evaluate(
                    "(() => { const S = window.__aw; const f = S.frames[S.cur - S.base];"
                    " return f.decisions.uav1.chosen; })()"
                )
                assert shown == want
                assert (await page.inner_text("#decision h3")).startswith("uav1")
                rows = await page.locator("#decision table.options tbody tr").count()
                assert rows >= 2
                await page.click("#live")  # follow the run again
                await page.wait_for_timeout(600)
                shot = tmp_path / "console.png"
                await page.screenshot(path=str(shot))
                assert shot.stat().st_size > 20_000
                if os.environ.get("AEROWEAVER_CONSOLE_SCREENSHOT"):
                    shutil.copy(shot, os.environ["AEROWEAVER_CONSOLE_SCREENSHOT"])
                drawn = await page.evaluate("window.__aw.drawn")
                assert len(drawn) >= 3
                assert all(d["drawn"] >= d["stamp"] for d in drawn if d["stamp"])

                # the operator's stop, through the page: the typed phrase is required
                await page.click("#stop")
                await page.wait_for_selector("#confirm[open]")
                await page.fill("#confirm-input", "stop")
                await page.click("#confirm-ok")
                assert await page.inner_text("#confirm-error") == "the text does not match"
                assert not run.done()
                phrase = await page.inner_text("#confirm-phrase")
                assert phrase == "stop coverage-s1"
                await page.fill("#confirm-input", phrase)
                await page.click("#confirm-ok")
                summary = await asyncio.wait_for(run, 30)
                assert errors == []
                await ctx.close()
        finally:
            run.cancel()
    assert summary.stopped is not None
    assert summary.stopped.startswith("operator stop by")
    assert len(summary.episodes) < 30  # cut short by the stop


async def test_the_page_outlives_a_sim_console_run(tmp_path: Path) -> None:
    """``sim --console`` (``with_console``): when the run ends the server goes with it, but
    the page shows ENDED, disables the stop button, keeps every frame and replays them."""
    from aeroweaver_edge.console.server import with_console
    from tests.helpers.zenoh_net import free_port

    async_playwright = browser_or_skip()
    port = free_port()
    opts = SwarmOptions(task="coverage", selector="scripted", max_rounds=16, pace_s=0.3)
    run: asyncio.Task[RunSummary] = asyncio.create_task(with_console(opts, "127.0.0.1", port))
    try:
        async with async_playwright() as pw:
            ctx = await pw.chromium.launch_persistent_context(
                str(tmp_path / "profile"), executable_path=str(CHROMIUM), args=FLAGS,
                headless=True, viewport={"width": 1280, "height": 760},
            )  # fmt: skip
            page = ctx.pages[0] if ctx.pages else await ctx.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            for _ in range(200):  # the console binds its port as the run starts
                try:
                    await page.goto(f"http://127.0.0.1:{port}/")
                    break
                except Exception:
                    await asyncio.sleep(0.1)
            await page.wait_for_function("window.__aw.frames.length >= 2", timeout=30_000)
            assert await page.text_content("#mode") == "live"
            await asyncio.wait_for(run, 60)
            await page.wait_for_function(
                "document.getElementById('mode').textContent === 'ended'", timeout=15_000
            )
            assert await page.is_disabled("#stop")
            assert not await page.is_visible("#live")
            seen = await page.evaluate("window.__aw.frames.length")
            assert seen >= 10  # every round it saw stays (16 rounds, 0.3 s each)
            await page.click("#play")  # replay from the first frame
            await page.wait_for_function(
                f"window.__aw.cur > window.__aw.base && window.__aw.cur < {seen - 1}"
            )
            assert errors == []
            await ctx.close()
    finally:
        run.cancel()
