"""Persistence of experience memory: the SQLite file, its schema, migration, quarantine,
transactions and failure policy (agent.memory).

One SQLite file per daemon in WAL mode (``path=None``: in-memory). ``schema_version`` and
``meta`` (tokeniser version, gamma) let a later release migrate or rebuild; a version-1
file (no run column) is migrated in place, its rows under run ``LEGACY_RUN``; a file from a
newer release is refused, never rewritten. ``PRAGMA integrity_check`` runs at open; a
corrupt or foreign file is renamed aside (``<name>.corrupt-<utc>``) and a fresh one is
created. Every write is one ``BEGIN IMMEDIATE`` transaction (``Store.tx``), or one per
``Store.batch`` of writes, so a write commits whole or not at all and a concurrent writer
waits on ``BUSY_TIMEOUT_S`` instead of failing. ``required`` turns an unusable file or a
failed write of our own experience into ``MemoryUnavailable``; otherwise the store falls
back to RAM (unusable file) or logs, counts and drops the write (``Store.guard``).
"""

from __future__ import annotations

import contextlib
import logging
import math
import sqlite3
import time
import uuid
from collections.abc import Callable, Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Final, Literal, TypeVar

from aeroweaver_edge.agent.memory.returns import recompute_returns
from aeroweaver_edge.agent.state_tokens import TOKENIZER_VERSION, tokenise

log = logging.getLogger("aeroweaver_edge.agent.memory.experience")

SCHEMA_VERSION: Final = 2
LEGACY_RUN: Final = "v1"  # run of the rows migrated from a version-1 file
BUSY_TIMEOUT_S: Final = 10.0  # a concurrent writer waits this long for the write lock

T = TypeVar("T")


class MemoryUnavailable(RuntimeError):
    """The experience memory cannot be opened or written, and it is required.

    ``during`` is ``"open"`` (start-up: a configuration or environment problem) or
    ``"write"`` (a write failed mid-run: disk full, read-only, I/O error)."""

    def __init__(self, message: str, *, during: Literal["open", "write"]) -> None:
        super().__init__(message)
        self.during = during

    def explain(self) -> tuple[int, str]:
        if self.during == "open":
            return 2, (
                f"{self}; choose a writable --memory-dir / agent.memory_path, or set "
                "agent.memory_required = false to fly without persistent memory"
            )
        return 1, f"{self}; the daemon held and stopped (agent.memory_required = true)"


def new_run_id() -> str:
    """A sortable, unique run identity: ``<UTC time>-<8 hex>``."""
    return datetime.now(UTC).strftime("%Y%m%dT%H%M%S") + "-" + uuid.uuid4().hex[:8]


_META = """
CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL) WITHOUT ROWID;
"""

_TABLES = """
CREATE TABLE IF NOT EXISTS records (
    seq           INTEGER PRIMARY KEY AUTOINCREMENT,  -- created order: the recency tie-break
    run           TEXT    NOT NULL,                   -- writer's run identity
    task          TEXT    NOT NULL,
    role          TEXT    NOT NULL,
    uav           TEXT    NOT NULL,
    episode       INTEGER NOT NULL,
    round         INTEGER NOT NULL,
    state_text    TEXT    NOT NULL,
    tokens        TEXT    NOT NULL,                   -- space-joined token set
    skill         TEXT    NOT NULL,
    invocation    TEXT    NOT NULL,
    reward        REAL,                               -- r_t as delivered, unchanged
    ret           REAL,                               -- G_t so far; NULL until rewarded
    final         INTEGER NOT NULL DEFAULT 0,
    origin        TEXT    NOT NULL DEFAULT '',        -- '' = appended here, else peer sender
    reward_source TEXT    NOT NULL DEFAULT '',
    src_epoch     INTEGER NOT NULL DEFAULT 0,         -- version of a peer's record
    src_seq       INTEGER NOT NULL DEFAULT 0,
    created_at    REAL    NOT NULL,
    UNIQUE (run, uav, episode, round)
);
CREATE INDEX IF NOT EXISTS records_by_role ON records (task, role, seq);
CREATE INDEX IF NOT EXISTS records_by_origin ON records (origin, seq);
CREATE TABLE IF NOT EXISTS rewards (
    run     TEXT    NOT NULL,
    uav     TEXT    NOT NULL,
    episode INTEGER NOT NULL,
    round   INTEGER NOT NULL,
    reward  REAL    NOT NULL,
    source  TEXT    NOT NULL,
    PRIMARY KEY (run, uav, episode, round)
) WITHOUT ROWID;
"""

