"""Shared fixtures and checks for the whole test tree.

Every test runs in an empty working directory of its session (``_elsewhere``), so none can
depend on being started from the repository root.

The suite tests both distributions: without ``aeroweaver-lab`` (``pip install -e ./lab``) it
refuses to start. Requirements (``tests/helpers/requirements.py``): a test marked
``embedded`` or ``mavsdk`` fails when what it needs is not installed, unless
``AEROWEAVER_ALLOW_SKIP`` names it; the terminal summary says what was missing and whether
that was allowed.
"""

from __future__ import annotations

import importlib.util
import signal
import threading
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest

from tests.helpers import sitl
from tests.helpers.hang_dump import dump_asyncio_tasks, timeout_s
from tests.helpers.requirements import ALLOW_SKIP_ENV, REQUIREMENTS, allowed_skips, decide, missing
from tests.helpers.zenoh_net import ZenohNet

_allowed: frozenset[str] = frozenset()
_met: dict[str, str] = {}  # requirement -> why it was missing, for the summary


def pytest_configure(config: pytest.Config) -> None:
    global _allowed
    try:
        _allowed = allowed_skips()
    except ValueError as exc:
        raise pytest.UsageError(str(exc)) from None
    if importlib.util.find_spec("aeroweaver_lab") is None:  # the suite tests both distributions
        raise pytest.UsageError(
            "the aeroweaver-lab distribution is not installed: pip install -e ./lab "
            "(the README's test command installs it)"
        )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Tests that run the embedded model (llama.cpp on every core) share one xdist worker
    (``--dist loadgroup``): two at once on two cores would each run at half speed against
    deadlines sized for one."""
    for item in items:
        if item.get_closest_marker("embedded") is not None:
            item.add_marker(pytest.mark.xdist_group("embedded"))


def pytest_runtest_setup(item: pytest.Item) -> None:
    if item.get_closest_marker("sitl") is not None:
        why = sitl.unavailable()  # the user's own SITL build: skipped, never failed, without it
        if why is not None:
            pytest.skip(why)
    for name in REQUIREMENTS:
        if item.get_closest_marker(name) is None:
            continue
        why = missing(name)
        verdict = decide(name, why, _allowed)
        if why is not None:
            _met[name] = why
        if verdict == "skip":
            pytest.skip(f"{why} (allowed by {ALLOW_SKIP_ENV})")
        if verdict == "fail":
            pytest.fail(
                f"{why}. Install it, or run with {ALLOW_SKIP_ENV}={name} to skip these tests.",
                pytrace=False,
            )


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    """Five seconds before pytest-timeout fires, print where every asyncio task waits:
    its own dump shows threads only, and a hung async test's main thread is in ``select``."""
    timeout = timeout_s(item)
    timer = None
    if timeout > 10:
        timer = threading.Timer(timeout - 5, dump_asyncio_tasks, args=(item.nodeid,))
        timer.daemon = True
        timer.start()
    try:
        return (yield)
    finally:
        if timer is not None:
            timer.cancel()


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    for name, why in sorted(_met.items()):
        how = "skipped: allowed" if name in _allowed else "FAILED: not allowed"
        terminalreporter.write_line(f"requirement '{name}' missing ({how}): {why}")


@pytest.fixture(scope="session")
def _empty_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("cwd")


@pytest.fixture(autouse=True)
def _elsewhere(_empty_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Not the repository root: a relative path in a test fails here, in every run."""
    monkeypatch.chdir(_empty_dir)


@pytest.fixture(autouse=True)
def _signal_handlers_kept() -> Iterator[None]:
    """Whatever a test's in-process command does to SIGTERM/SIGINT ends with the test: a
    SIG_IGN left behind is inherited by every process a later test starts."""
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    yield
    for sig, handler in saved.items():
        if handler is not None:
            signal.signal(sig, handler)


@pytest.fixture
async def zenoh_net() -> AsyncIterator[ZenohNet]:
    """A fresh loopback mesh namespace; every session opened through it is closed after."""
    net = ZenohNet()
    try:
        yield net
    finally:
        await net.aclose()
