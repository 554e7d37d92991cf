"""A point-to-point IP link with loss and delay between this network namespace and another,
for kernels without ``sch_netem`` (``tc qdisc add ... netem`` says "Specified qdisc kind is
unknown"). Run as a script by ``netlab.NetLab.impaired``:

    python impair_link.py NETNS HOST_IF NS_IF LOSS_PCT DELAY_MS SEED

It creates a TUN device on each side (``HOST_IF`` here, ``NS_IF`` inside ``NETNS``), prints
``ready``, then forwards every IP packet from one to the other, dropping each with
probability ``LOSS_PCT``% and delivering the rest ``DELAY_MS`` later, each direction on
its own: the kernels on both sides see real packets, so TCP retransmits and backs off as it
would over netem. Commands on stdin: ``loss P``, ``delay MS``, ``stats`` (prints the
counters as one JSON line), ``quit`` (prints them and exits). Linux, root.
"""

from __future__ import annotations

import ctypes
import fcntl
import heapq
import json
import os
import random
import select
import struct
import sys
import time

TUNSETIFF = 0x400454CA
IFF_TUN = 0x0001
IFF_NO_PI = 0x1000
CLONE_NEWNET = 0x40000000


def open_tun(name: str) -> int:
    fd = os.open("/dev/net/tun", os.O_RDWR)
    fcntl.ioctl(fd, TUNSETIFF, struct.pack("16sH", name.encode(), IFF_TUN | IFF_NO_PI))
    return fd


def setns(fd: int) -> None:
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.setns(fd, CLONE_NEWNET) != 0:
        raise OSError(ctypes.get_errno(), "setns failed")


def main(argv: list[str]) -> int:
    netns, host_if, ns_if = argv[0], argv[1], argv[2]
    loss, delay = float(argv[3]) / 100.0, float(argv[4]) / 1000.0
    rng = random.Random(int(argv[5]))
    own = os.open("/proc/self/ns/net", os.O_RDONLY)
    host = open_tun(host_if)
    target = os.open(f"/var/run/netns/{netns}", os.O_RDONLY)
    setns(target)
    inner = open_tun(ns_if)
    setns(own)
    peer = {host: inner, inner: host}
    counts = {"forwarded": 0, "dropped": 0, "undeliverable": 0, "bytes": 0}
    queue: list[tuple[float, int, int, bytes]] = []
    n = 0
    print("ready", flush=True)
    stdin = sys.stdin.fileno()
    while True:
        now = time.monotonic()
        while queue and queue[0][0] <= now:
            _, _, dst, pkt = heapq.heappop(queue)
            try:
                os.write(dst, pkt)
            except OSError:
                counts["undeliverable"] += 1  # that side's interface is down (or not up yet)
        timeout = max(0.0, queue[0][0] - now) if queue else 1.0
        readable, _, _ = select.select([host, inner, stdin], [], [], timeout)
        for fd in readable:
            if fd == stdin:
                line = sys.stdin.readline().split()
                if not line or line[0] == "quit":
                    print(json.dumps(counts), flush=True)
                    return 0
                if line[0] == "stats":
                    print(json.dumps(counts), flush=True)
                elif line[0] == "loss":
                    loss = float(line[1]) / 100.0
                elif line[0] == "delay":
                    delay = float(line[1]) / 1000.0
                continue
            pkt = os.read(fd, 65536)
            if rng.random() < loss:
                counts["dropped"] += 1
                continue
            counts["forwarded"] += 1
            counts["bytes"] += len(pkt)
            n += 1
            heapq.heappush(queue, (time.monotonic() + delay, n, peer[fd], pkt))


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
