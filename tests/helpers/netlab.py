"""Network namespaces joined to the test's own namespace, for partition and lossy-link tests.

``NetLab.unavailable()`` says why the machine cannot do it (not Linux, not root, no ``ip``,
namespaces refused), so a test can skip with that reason. Each ``segment`` is a namespace
with a point-to-point link to this one:

- ``veth``: a veth pair; ``down``/``up`` cut and heal it (a partition: no FIN, no RST, the
  peers only notice through zenoh's lease); ``impair`` puts ``tc netem`` loss and delay on
  both ends, where the kernel has ``sch_netem``;
- ``impaired``: where it has not, two TUN devices with a userspace forwarder between them
  (``impair_link.py``) that drops and delays real IP packets in each direction.

Every namespace, link and forwarder is removed by ``close``.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import socket
import subprocess
import sys
import uuid
from dataclasses import dataclass, field
from pathlib import Path

IMPAIR = Path(__file__).with_name("impair_link.py")


def _ip(*args: str, ns: str | None = None) -> None:
    cmd = ["ip", *args] if ns is None else ["ip", "netns", "exec", ns, "ip", *args]
    subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=30)


@dataclass
class Segment:
    ns: str
    host_if: str
    ns_if: str
    host_ip: str
    ns_ip: str
    kind: str  # "veth" or "tun"
    forwarder: subprocess.Popen[str] | None = None
    counters: dict[str, int] = field(default_factory=dict)

    def prefix(self) -> list[str]:
        """Run a command inside this segment's namespace."""
        return ["ip", "netns", "exec", self.ns]