_V1_COLUMNS = (
    "seq, task, role, uav, episode, round, state_text, tokens, skill, invocation, reward, ret, "
    "final, origin, reward_source, src_epoch, src_seq, created_at"
)


class NewerSchema(Exception):
    """The file belongs to a newer release: refuse it, never rewrite or set it aside."""


class Store:
    """The open SQLite connection of one memory and what happened while opening it."""

    def __init__(
        self, path: Path | None, *, gamma: float, durable: bool = False, required: bool = False
    ) -> None:
        """``durable=True`` sets ``synchronous=FULL`` (commits survive power loss); the
        default ``NORMAL`` is crash-consistent and may lose the last commits on power loss,
        which advisory memory can afford."""
        self.path = path
        self.gamma = gamma
        self.required = required and path is not None
        self.quarantined: Path | None = None
        self.migrated_from: int | None = None  # schema version this open migrated
        self.degraded: str | None = None  # why we fell back to an in-memory database
        self.write_errors = 0
        self._last_error_log = -math.inf
        self._durable = durable
        self._batch = 0  # depth of open ``batch`` blocks: ``tx`` joins their transaction
        self.db = self._open()

    # ------------------------------------------------------------------ opening

    def _open(self) -> sqlite3.Connection:
        """A ready connection to ``path``. On an environmental failure (unwritable
        directory, read-only file system, a newer release's file, ...) raise
        ``MemoryUnavailable`` if required, else fall back to an in-memory database."""
        if self.path is not None:
            conn: sqlite3.Connection | None = None
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                problem = self._check(self.path)
                if problem is not None:
                    self._quarantine(problem)
                conn = sqlite3.connect(self.path, isolation_level=None, timeout=BUSY_TIMEOUT_S)
                self._prepare(conn)
                return conn
            except (OSError, sqlite3.Error, NewerSchema) as exc:
                if conn is not None:
                    conn.close()
                reason = str(exc) if isinstance(exc, NewerSchema) else _why(exc)
                if self.required:
                    raise MemoryUnavailable(
                        f"experience memory {self.path} cannot be used: {reason}",
                        during="open",
                    ) from None
                self.degraded = reason
                log.error(
                    "experience memory %s unusable (%s); using an in-memory database, "
                    "experience will not survive a restart",
                    self.path,
                    self.degraded,
                )
        conn = sqlite3.connect(":memory:", isolation_level=None)
        self._prepare(conn)
        return conn

    @staticmethod
    def _check(path: Path) -> str | None:
        """Why ``path`` must be set aside (corrupt, foreign), or ``None`` if it can be used.
        Raises ``NewerSchema`` for a newer release's file, which is never touched."""
        if not path.exists():
            return None
        conn = sqlite3.connect(path, isolation_level=None, timeout=BUSY_TIMEOUT_S)
        try:
            rows = conn.execute("PRAGMA integrity_check").fetchall()
            if rows != [("ok",)]:
                return "integrity_check: " + "; ".join(str(r[0]) for r in rows[:5])
            tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master")}
            if "schema_version" not in tables:
                return None if not tables else f"not an experience memory (tables {sorted(tables)})"
            row = conn.execute("SELECT max(version) FROM schema_version").fetchone()
            version = row[0] if row else None
            if version is None:
                return None  # created but never initialised (a writer died at its birth)
            if not isinstance(version, int) or version < 1:
                return f"schema version {version!r} is not valid"
            if version > SCHEMA_VERSION:
                raise NewerSchema(
                    f"schema version {version} comes from a newer release (this one reads "
                    f"up to {SCHEMA_VERSION}); use that release or another memory path"
                )
            return None
        except sqlite3.DatabaseError as exc:
            if isinstance(exc, sqlite3.OperationalError) and _transient(exc):
                raise  # locked or unreadable now: not a reason to set the file aside
            return f"{type(exc).__name__}: {exc}"
        finally:
            conn.close()

    def _quarantine(self, problem: str) -> None:
        assert self.path is not None
        stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S%fZ")
        aside = self.path.with_name(f"{self.path.name}.corrupt-{stamp}")
        self.path.rename(aside)
        for suffix in ("-wal", "-shm"):
            side = self.path.with_name(self.path.name + suffix)
            if side.exists():
                side.rename(aside.with_name(aside.name + suffix))
        self.quarantined = aside
        log.error(
            "experience memory %s is unusable (%s): quarantined as %s, starting a fresh one "
            "(memory is advisory; flight is unaffected)",
            self.path,
            problem,
            aside,
        )

    def _prepare(self, conn: sqlite3.Connection) -> None:
        """Pragmas, schema (created or migrated), and the rebuilds a changed tokeniser or
        gamma requires. Every step is a transaction, so concurrent openers agree."""
        conn.execute(f"PRAGMA busy_timeout={int(BUSY_TIMEOUT_S * 1000)}")
        mode = _enter_wal(conn)
        if mode not in ("wal", "memory"):
            log.warning("experience memory: journal mode is %s, not WAL", mode)
        conn.execute(f"PRAGMA synchronous={'FULL' if self._durable else 'NORMAL'}")
        self.db = conn
        with self.tx():
            for statement in _statements(_META):
                conn.execute(statement)
            row = conn.execute("SELECT max(version) FROM schema_version").fetchone()
            version = row[0] if row is not None else None
            if version is None:
                for statement in _statements(_TABLES):
                    conn.execute(statement)
                conn.execute("INSERT INTO schema_version VALUES (?)", (SCHEMA_VERSION,))
            elif version == 1:
                self._migrate_v1()
            elif version > SCHEMA_VERSION:  # raced with a newer release's first open
                raise NewerSchema(f"schema version {version} comes from a newer release")
            meta = dict(conn.execute("SELECT key, value FROM meta").fetchall())
            if meta.get("tokenizer") != str(TOKENIZER_VERSION):
                self._retokenise()
            if "gamma" in meta and float(meta["gamma"]) != self.gamma:
                log.info(
                    "experience memory: gamma %s -> %s, recomputing returns",
                    meta["gamma"],
                    self.gamma,
                )
                recompute_returns(conn, self.gamma)
            conn.executemany(
                "INSERT OR REPLACE INTO meta VALUES (?, ?)",
                [("tokenizer", str(TOKENIZER_VERSION)), ("gamma", repr(self.gamma))],
            )

    def _migrate_v1(self) -> None:
        """Version 1 -> 2 inside the open transaction: tables rebuilt with a ``run``
        column (SQLite cannot change a UNIQUE constraint in place); every v1 row keeps
        its values under run ``LEGACY_RUN``. Rows mixed by v1's run collisions cannot be
        told apart any more and stay as they were."""
        db = self.db
        db.execute("DROP INDEX IF EXISTS records_by_role")
        db.execute("ALTER TABLE records RENAME TO records_v1")
        db.execute("ALTER TABLE rewards RENAME TO rewards_v1")
        for statement in _statements(_TABLES):
            db.execute(statement)
        db.execute(
            f"INSERT INTO records (run, {_V1_COLUMNS}) SELECT ?, {_V1_COLUMNS} FROM records_v1",
            (LEGACY_RUN,),
        )
        db.execute(
            "INSERT INTO rewards (run, uav, episode, round, reward, source) "
            "SELECT ?, uav, episode, round, reward, source FROM rewards_v1",
            (LEGACY_RUN,),
        )
        db.execute("DROP TABLE records_v1")
        db.execute("DROP TABLE rewards_v1")
        db.execute("UPDATE schema_version SET version = ?", (SCHEMA_VERSION,))
        self.migrated_from = 1
        log.warning(
            "experience memory %s: migrated schema 1 -> %d (old rows kept under run %r)",
            self.path,
            SCHEMA_VERSION,
            LEGACY_RUN,
        )

    def _retokenise(self) -> None:
        rows = self.db.execute("SELECT seq, state_text FROM records").fetchall()
        self.db.executemany(
            "UPDATE records SET tokens = ? WHERE seq = ?",
            [(" ".join(sorted(tokenise(text))), seq) for seq, text in rows],
        )

    # ------------------------------------------------------------------ transactions

    @contextlib.contextmanager
    def tx(self) -> Iterator[None]:
        """One write transaction. IMMEDIATE takes the write lock up front, so a concurrent
        writer waits on the busy timeout instead of failing half-way (WAL cannot upgrade
        a read snapshot to a write without risking SQLITE_BUSY_SNAPSHOT). Inside ``batch``
        it joins the batch's transaction (which then commits or fails whole)."""
        if self._batch:
            yield
            return
        self.db.execute("BEGIN IMMEDIATE")
        try:
            yield
        except BaseException:
            if self.db.in_transaction:  # SQLite may already have rolled back (disk full)
                with contextlib.suppress(sqlite3.Error):
                    self.db.execute("ROLLBACK")
            raise
        self.db.execute("COMMIT")

    @contextlib.contextmanager
    def batch(self) -> Iterator[None]:
        """Many writes in one transaction: nothing of the block is acknowledged (durable)
        until it ends, then all of it at once; a failure anywhere rolls back all of it
        (``guard`` lets a database error inside a batch through to here). For bulk intake
        (a peer's backlog, a restore, the bench's fill), never for a decision that must be
        durable on return. Nested blocks join the outer one."""
        if self._batch:
            self._batch += 1
            try:
                yield
            finally:
                self._batch -= 1
            return
        self.db.execute("BEGIN IMMEDIATE")
        self._batch = 1
        try:
            yield
        except BaseException:
            self._batch = 0
            if self.db.in_transaction:
                with contextlib.suppress(sqlite3.Error):
                    self.db.execute("ROLLBACK")
            raise
        self._batch = 0
        try:
            self.db.execute("COMMIT")
        except BaseException:
            if self.db.in_transaction:
                with contextlib.suppress(sqlite3.Error):
                    self.db.execute("ROLLBACK")
            raise

    def guard(
        self, what: str, default: T, fn: Callable[[], T], *, write: bool = True, own: bool = True
    ) -> T:
        """Run a database operation; a programming error raises. An environmental failure
        of a write of our own experience raises ``MemoryUnavailable`` when the memory is
        required; otherwise (reads, which are advisory, and peers' records, ``own=False``)
        it is logged, counted and dropped."""
        try:
            return fn()
        except (sqlite3.ProgrammingError, sqlite3.IntegrityError, sqlite3.InterfaceError):
            raise
        except sqlite3.Error as exc:
            if self._batch:
                raise  # the batch fails whole: its owner applies this policy once
            if write:
                self.write_errors += 1
            if write and own and self.required:
                raise MemoryUnavailable(
                    f"experience memory {self.path}: {what} failed: {exc}", during="write"
                ) from None
            now = time.monotonic()
            if now - self._last_error_log >= 5.0:
                self._last_error_log = now
                log.error(
                    "experience memory: %s failed (%s); dropped (%d write errors so far)",
                    what,
                    exc,
                    self.write_errors,
                )
            return default

    def failed(self, what: str, exc: sqlite3.Error, *, own: bool = True) -> None:
        """``guard``'s policy for a write that already failed (a whole batch)."""

        def again() -> None:
            raise exc

        self.guard(what, None, again, own=own)

    def close(self) -> None:
        with contextlib.suppress(sqlite3.Error):
            self.db.close()


