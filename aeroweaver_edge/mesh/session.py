"""An asyncio facade over one zenoh-python 1.10 session.

zenoh-python has no asyncio API, so every zenoh callback here does exactly one thing: hand
its data to the event loop with ``call_soon_threadsafe``. Decoding, validation and query
replies run on the loop, where exceptions are visible and no zenoh thread is held up.

Callbacks are registered with ``indirect=False``: they run on zenoh's RX thread instead of a
per-entity Python thread. That keeps the wire order of one link across *all* our
subscriptions (a peer's liveliness token is seen before its first message), spawns no
non-daemon threads (no exit hang) and costs nothing that matters at swarm-control rates,
because the callback is trivial. Opening, undeclaring and closing can block for up to a
second, so they run in worker threads; ``put`` and issuing a ``get`` do not block (see
docs/notes/zenoh.md) and stay on the loop so the order of our own puts is kept.

With ``[mesh.security]`` the session runs TLS with mutual authentication and the ACL built
from the swarm's identity list, every payload we publish (puts and query replies) carries
an Ed25519 signature in its attachment, and every payload we receive must carry a valid
one by an author allowed to write its key; anything else is counted and dropped here,
before any handler sees it (see ``security/``).

Receiving under a flood (``intake.py``): a callback only checks the size (and, secured, that
an attachment names a known key id), then puts the sample in its subscription's per-sender
FIFO (bounded, round robin, full = dropped and counted, never blocking) and wakes the loop
at most once per batch. The loop serves *control* subscriptions (liveliness, the world's
perceptions and commands, the Commander's keys) completely first, then at most
``BULK_BATCH`` *bulk* samples (peer messages, beacons, experience, reports) before giving
the loop back, so a flood of broadcasts can delay neither a liveliness change nor a round.
Before any decoding or crypto a signed payload must carry a known key id allowed to write
its key; after decoding, its claimed sender must own that key and the subscription's own
cheap checks (``precheck``: roster, round window, epoch) must pass; only then is one
verification spent from the signer's budget (``VerifyBudget``); over budget is dropped and
counted as ``over_budget``.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import json
import logging
import os
from collections.abc import AsyncIterator, Callable
from types import TracebackType
from typing import Any, Generic, Protocol, Self, TypeVar

import msgspec
import zenoh

from aeroweaver_edge.config import ConfigError, MeshConfig
from aeroweaver_edge.contracts.wire import MAX_PAYLOAD_BYTES, Codec, traffic_lane, writer_of
from aeroweaver_edge.mesh.intake import (
    FIFO_MIN,
    SAMPLE_RATE,
    BudgetLimits,
    SenderQueues,
    VerifyBudget,
    low_pass_filter,
)
from aeroweaver_edge.mesh.link_timeout import LinkTimeouts
from aeroweaver_edge.security.key_files import PkiError
from aeroweaver_edge.security.signing import ATTACHMENT_BYTES
from aeroweaver_edge.security.signing import VERSION as SIGNING_VERSION
from aeroweaver_edge.security.transport import (
    LoadedSecurity,
    load_security,
    zenoh_security_settings,
)

log = logging.getLogger(__name__)

T = TypeVar("T", bound=msgspec.Struct)
I = TypeVar("I")  # noqa: E741 - item type of a Stream

Lane = str  # "control" (served first, completely) or "bulk" (served in batches)
CONTROL_SENDERS = 4096
"""Writers the control FIFO tracks at once (a token flood of distinct names included)."""
CONTROL_PER_SENDER = 1024
"""Control items one writer may have waiting."""
CONTROL_BATCH = 1024
"""Control items handled per turn of the loop (all of them but under a flood of its own)."""
BULK_BATCH = 64
"""Bulk samples handled per turn of the loop before other ready work runs."""
MAX_REPLIES = 1024
"""Replies one ``get`` keeps (more are dropped and counted: a reply flood cannot grow it)."""
MAX_QUERIES = 64
"""Queries waiting for an answer per queryable (more are ended unanswered, counted)."""

LivelinessEvent = tuple[str, bool]
"""``(key, alive)``: True when a token appeared (PUT), False when it went away (DELETE)."""


class MeshError(RuntimeError):
    """The zenoh session could not be opened or used."""

    def explain(self) -> tuple[int, str]:
        text = str(self)
        if "already in use" in text.lower():
            return 2, (
                f"a listen endpoint is already in use ({text}); choose a free port in "
                "mesh.listen / --listen, or stop the process that holds it"
            )
        return 2, f"{text}; check mesh.listen, mesh.connect and mesh.namespace"


class MeshClosed(MeshError):
    """The mesh (or this subscription) was closed."""


class _Undeclarable(Protocol):
    def undeclare(self) -> Any: ...


class _Closable(Protocol):
    def close(self) -> Any: ...


class _Closed(enum.Enum):
    TOKEN = enum.auto()


_CLOSED = _Closed.TOKEN


def load_mesh_security(cfg: MeshConfig) -> LoadedSecurity | None:
    """Read and check ``cfg.security``'s files (blocking file IO: call off the loop)."""
    if cfg.security is None:
        return None
    try:
        return load_security(cfg.security, cfg.namespace)
    except PkiError as exc:
        raise ConfigError(f"mesh.security: {exc}") from None