class NetLab:
    def __init__(self) -> None:
        tag = uuid.uuid4().hex[:6]
        self.tag = tag
        self.net = 200 + int(tag[:2], 16) % 50  # 10.<net>.<k>.0/30 per segment
        self.segments: list[Segment] = []

    @staticmethod
    def unavailable() -> str | None:
        """Why this machine cannot build namespaces here (None: it can)."""
        if not sys.platform.startswith("linux"):
            return "network namespaces are Linux only"
        if os.geteuid() != 0:
            return "network namespaces need root"
        if shutil.which("ip") is None:
            return "the ip command (iproute2) is not installed"
        probe = f"awprobe-{uuid.uuid4().hex[:6]}"
        try:
            _ip("netns", "add", probe)
            _ip("netns", "del", probe)
        except (subprocess.CalledProcessError, OSError) as exc:
            return f"cannot create a network namespace: {getattr(exc, 'stderr', exc)}".strip()
        return None

    @staticmethod
    def netem_unavailable() -> str | None:
        """Why ``tc netem`` cannot be used (None: it can)."""
        if shutil.which("tc") is None:
            return "the tc command (iproute2) is not installed"
        probe = f"awprobe-{uuid.uuid4().hex[:6]}"
        try:
            _ip("netns", "add", probe)
            done = subprocess.run(
                ["ip", "netns", "exec", probe, "tc", "qdisc", "add", "dev", "lo", "root",
                 "netem", "delay", "1ms"],
                capture_output=True, text=True, timeout=30,
            )  # fmt: skip
            if done.returncode != 0:
                return f"tc netem: {done.stderr.strip()} (the kernel has no sch_netem)"
            return None
        finally:
            subprocess.run(["ip", "netns", "del", probe], capture_output=True, timeout=30)

    def _names(self) -> tuple[str, str, str, str, str]:
        k = len(self.segments) + 1
        ns = f"aw{self.tag}n{k}"
        return (
            ns,
            f"aw{self.tag}h{k}",
            f"aw{self.tag}i{k}",
            f"10.{self.net}.{k}.1",
            f"10.{self.net}.{k}.2",
        )

    def veth(self) -> Segment:
        ns, host_if, ns_if, host_ip, ns_ip = self._names()
        _ip("netns", "add", ns)
        seg = Segment(ns, host_if, ns_if, host_ip, ns_ip, "veth")
        self.segments.append(seg)
        _ip("link", "add", host_if, "type", "veth", "peer", "name", ns_if)
        _ip("link", "set", ns_if, "netns", ns)
        self._address(seg)
        return seg

    def impaired(self, loss_pct: float, delay_ms: float, seed: int = 1) -> Segment:
        """A segment whose link drops ``loss_pct``% and delays ``delay_ms`` each way: netem
        on a veth pair where the kernel has it, else the userspace TUN forwarder."""
        if self.netem_unavailable() is None:
            seg = self.veth()
            for dev, ns in ((seg.host_if, None), (seg.ns_if, seg.ns)):
                cmd = ["tc", "qdisc", "add", "dev", dev, "root", "netem",
                       "loss", f"{loss_pct}%", "delay", f"{delay_ms}ms"]  # fmt: skip
                subprocess.run(
                    cmd if ns is None else ["ip", "netns", "exec", ns, *cmd],
                    check=True, capture_output=True, timeout=30,
                )  # fmt: skip
            return seg
        ns, host_if, ns_if, host_ip, ns_ip = self._names()
        _ip("netns", "add", ns)
        seg = Segment(ns, host_if, ns_if, host_ip, ns_ip, "tun")
        self.segments.append(seg)
        seg.forwarder = subprocess.Popen(
            [sys.executable, str(IMPAIR), ns, host_if, ns_if, str(loss_pct), str(delay_ms),
             str(seed)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        )  # fmt: skip
        assert seg.forwarder.stdout is not None
        if seg.forwarder.stdout.readline().strip() != "ready":
            raise RuntimeError("the impairment forwarder did not start")
        self._address(seg)
        return seg

    def _address(self, seg: Segment) -> None:
        _ip("addr", "add", f"{seg.host_ip}/32", "peer", seg.ns_ip, "dev", seg.host_if)
        _ip("link", "set", seg.host_if, "up")
        _ip("addr", "add", f"{seg.ns_ip}/32", "peer", seg.host_ip, "dev", seg.ns_if, ns=seg.ns)
        _ip("link", "set", seg.ns_if, "up", ns=seg.ns)
        _ip("link", "set", "lo", "up", ns=seg.ns)

    def down(self, seg: Segment) -> None:
        """Cut the link (both ends down: nothing crosses, nobody is told)."""
        _ip("link", "set", seg.host_if, "down")
        _ip("link", "set", seg.ns_if, "down", ns=seg.ns)

    def up(self, seg: Segment) -> None:
        _ip("link", "set", seg.host_if, "up")
        _ip("link", "set", seg.ns_if, "up", ns=seg.ns)
        # bringing a link down drops its routes; the peer route comes back with the address
        _ip("route", "replace", seg.ns_ip, "dev", seg.host_if)
        _ip("route", "replace", seg.host_ip, "dev", seg.ns_if, ns=seg.ns)

    def handshakes_ms(self, seg: Segment, n: int = 20) -> list[float]:
        """TCP handshake times (ms) from inside ``seg``'s namespace to a socket listening
        on this side of its link: one round trip each (a lost SYN or SYN-ACK costs the
        kernel's 1 s retransmission), so the link's delay and loss show as measured."""
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as srv:
            srv.bind((seg.host_ip, 0))
            srv.listen(n + 8)  # the kernel completes handshakes without accept()
            port = srv.getsockname()[1]
            probe = (
                "import socket, sys, time\n"
                "for _ in range(int(sys.argv[3])):\n"
                "    t = time.monotonic()\n"
                "    socket.create_connection((sys.argv[1], int(sys.argv[2])), 10).close()\n"
                "    print((time.monotonic() - t) * 1000, flush=True)\n"
            )
            done = subprocess.run(
                [*seg.prefix(), sys.executable, "-c", probe, seg.host_ip, str(port), str(n)],
                check=True, capture_output=True, text=True, timeout=30 + 12 * n,
            )  # fmt: skip
        return [float(x) for x in done.stdout.split()]

    def stats(self, seg: Segment) -> dict[str, int]:
        """Packets the link carried and dropped so far, both directions: the forwarder's
        counters, or the netem qdiscs' on both ends of a veth pair. Proves a test's
        impairment really happened."""
        if seg.forwarder is not None:
            assert seg.forwarder.stdin is not None
            assert seg.forwarder.stdout is not None
            seg.forwarder.stdin.write("stats\n")
            seg.forwarder.stdin.flush()
            counts: dict[str, int] = json.loads(seg.forwarder.stdout.readline())
            return counts
        out = {"forwarded": 0, "dropped": 0}
        for dev, ns in ((seg.host_if, None), (seg.ns_if, seg.ns)):
            cmd = ["tc", "-s", "qdisc", "show", "dev", dev]
            text = subprocess.run(
                cmd if ns is None else ["ip", "netns", "exec", ns, *cmd],
                check=True, capture_output=True, text=True, timeout=30,
            ).stdout  # fmt: skip
            # " Sent 1234 bytes 12 pkt (dropped 3, overlimits 0 requeues 0)" (root qdisc first)
            m = re.search(r"Sent \d+ bytes (\d+) pkt \(dropped (\d+),", text)
            if m is not None:
                out["forwarded"] += int(m.group(1))
                out["dropped"] += int(m.group(2))
        return out

    def close(self) -> None:
        for seg in self.segments:
            if seg.forwarder is not None and seg.forwarder.poll() is None:
                try:
                    out, _ = seg.forwarder.communicate("quit\n", timeout=10)
                    seg.counters = json.loads(out.strip().splitlines()[-1])
                except (subprocess.TimeoutExpired, ValueError, IndexError):
                    seg.forwarder.kill()
            subprocess.run(["ip", "link", "del", seg.host_if], capture_output=True, timeout=30)
            subprocess.run(["ip", "netns", "del", seg.ns], capture_output=True, timeout=30)
        self.segments.clear()