def _statements(script: str) -> list[str]:
    """Split a DDL script into statements (``executescript`` would commit on its own,
    outside our transaction). Comments may hold ';': SQLite decides where one ends."""
    out: list[str] = []
    current = ""
    for line in script.splitlines(keepends=True):
        current += line
        if sqlite3.complete_statement(current):
            out.append(current.strip())
            current = ""
    return out


def _enter_wal(conn: sqlite3.Connection) -> str:
    """Switch to WAL, retrying for ``BUSY_TIMEOUT_S``: SQLite returns SQLITE_BUSY at once,
    without the busy handler, when two processes switch a fresh file at the same moment
    (it declines to wait where waiting could deadlock), so the busy timeout alone does
    not cover the first open of a shared file."""
    deadline = time.monotonic() + BUSY_TIMEOUT_S
    pause = 0.005
    while True:
        try:
            return str(conn.execute("PRAGMA journal_mode=WAL").fetchone()[0])
        except sqlite3.OperationalError as exc:
            if not _transient(exc) or time.monotonic() >= deadline:
                raise
        time.sleep(pause)  # the open runs on a worker thread, never on the event loop
        pause = min(pause * 2, 0.1)


def _transient(exc: sqlite3.Error) -> bool:
    text = str(exc).lower()
    return "locked" in text or "busy" in text or "unable to open" in text


def _why(exc: BaseException) -> str:
    """One line for an environmental failure, with the errno text when there is one."""
    if isinstance(exc, OSError):
        return f"{exc.strerror or type(exc).__name__}: {exc.filename or ''}".rstrip(": ")
    return f"{type(exc).__name__}: {exc}"


__all__ = [
    "BUSY_TIMEOUT_S",
    "LEGACY_RUN",
    "SCHEMA_VERSION",
    "MemoryUnavailable",
    "NewerSchema",
    "Store",
    "new_run_id",
]
