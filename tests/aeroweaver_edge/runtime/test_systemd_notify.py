"""sd_notify under a fake NOTIFY_SOCKET (a real AF_UNIX datagram socket): READY, WATCHDOG
and STOPPING arrive from a real daemon, SIGTERM exits 0, and a stalled event loop stops
the watchdog pings."""

from __future__ import annotations

import asyncio
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from aeroweaver_edge.runtime.systemd_notify import (
    Notifier,
    Supervision,
    Watchdog,
    watchdog_interval_s,
)
from tests.aeroweaver_edge.cli.test_main import aeroweaver


@pytest.fixture
def listener(tmp_path: Path) -> Iterator[tuple[socket.socket, str]]:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    path = tmp_path / "notify.sock"
    sock.bind(str(path))
    try:
        yield sock, str(path)
    finally:
        sock.close()


def receive(sock: socket.socket, timeout_s: float) -> str | None:
    sock.settimeout(timeout_s)
    try:
        return sock.recv(4096).decode()
    except TimeoutError:
        return None


def test_notifier_path_and_abstract_sockets(listener: tuple[socket.socket, str]) -> None:
    sock, path = listener
    n = Notifier(path)
    assert n.notify("READY=1", "STATUS=up")
    assert receive(sock, 5) == "READY=1\nSTATUS=up"
    n.close()
    name = f"aw-test-{uuid.uuid4().hex}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as abstract:
        abstract.bind("\0" + name)
        a = Notifier.from_env({"NOTIFY_SOCKET": "@" + name})
        assert a.notify("WATCHDOG=1")
        assert receive(abstract, 5) == "WATCHDOG=1"
        a.close()


def test_without_notify_socket_everything_is_a_no_op() -> None:
    n = Notifier.from_env({})
    assert not n.enabled
    assert not n.notify("READY=1")
    sup = Supervision.from_env({"WATCHDOG_USEC": "1000000"})
    assert sup.watchdog is None


def test_a_missing_listener_never_raises(tmp_path: Path) -> None:
    n = Notifier(str(tmp_path / "nobody-listens.sock"))
    assert not n.notify("READY=1")
    assert not n.notify("WATCHDOG=1")


@pytest.mark.parametrize(
    ("env", "want"),
    [
        ({"WATCHDOG_USEC": "4000000"}, 2.0),
        ({"WATCHDOG_USEC": "4000000", "WATCHDOG_PID": str(os.getpid())}, 2.0),
        ({"WATCHDOG_USEC": "4000000", "WATCHDOG_PID": "1"}, None),  # meant for another process
        ({"WATCHDOG_USEC": "0"}, None),
        ({"WATCHDOG_USEC": "soon"}, None),
        ({}, None),
    ],
)
def test_watchdog_interval_is_half_of_watchdog_usec(
    env: dict[str, str], want: float | None
) -> None:
    assert watchdog_interval_s(env) == want


class TimedNotifier(Notifier):
    """Records when each datagram left (on the loop's thread) besides sending it."""

    def __init__(self, address: str) -> None:
        super().__init__(address)
        self.sent_at: list[float] = []

    def notify(self, *fields: str) -> bool:
        ok = super().notify(*fields)
        if ok:
            self.sent_at.append(time.monotonic())
        return ok


def test_a_stalled_loop_stops_the_pings(listener: tuple[socket.socket, str]) -> None:
    """The event loop runs in a thread; a blocking call on it (time.sleep, as a hung
    daemon would) must stop the pings, and the first late wake-up must not ping either."""
    sock, path = listener
    interval, stall = 0.1, 1.0
    loop = asyncio.new_event_loop()
    notifier = TimedNotifier(path)
    dog = Watchdog(notifier, interval)
    started = threading.Event()
    stalled: list[tuple[float, float]] = []

    def block() -> None:
        begin = time.monotonic()
        time.sleep(stall)
        stalled.append((begin, time.monotonic()))

    def run() -> None:
        asyncio.set_event_loop(loop)

        async def main() -> None:
            dog.start()
            started.set()
            await asyncio.Event().wait()  # until the loop is stopped

        task = loop.create_task(main())
        loop.run_forever()
        task.cancel()
        loop.run_until_complete(asyncio.gather(task, return_exceptions=True))
        loop.run_until_complete(dog.stop())
        loop.close()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        assert started.wait(10)
        for _ in range(3):  # healthy: pings keep coming, through the real socket
            assert receive(sock, 5) == "WATCHDOG=1"
        skipped_before, pings_before = dog.skipped, dog.pings
        loop.call_soon_threadsafe(block)
        # Wait (bounded) for the pings to resume after the stall.
        deadline = time.monotonic() + stall + 10.0
        while time.monotonic() < deadline and not (
            stalled and dog.pings >= pings_before + 2 and notifier.sent_at[-1] > stalled[0][1]
        ):
            receive(sock, 0.5)
        assert stalled, "the stall never ran"
        begin, end = stalled[0]
        assert [t for t in notifier.sent_at if begin < t < end] == []  # silent while stalled
        assert any(t > end for t in notifier.sent_at), "pings resume once the loop is free"
        assert dog.skipped > skipped_before  # the first late wake-up withheld its ping
        assert dog.last_lag_s < stall
    finally:
        loop.call_soon_threadsafe(loop.stop)
        thread.join(10)
        notifier.close()


def test_daemon_speaks_sd_notify_and_exits_0_on_sigterm(
    listener: tuple[socket.socket, str], tmp_path: Path
) -> None:
    sock, path = listener
    config = tmp_path / "uav0.toml"
    config.write_text(
        'uav = "uav0"\n[agent]\nselector = "scripted"\n'
        f'memory_path = "{tmp_path / "memory" / "uav0.sqlite3"}"\n'
    )
    env = {
        **os.environ,
        "NOTIFY_SOCKET": path,
        "WATCHDOG_USEC": "400000",  # pings every 0.2 s
    }
    proc = subprocess.Popen(
        [*aeroweaver(), "daemon", "--config", str(config)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    try:
        messages: list[str] = []
        while not any(m.startswith("READY=1") for m in messages):
            msg = receive(sock, 30)
            assert msg is not None, proc.stderr.read() if proc.poll() is not None else "no READY"
            messages.append(msg)
        ready = next(m for m in messages if m.startswith("READY=1"))
        assert "STATUS=uav0 up" in ready
        pings = 0
        while pings < 3:
            msg = receive(sock, 10)
            assert msg is not None, "watchdog pings stopped"
            pings += msg == "WATCHDOG=1"
        proc.send_signal(signal.SIGTERM)
        rest: list[str] = []
        while not any(m.startswith("STOPPING=1") for m in rest):
            msg = receive(sock, 10)
            assert msg is not None, "no STOPPING=1"
            rest.append(msg)
        _out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err[-2000:]
    assert "Traceback" not in err
    assert (tmp_path / "memory" / "uav0.sqlite3").exists()


if sys.platform != "linux":  # pragma: no cover
    pytestmark = pytest.mark.skip("AF_UNIX datagrams and abstract sockets are Linux-only")