def zenoh_settings(cfg: MeshConfig, security: LoadedSecurity | None) -> list[tuple[str, Any]]:
    """Every zenoh config entry we set, as (path, value); ``keys init`` renders the same
    list into a JSON5 file, so a generated config is exactly what a daemon would open."""
    settings: list[tuple[str, Any]] = [
        ("mode", cfg.mode),
        ("listen/endpoints", cfg.listen),
        ("connect/endpoints", cfg.connect),
        (
            "connect/retry",
            {"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2},
        ),
        ("scouting/multicast/enabled", cfg.multicast),
        ("scouting/gossip/enabled", cfg.gossip),
        ("scouting/delay", 100),
        ("transport/link/tx/lease", cfg.lease_ms),
        # zenoh #2628: SHM watchdog race loses query replies under load; our payloads are small.
        ("transport/shared_memory/enabled", False),
    ]
    if cfg.namespace:
        settings.append(("namespace", cfg.namespace))
    if security is not None:
        settings.extend(zenoh_security_settings(security))
        # Oversize messages die at the first secured hop (a router drops them for every
        # client), before any process copies or verifies them.
        settings.append(("low_pass_filter", low_pass_filter()))
    return settings


def build_zenoh_config(cfg: MeshConfig, security: LoadedSecurity | None = None) -> zenoh.Config:
    """Translate a MeshConfig into a zenoh Config (overrides last; a bad one names its key).
    A secured config loads its key material here unless ``security`` is given."""
    if security is None and cfg.security is not None:
        security = load_mesh_security(cfg)
    conf = zenoh.Config()
    names = {"listen/endpoints": "mesh.listen", "connect/endpoints": "mesh.connect",
             "namespace": "mesh.namespace"}  # fmt: skip
    for path, value in zenoh_settings(cfg, security):
        try:
            conf.insert_json5(path, json.dumps(value))
        except (zenoh.ZError, TypeError, ValueError) as exc:
            raise ConfigError(f"{names.get(path, path)} = {value!r}: {_zerror_text(exc)}") from None
    for path, text in cfg.zenoh_overrides.items():
        try:
            conf.insert_json5(path, text)
        except (zenoh.ZError, TypeError, ValueError) as exc:
            raise ConfigError(
                f"mesh.zenoh_overrides[{path!r}] = {text!r}: {_zerror_text(exc)}"
            ) from None
    return conf


def _zerror_text(exc: Exception) -> str:
    """A ZError's message without the Rust source location and JSON5 wrapping zenoh adds."""
    text = str(exc)
    inner = text.split('msg: "', 1)
    if len(inner) == 2:  # Json5Err(Message { msg: "<the message> at /src/...", ... })
        text = inner[1]
    return text.split(" at /", 1)[0].strip().rstrip('"')


ZENOH_RUNTIME_ENV = "ZENOH_RUNTIME"
RX_WORKERS = 8
"""Zenoh RX worker threads per process (zenoh's own default is 2).

Zenoh 1.10 sets SO_LINGER = 10 s on its TCP and TLS links and, when a link's lease expires,
closes it from a task on the RX runtime. A peer that went silent (a radio partition: no FIN,
no RST) always leaves unacknowledged bytes queued (at least keep-alives), so that close(2)
blocks its RX worker thread in the kernel for up to 10 s (zenoh #1101, #2718). With the
default two workers, two peers going silent together block both, and the session (for a
router: every client's traffic) hears nothing for 10 s. Measured in
``tests/aeroweaver_edge/orchestration/test_netns_faults.py`` (docs/reliability.md). With
``RX_WORKERS`` workers, up to ``RX_WORKERS - 1`` links dying silently within 10 s leave a
worker for the live ones. An operator's own ``ZENOH_RUNTIME`` is left as it is. The cure is
``link_timeout``: every TCP/TLS link gets ``TCP_USER_TIMEOUT`` = the lease, so such a close
no longer waits out the linger; the extra workers stay as the second line (a link whose
socket was not found, a platform without the option)."""

_log_initialised = False


def _init_zenoh_runtime() -> None:
    """Ask for ``RX_WORKERS`` RX threads unless the operator configured the runtime. Zenoh
    reads the variable when its runtime first starts (the process's first session), and
    spawned daemons inherit it."""
    if ZENOH_RUNTIME_ENV not in os.environ:
        os.environ[ZENOH_RUNTIME_ENV] = f"(rx: (worker_threads: {RX_WORKERS}))"


def _init_zenoh_log() -> None:
    """Zenoh logs to stdout, so only turn it on when the operator asked (RUST_LOG)."""
    global _log_initialised
    if not _log_initialised and os.environ.get("RUST_LOG"):
        zenoh.try_init_log_from_env()  # type: ignore[no-untyped-call]
        _log_initialised = True


class Declared:
    """Something declared on the session; ``aclose`` undeclares it (off the loop)."""

    lane: Lane = "control"
    _raw: SenderQueues[Any] | None = None  # what callbacks enqueued, for the loop to take

    def __init__(self, mesh: Mesh, key: str) -> None:
        self.key = key
        self._mesh = mesh
        self._entity: _Undeclarable | None = None
        self._closed = False
        self.intake_dropped = 0  # samples dropped by the callback (FIFO full, cheap checks)

    @property
    def closed(self) -> bool:
        return self._closed

    def _mark_closed(self) -> None:
        self._closed = True
        if self._raw is not None:
            self._raw.clear()

    def _take(self, item: Any) -> None:
        """Loop side: handle one item a callback enqueued."""

    async def aclose(self) -> None:
        """Undeclare; idempotent. Mesh.aclose does this for everything still declared."""
        if self._closed:
            return
        self._mark_closed()
        await self._mesh._release(self)


class Stream(Declared, Generic[I]):
    """A bounded queue of items fed from zenoh callbacks.

    When full it drops the *oldest* item (counted in ``dropped``), like zenoh's RingChannel:
    for latest-wins state and next-round messages the newest data is the useful data.
    With ``on_item`` set, items go straight to that loop-side function instead, in arrival
    order, and the queue stays empty. Before that, callbacks put what they receive in
    per-sender FIFOs of ``maxsize`` each (``intake.SenderQueues``).
    """

    def __init__(
        self,
        mesh: Mesh,
        key: str,
        maxsize: int,
        on_item: Callable[[I], object] | None,
        lane: Lane | None = None,
    ) -> None:
        super().__init__(mesh, key)
        if maxsize < 1:
            raise ValueError(f"maxsize must be >= 1, got {maxsize}")
        self.maxsize = maxsize
        self.lane = lane or traffic_lane(key)
        # bulk: a FIFO per sender of its own; control items share the mesh's (arrival order)
        self._raw = (
            SenderQueues(max(maxsize, FIFO_MIN), rate=SAMPLE_RATE) if self.lane == "bulk" else None
        )
        self.received = 0
        self.dropped = 0
        self._on_item = on_item
        self._queue: asyncio.Queue[I | _Closed] = asyncio.Queue()

    def _offer(self, item: I) -> None:
        if self._closed:
            return
        self.received += 1
        if self._on_item is not None:
            try:
                self._on_item(item)
            except Exception:
                log.exception("on_item handler for %s failed", self.key)
            return
        if self._queue.qsize() >= self.maxsize:
            self._queue.get_nowait()
            self.dropped += 1
        self._queue.put_nowait(item)

    def _take(self, item: Any) -> None:
        self._offer(item)

    def _mark_closed(self) -> None:
        if not self._closed:
            super()._mark_closed()
            self._queue.put_nowait(_CLOSED)

    async def get(self) -> I:
        """The next item; raises MeshClosed once closed and empty."""
        item = await self._queue.get()
        if item is _CLOSED:
            self._queue.put_nowait(_CLOSED)  # keep waking every other waiter
            raise MeshClosed(f"{self.key} is closed")
        return item

    def drain(self) -> list[I]:
        """Everything queued right now, without waiting."""
        out: list[I] = []
        while not self._queue.empty():
            item = self._queue.get_nowait()
            if item is _CLOSED:
                self._queue.put_nowait(_CLOSED)
                break
            out.append(item)
        return out

    def __aiter__(self) -> AsyncIterator[I]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[I]:
        while True:
            try:
                yield await self.get()
            except MeshClosed:
                return


Precheck = Callable[[str, Any], bool]
"""A subscription's own cheap checks on a decoded payload, run before its signature is
verified: False drops it (the check counts why)."""


class Subscription(Stream[tuple[str, T]], Generic[T]):
    """Decoded ``(key, msg)`` pairs; undecodable payloads are counted and skipped."""

    def __init__(
        self,
        mesh: Mesh,
        key: str,
        kind: type[T],
        maxsize: int,
        on_item: Callable[[tuple[str, T]], object] | None,
        lane: Lane | None = None,
        precheck: Precheck | None = None,
    ) -> None:
        super().__init__(mesh, key, maxsize, on_item, lane)
        self.kind = kind
        self.precheck = precheck
        self.undecodable = 0

    def _take(self, item: Any) -> None:
        self._deliver(*item)

    def _deliver(self, key: str, data: bytes, attachment: bytes | None) -> None:
        if self._closed:
            return
        msg = self._mesh._accept(key, data, attachment, self.kind, self.precheck)
        if msg is None:
            self.undecodable += 1
            return
        self._offer((key, msg))


class LivelinessWatch(Stream[LivelinessEvent]):
    """``(key, alive)`` events for liveliness tokens, starting with those already alive.
    Always on the control lane: a flood of data never delays who is alive."""


class Queryable(Declared):
    """Answers queries on one concrete key with the provider's latest value. The signed
    reply is made once per value (a query flood costs no signatures), and at most
    ``MAX_QUERIES`` queries wait; more are ended unanswered."""

    def __init__(self, mesh: Mesh, key: str, provider: Callable[[], msgspec.Struct | None]) -> None:
        super().__init__(mesh, key)
        self.lane = "bulk"
        self._raw = SenderQueues(MAX_QUERIES)
        self._provider = provider
        self._signed: tuple[msgspec.Struct, bytes, bytes | None] | None = None
        self.answered = 0

    def _take(self, item: Any) -> None:
        self._answer(item)

    def _answer(self, query: zenoh.Query) -> None:
        try:
            if not self._closed:
                value = self._provider()
                if value is not None:
                    cached = self._signed
                    if cached is None or cached[0] is not value:
                        data = self._mesh.codec.encode(value)
                        cached = self._signed = (
                            value,
                            data,
                            self._mesh._sign(self.key, value, data),
                        )
                    query.reply(self.key, cached[1], attachment=cached[2])
                    self.answered += 1
        except Exception:
            log.exception("queryable %s failed to answer", self.key)
        finally:
            # Ends the querier's get now instead of at its timeout.
            query.drop()  # type: ignore[no-untyped-call]


class Mesh:
    """One zenoh session with asyncio-friendly declarations. Create with ``await Mesh.open``."""

    def __init__(
        self,
        session: zenoh.Session,
        *,
        node_id: str,
        codec: Codec,
        loop: asyncio.AbstractEventLoop,
        security: LoadedSecurity | None = None,
        budget: BudgetLimits | None = None,
    ) -> None:
        self.node_id = node_id
        self.codec = codec
        self.security = security
        self._auth = security.auth if security is not None else None
        self._session = session
        self._loop = loop
        self._declared: list[Declared] = []
        self._link_timeouts: LinkTimeouts | None = None
        self._closing: asyncio.Future[None] | None = None
        self.budget = VerifyBudget(budget)
        self._intakes: dict[Lane, list[Declared]] = {"control": [], "bulk": []}
        # One FIFO per writer for every control subscription together, so one writer's
        # items keep their wire order across subscriptions (a Commander's token is seen
        # before its assignment) while a flooding writer waits behind its own backlog.
        self._control: SenderQueues[tuple[Declared, Any]] = SenderQueues(
            CONTROL_PER_SENDER, CONTROL_SENDERS
        )
        self._scheduled = False  # a _pump is on its way to the loop
        self._turn = 0  # which bulk intake goes first in the next batch

    @classmethod
    async def open(cls, cfg: MeshConfig, *, node_id: str, codec: Codec | None = None) -> Mesh:
        """Open a session in a worker thread (zenoh.open blocks up to scouting.delay)."""
        _init_zenoh_log()
        _init_zenoh_runtime()
        if cfg.security is not None and cfg.security.identity != node_id:
            raise ConfigError(
                f"mesh.security.identity is {cfg.security.identity!r} but this node is {node_id!r}"
            )
        security = await asyncio.to_thread(load_mesh_security, cfg)
        conf = build_zenoh_config(cfg, security)
        try:
            session = await asyncio.to_thread(zenoh.open, conf)
        except zenoh.ZError as exc:
            raise MeshError(
                f"{node_id}: cannot open zenoh session (mode={cfg.mode}, listen={cfg.listen}, "
                f"connect={cfg.connect}): {_zerror_text(exc)}"
            ) from None
        log.debug("%s: zenoh session %s open", node_id, session.zid())
        loop = asyncio.get_running_loop()
        mesh = cls(session, node_id=node_id, codec=codec or Codec(), loop=loop, security=security)
        # A link that dies silently must not block a zenoh RX thread for SO_LINGER's 10 s.
        mesh._link_timeouts = LinkTimeouts(session, cfg.lease_ms, node_id)
        return mesh

    @property
    def session(self) -> zenoh.Session:
        """The raw session, for what this facade does not cover (tests, diagnostics)."""
        return self._session

    @property
    def closed(self) -> bool:
        return self._closing is not None

    @property
    def authenticated(self) -> bool:
        """True if every payload this mesh delivers carried a valid signature by an author
        allowed to write its key (so its header, including the epoch, is authentic)."""
        return self._auth is not None

    def security_summary(self) -> dict[str, Any]:
        """``{"tls", "acl", "signed", ...}`` for run summaries (all False when insecure)."""
        if self.security is None:
            return {"tls": False, "mtls": False, "acl": False, "signed": False}
        return self.security.summary

    def _sign(self, key: str, msg: msgspec.Struct | None, data: bytes) -> bytes | None:
        """The signature attachment for a payload we publish, or None when not signing.
        A payload claiming another sender is a bug here: receivers would refuse it."""
        if self._auth is None or self._auth.signer is None:
            return None
        sender = getattr(getattr(msg, "h", None), "sender", None)
        if msg is not None and sender != self._auth.signer.name:
            raise MeshError(
                f"{self.node_id}: refusing to sign a payload from {sender!r} as "
                f"{self._auth.signer.name!r}"
            )
        return self._auth.signer.sign(key, data)

    def _accept(
        self,
        key: str,
        data: bytes,
        attachment: bytes | None,
        kind: type[T],
        precheck: Precheck | None = None,
    ) -> T | None:
        """Cheap checks first, then decode, the subscription's ``precheck``, the signer's
        budget and, last, the signature (when secured)."""
        auth = self._auth
        if auth is None:
            msg = self.codec.decode(data, kind, key)
            if msg is not None and precheck is not None and not precheck(key, msg):
                return None
            return msg
        verifier = auth.verifier
        signer, why = verifier.signer_of(attachment)
        if why is not None or signer is None or attachment is None:
            self.codec.stats.reject(why or "unsigned", key)
            return None
        msg = self.codec.decode(data, kind, key)
        if msg is None:
            return None
        sender = getattr(getattr(msg, "h", None), "sender", "")
        if sender != signer:
            why = "wrong_key" if sender in verifier.identities.members else "unknown_signer"
            self.codec.stats.reject(why, key, f"claimed sender {sender!r}, key of {signer!r}")
            return None
        if not verifier.may_write(signer, key):
            self.codec.stats.reject("unauthorised_signer", key, f"signer {signer!r}")
            return None
        if precheck is not None and not precheck(key, msg):
            return None
        if not self.budget.take(signer):
            self.codec.stats.reject("over_budget", key, f"signer {signer!r}")
            return None
        why = verifier.verify(key, data, attachment, signer)
        if why is not None:
            self.codec.stats.reject(why, key, f"claimed sender {sender!r}")
            return None
        return msg

    def note_round(self) -> None:
        """A round started here: every signer's verification budget gains its per-round
        share (``intake.BudgetLimits``)."""
        self.budget.note_round()

    # -- intake: zenoh threads -> loop ------------------------------------------------------

    def _sender_of(self, key: str, attachment: bytes | None) -> tuple[str, str | None]:
        """Thread side: whose FIFO a sample goes to, or why it is dropped at once. Secured:
        the identity whose key id a well-formed attachment names; else the key's writer
        by the key layout (``wire.writer_of``)."""
        if self._auth is None:
            return writer_of(key), None
        if not attachment:
            return "", "unsigned"
        if len(attachment) != ATTACHMENT_BYTES or attachment[0] != SIGNING_VERSION:
            return "", "bad_attachment"
        signer = self._auth.verifier.name_of_key_id(bytes(attachment[1:9]))
        if signer is None:
            return "", "wrong_key"
        if self.budget.exhausted(signer):
            return "", "over_budget"
        return signer, None

    def _enqueue(self, handle: Declared, sender: Any, item: Any, nbytes: int = 0) -> None:
        """Thread side: queue ``item`` in ``handle``'s FIFO for ``sender``; drop and count
        when full (never block, never raise); wake the loop once per batch."""
        if handle._closed:
            return
        raw = handle._raw
        if raw is None:
            why = self._control.push(sender, (handle, item), nbytes)
        else:
            why = raw.push(sender, item, nbytes)
        if why is not None:
            self._dropped(handle, why)
            if isinstance(handle, Queryable):
                with contextlib.suppress(Exception):
                    item.drop()
            return
        if not self._scheduled:
            self._scheduled = True
            self._to_loop(self._pump)

    def _dropped(self, handle: Declared, why: str) -> None:
        handle.intake_dropped += 1
        self.codec.stats.reject(why, handle.key)

    def _pump(self) -> None:
        """Loop side: every control item, then one batch of bulk items (round robin over
        bulk intakes and, inside each, over senders); reschedules itself while work is left
        so other loop work runs between batches."""
        self._scheduled = False
        for _ in range(CONTROL_BATCH):
            entry = self._control.pop()
            if entry is None:
                break
            if not entry[0]._closed:
                self._take(*entry)
        bulk = [h for h in self._intakes["bulk"] if h._raw]
        budget = BULK_BATCH
        if bulk:
            self._turn = (self._turn + 1) % len(bulk)
            order = bulk[self._turn :] + bulk[: self._turn]
            while budget > 0 and order:
                for handle in list(order):
                    raw = handle._raw
                    item = raw.pop() if raw is not None else None
                    if item is None:
                        order.remove(handle)
                        continue
                    self._take(handle, item)
                    budget -= 1
        left = len(self._control) > 0 or any(h._raw for h in self._intakes["bulk"])
        if left and not self._scheduled and self._closing is None:
            self._scheduled = True
            self._loop.call_soon(self._pump)

    def _take(self, handle: Declared, item: Any) -> None:
        try:
            handle._take(item)
        except Exception:
            log.exception("%s: handling a sample on %s failed", self.node_id, handle.key)

    def _check_open(self) -> None:
        if self._closing is not None:
            raise MeshClosed(f"{self.node_id}: mesh is closed")

    def _to_loop(self, fn: Callable[..., None], *args: Any) -> None:
        """The one thing a zenoh callback may do: schedule work on the loop."""
        with contextlib.suppress(RuntimeError):  # loop closed: the mesh is going away anyway
            self._loop.call_soon_threadsafe(fn, *args)

    def _register(self, handle: Declared, entity: _Undeclarable) -> None:
        handle._entity = entity
        self._declared.append(handle)

    def _add_intake(self, handle: Declared) -> None:
        """Before declaring: the callback may fire as soon as the entity exists."""
        self._intakes.setdefault(handle.lane, []).append(handle)

    # -- publishing -------------------------------------------------------------------------

    def put(self, key: str, msg: msgspec.Struct, *, block: bool = False) -> None:
        """Encode and publish. DROP congestion control unless ``block`` (important, low rate)."""
        self._check_open()
        data = self.codec.encode(msg)
        self._put(key, data, self._sign(key, msg, data), block)

    def put_bytes(self, key: str, data: bytes, *, block: bool = False) -> None:
        """Publish pre-encoded bytes (signed as they are when this mesh signs)."""
        self._check_open()
        self._put(key, data, self._sign(key, None, data), block)

    def _put(self, key: str, data: bytes, attachment: bytes | None, block: bool) -> None:
        cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        if attachment is None:
            self._session.put(key, data, congestion_control=cc)
        else:
            self._session.put(key, data, congestion_control=cc, attachment=attachment)

    # -- subscribing ------------------------------------------------------------------------

    def subscribe(
        self,
        key_expr: str,
        kind: type[T],
        *,
        maxsize: int = 1024,
        on_item: Callable[[tuple[str, T]], object] | None = None,
        lane: Lane | None = None,
        precheck: Precheck | None = None,
    ) -> Subscription[T]:
        """Subscribe to ``key_expr``, decoding payloads as ``kind`` on the loop. ``lane``
        defaults by key (``wire.traffic_lane``); ``maxsize`` bounds the decoded queue and
        each sender's FIFO; ``precheck`` runs before the signature is verified."""
        self._check_open()
        sub: Subscription[T] = Subscription(self, key_expr, kind, maxsize, on_item, lane, precheck)

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                key = str(sample.key_expr)
                if len(sample.payload) > MAX_PAYLOAD_BYTES:
                    self._dropped(sub, "oversize")
                    return
                att = sample.attachment
                attachment = att.to_bytes() if att is not None else None
                sender, why = self._sender_of(key, attachment)
                if why is None and sub._raw is not None and not sub._raw.admit(sender):
                    why = "over_rate"
                if why is not None:
                    self._dropped(sub, why)
                    return
                data = sample.payload.to_bytes()
                self._enqueue(sub, sender, (key, data, attachment), len(data))
            except Exception:  # never into zenoh's thread: counted, the sample dropped
                self._dropped(sub, "intake_error")

        self._add_intake(sub)
        handler = zenoh.handlers.Callback(on_sample, indirect=False)
        self._register(sub, self._session.declare_subscriber(key_expr, handler))
        return sub

    def watch_liveliness(
        self,
        key_expr: str,
        *,
        maxsize: int = 1024,
        on_item: Callable[[LivelinessEvent], object] | None = None,
    ) -> LivelinessWatch:
        """Liveliness PUT/DELETE events as ``(key, alive)``, with tokens already alive first."""
        self._check_open()
        watch = LivelinessWatch(self, key_expr, maxsize, on_item, "control")

        def on_sample(sample: zenoh.Sample) -> None:
            key = str(sample.key_expr)
            self._enqueue(watch, writer_of(key), (key, sample.kind == zenoh.SampleKind.PUT))

        self._add_intake(watch)
        handler = zenoh.handlers.Callback(on_sample, indirect=False)
        sub = self._session.liveliness().declare_subscriber(key_expr, handler, history=True)
        self._register(watch, sub)
        return watch

    def declare_token(self, key: str) -> Declared:
        """A liveliness token: peers see it until ``aclose`` or the session goes away."""
        self._check_open()
        handle = Declared(self, key)
        self._register(handle, self._session.liveliness().declare_token(key))
        return handle

    # -- queries ----------------------------------------------------------------------------

    def declare_queryable(
        self, key: str, provider: Callable[[], msgspec.Struct | None]
    ) -> Queryable:
        """Serve ``provider()`` on the concrete ``key``; ``None`` means no reply."""
        self._check_open()
        if "*" in key or "$" in key:
            raise ValueError(f"queryable key must be concrete (replies use it): {key!r}")
        queryable = Queryable(self, key, provider)

        def on_query(query: zenoh.Query) -> None:
            self._enqueue(queryable, "q", query)

        self._add_intake(queryable)
        handler = zenoh.handlers.Callback(on_query, indirect=False)
        self._register(queryable, self._session.declare_queryable(key, handler))
        return queryable

    async def get(
        self, selector: str, kind: type[T], timeout_s: float = 1.0
    ) -> list[tuple[str, T]]:
        """Query every matching queryable; returns decoded replies (bad ones skipped)."""
        self._check_open()
        raw: list[tuple[str, bytes, bytes | None]] = []
        done: asyncio.Future[None] = self._loop.create_future()

        def finish() -> None:
            if not done.done():
                done.set_result(None)

        taken = [0]  # replies handed to the loop (counted thread side: raw grows later)

        def on_reply(reply: zenoh.Reply) -> None:
            sample = reply.ok
            if sample is not None and len(sample.payload) <= MAX_PAYLOAD_BYTES:
                taken[0] += 1
                if taken[0] > MAX_REPLIES:
                    return
                att = sample.attachment
                item = (
                    str(sample.key_expr),
                    sample.payload.to_bytes(),
                    att.to_bytes() if att is not None else None,
                )
                self._to_loop(raw.append, item)

        def on_done() -> None:
            self._to_loop(finish)

        self._session.get(
            selector,
            zenoh.handlers.Callback(on_reply, on_done, indirect=False),
            target=zenoh.QueryTarget.ALL,
            timeout=timeout_s,
        )
        # zenoh ends the query itself at timeout_s; the margin only guards a lost on_done.
        await asyncio.wait({done}, timeout=timeout_s + 0.5)
        out: list[tuple[str, T]] = []
        for key, data, attachment in raw:
            msg = self._accept(key, data, attachment, kind)
            if msg is not None:
                out.append((key, msg))
        return out

    # -- closing ----------------------------------------------------------------------------

    async def _release(self, handle: Declared) -> None:
        """Undeclare one handle (already marked closed) in a worker thread."""
        if handle in self._declared:
            self._declared.remove(handle)
        lane = self._intakes.get(handle.lane, [])
        if handle in lane:
            lane.remove(handle)
        entity, handle._entity = handle._entity, None
        if entity is not None and self._closing is None:
            await asyncio.to_thread(_undeclare_all, [entity])

    async def aclose(self) -> None:
        """Undeclare everything (tokens first) and close the session; idempotent."""
        if self._closing is None:
            handles, self._declared = self._declared, []
            # Tokens (plain Declared) first, so peers see us leave before our subscriptions go.
            handles.sort(key=lambda h: isinstance(h, (Stream, Queryable)))
            entities = []
            for handle in handles:
                handle._mark_closed()  # wakes waiters; late callbacks are ignored
                if handle._entity is not None:
                    entities.append(handle._entity)
                    handle._entity = None
            guard, self._link_timeouts = self._link_timeouts, None
            self._closing = asyncio.ensure_future(self._close(guard, entities))
            self._closing.add_done_callback(lambda _: log.debug("%s: closed", self.node_id))
        await asyncio.shield(self._closing)

    async def _close(self, guard: LinkTimeouts | None, entities: list[_Undeclarable]) -> None:
        if guard is not None:
            await guard.aclose()
        await asyncio.to_thread(_undeclare_all, entities, self._session)

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.aclose()


def _undeclare_all(entities: list[_Undeclarable], session: _Closable | None = None) -> None:
    """Worker-thread side of closing: undeclare may wait for in-flight callbacks."""
    try:
        for entity in entities:
            try:
                entity.undeclare()
            except zenoh.ZError as exc:
                log.debug("undeclare failed: %s", exc)
    finally:
        if session is not None:
            session.close()
