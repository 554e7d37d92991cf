"""Bounded, per-sender fair hand-off from Zenoh's threads to the event loop, and the
per-sender budget of signature verifications.

Why: one enrolled but compromised UAV could flood its own keys (6-14k msg/s). With one
``call_soon_threadsafe`` and one Ed25519 verification per sample, the receiving loop fell
behind without bound, liveliness events queued behind the flood and, once the loop held
the GIL all the time, Zenoh's RX threads could not hand samples over, links congested and
closed (the world saw every UAV "leave the swarm" at once). Here:

* ``SenderQueues``: what a callback enqueues, one small FIFO per sender (the signer's key
  id when secured, else the key), served round robin, so a flooding sender fills only its
  own FIFO and an honest sender's next sample is never behind more than one of the
  flooder's. Full means dropped and counted, never blocked, never raised.
* ``VerifyBudget``: per signer, a token bucket of verifications, refilled per second and
  per round the owner announces (``Mesh.note_round``); a payload over budget is dropped
  and counted before any decoding or crypto. Honest senders need a handful per round and
  a burst of experience records at an episode's end, which ``burst`` covers.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from aeroweaver_edge.contracts.wire import MAX_PAYLOAD_BYTES

I = TypeVar("I")  # noqa: E741 - queued item type

MAX_SENDERS = 256
"""FIFOs one subscription keeps at once: senders beyond it are dropped (a forged-key flood
cannot grow the table; the identity list of a swarm is far smaller)."""


FIFO_MIN = 256
"""Smallest per-sender FIFO of a subscription (a burst of local puts, or an episode's
experience records, arrives before the loop runs)."""
FIFO_BYTES = 4 * 1024 * 1024
"""Payload bytes one sender may have waiting in one FIFO."""
SAMPLE_RATE = 1000.0
SAMPLE_BURST = 2048.0
"""Samples one sender may hand one bulk subscription per second (and at once): beyond, the
callback drops them before copying or decoding (``over_rate``). Honest peers send a few per
round (a few hundred per second at the fastest lockstep rounds) and an episode's experience
at once; a flood is cut to this rate at every receiver."""


class SenderQueues(Generic[I]):
    """Per-sender bounded FIFOs served round robin. ``push`` is called from Zenoh threads,
    ``pop`` from the loop; one lock guards both (held for a few dict/deque operations).
    Each sender may have ``per_sender`` items and ``max_bytes`` bytes waiting."""

    def __init__(
        self,
        per_sender: int,
        max_senders: int = MAX_SENDERS,
        max_bytes: int = FIFO_BYTES,
        *,
        rate: float | None = None,
        burst: float = SAMPLE_BURST,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if per_sender < 1:
            raise ValueError(f"per_sender must be >= 1, got {per_sender}")
        self.per_sender = per_sender
        self.max_senders = max_senders
        self.max_bytes = max_bytes
        self.rate = rate
        self.burst = burst
        self._clock = clock
        self._gate: dict[Hashable, tuple[float, float]] = {}  # sender -> (tokens, stamp)
        self._bytes: dict[Hashable, int] = {}
        self._queues: dict[Hashable, deque[tuple[I, int]]] = {}
        self._turn: deque[Hashable] = deque()  # senders with something queued, in turn
        self._lock = threading.Lock()
        self.size = 0

    def admit(self, sender: Hashable) -> bool:
        """Whether ``sender`` is within its sample rate (always, without one); spends one.
        Called by the callback before it copies the payload."""
        if self.rate is None:
            return True
        now = self._clock()
        with self._lock:
            tokens, stamp = self._gate.get(sender, (self.burst, now))
            tokens = min(self.burst, tokens + (now - stamp) * self.rate)
            if len(self._gate) >= self.max_senders and sender not in self._gate:
                self._gate.clear()  # bounded: forgetting only gives a fresh burst
            if tokens < 1.0:
                self._gate[sender] = (tokens, now)
                return False
            self._gate[sender] = (tokens - 1.0, now)
            return True

    def push(self, sender: Hashable, item: I, nbytes: int = 0) -> str | None:
        """Queue ``item`` (``nbytes`` long); None if queued, else why it was dropped."""
        with self._lock:
            q = self._queues.get(sender)
            if q is None:
                if len(self._queues) >= self.max_senders:
                    return "intake_senders"
                q = self._queues[sender] = deque()
                self._bytes[sender] = 0
                self._turn.append(sender)
            elif len(q) >= self.per_sender or self._bytes[sender] + nbytes > self.max_bytes:
                return "intake_full"
            q.append((item, nbytes))
            self._bytes[sender] += nbytes
            self.size += 1
            return None

    def pop(self) -> I | None:
        """The next item in round-robin order over senders, or None when empty."""
        with self._lock:
            if not self._turn:
                return None
            sender = self._turn.popleft()
            q = self._queues[sender]
            item, nbytes = q.popleft()
            self.size -= 1
            if q:
                self._bytes[sender] -= nbytes
                self._turn.append(sender)
            else:
                del self._queues[sender], self._bytes[sender]
            return item

    def clear(self) -> None:
        with self._lock:
            self._queues.clear()
            self._bytes.clear()
            self._turn.clear()
            self.size = 0

    def __len__(self) -> int:
        return self.size


@dataclass(frozen=True)
class BudgetLimits:
    """Verifications one signer may cost this process: ``per_round`` for every round the
    owner announces, ``per_s`` for every second, at most ``burst`` saved up (a full bucket
    at start). ``per_s`` is what receivers that know no round live on (the Commander, an
    observer): a UAV's reports at the fastest lockstep rounds measured (about 80 rounds/s
    secured, 3 UAVs in-process) stay well under it; an attacker gets at most that many
    verifications (about 15-20 ms of CPU) per second from each receiver."""

    per_round: float = 16.0
    per_s: float = 256.0
    burst: float = 512.0


class VerifyBudget:
    """Token buckets of signature verifications, one per signer (loop side only)."""

    def __init__(
        self, limits: BudgetLimits | None = None, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.limits = limits or BudgetLimits()
        self._clock = clock
        self._tokens: dict[str, float] = {}
        self._stamp: dict[str, float] = {}
        self._rounds = 0  # rounds announced so far
        self._seen_rounds: dict[str, int] = {}
        self._empty_until: dict[str, float] = {}  # signer -> when its next token is due
        self.spent = 0
        self.refused = 0

    def note_round(self) -> None:
        """A round started: every signer's bucket gains ``per_round`` (lazily)."""
        self._rounds += 1
        self._empty_until = {}

    def exhausted(self, signer: str) -> bool:
        """Whether ``signer``'s bucket is certainly still empty (thread-safe read): Zenoh's
        callback drops such a sample at once, before queueing or decoding it."""
        until = self._empty_until.get(signer)
        return until is not None and self._clock() < until

    def take(self, signer: str) -> bool:
        """Spend one verification of ``signer``'s; False (counted) when over budget."""
        lim, now = self.limits, self._clock()
        tokens = self._tokens.get(signer)
        if tokens is None:
            tokens = lim.burst
        else:
            tokens += (now - self._stamp[signer]) * lim.per_s
            tokens += (self._rounds - self._seen_rounds[signer]) * lim.per_round
            tokens = min(tokens, lim.burst)
        self._stamp[signer] = now
        self._seen_rounds[signer] = self._rounds
        if tokens < 1.0:
            self._tokens[signer] = tokens
            self.refused += 1
            if lim.per_s > 0:
                self._empty_until[signer] = now + (1.0 - tokens) / lim.per_s
            return False
        self._tokens[signer] = tokens - 1.0
        self.spent += 1
        return True


SIZE_LIMIT_BYTES = MAX_PAYLOAD_BYTES + 1024
"""What zenoh's ``low_pass_filter`` lets through: our payload cap plus the signature
attachment and headroom. Nothing we publish is larger."""


def low_pass_filter(size_limit: int = SIZE_LIMIT_BYTES) -> list[dict[str, Any]]:
    """Zenoh's size interceptor as a config entry (path ``low_pass_filter``): a router that
    loads it drops oversize messages for all its clients before they reach any process.
    Meant for ``mesh.zenoh_settings`` (and so for the configs ``keys init`` renders);
    ``mesh.py`` drops oversize samples in its callbacks either way."""
    return [
        {
            "id": "aeroweaver-size",
            "flows": ["ingress", "egress"],
            "messages": ["put", "delete", "query", "reply"],
            "key_exprs": ["**"],
            "size_limit": size_limit,
        }
    ]


__all__ = [
    "FIFO_BYTES",
    "FIFO_MIN",
    "MAX_SENDERS",
    "SAMPLE_BURST",
    "SAMPLE_RATE",
    "SIZE_LIMIT_BYTES",
    "BudgetLimits",
    "SenderQueues",
    "VerifyBudget",
    "low_pass_filter",
]
