"""Role-indexed experience memory (DESIGN §4 step 8 and §5).

Storage
    One SQLite file per daemon in WAL mode (``path=None``: in-memory). Every writer has a
    *run* identity (``run``: one per daemon start, or one per simulated run, shared by its
    daemons), so a second run on the same file never collides with the first: ``records``
    holds one row per decision, unique on (run, uav, episode, round); ``rewards`` holds
    every reward as delivered, unique on the same key, which makes reward delivery
    idempotent, attaches a reward only to a decision of its own run, and lets a record
    that is appended *after* its reward (or after a later reward) still get the right
    return. ``schema_version`` and ``meta`` (tokeniser version, gamma) let a later release
    migrate or rebuild; a version-1 file (no run column) is migrated in place, its rows
    under run ``"v1"``; a file from a newer release is refused, never rewritten.
    ``PRAGMA integrity_check`` runs at open; a corrupt or foreign file is renamed aside
    (``<name>.corrupt-<utc>``) and a fresh one is created.

Concurrency and failure
    Several processes may write one file: WAL, a busy timeout (``BUSY_TIMEOUT_S``) and one
    ``BEGIN IMMEDIATE`` transaction per write, so a write either commits whole or not at
    all and a concurrent writer waits instead of failing. A committed write survives a
    crash of the process (``kill -9``; see ``bench/memory_kill.py``); ``durable=True`` also
    survives power loss. ``required=True`` (the daemon's default when a path is
    configured, ``agent.memory_required``) makes an unusable file or a failed write raise
    ``MemoryUnavailable``, so the daemon says so and stops rather than silently losing
    experience; with ``required=False`` the memory falls back to RAM (unusable file) or
    logs, counts and drops the write (memory is advisory, never safety-critical).

Returns
    G_t = sum over delivered rewards r_u with u >= t of gamma^(u-t) * r_u, per trajectory
    (run, uav, episode). A record has no return (``None``) until a reward at or after its
    round arrives. Only records this memory appended itself (``origin == ""``) in its own
    run are credited by ``add_reward``; a peer's records carry the peer's own return and
    are replaced by a newer version through ``ingest``.

Retrieval (the exact algorithm of DESIGN §5)
    Exact (task, role) match; eligible records are those with a return -- by default any
    record with at least one reward, not only finalised ones. That is the paper's rule
    ("each online selection uses only reward evidence already observed before that
    decision"; returns "are extended and finalised when the trajectory ends"): with 24-round
    episodes, waiting for finalisation would leave the first episode with no correction at
    all. The price is that in-flight returns are truncated (biased towards the rewards seen
    so far); ``finalised_only=True`` gives the conservative variant. Among eligible records
    with a positive Jaccard overlap of token sets (see ``state_tokens``), the top
    ``neighbourhood`` by overlap are kept, ties broken by recency (the order in which this
    memory first stored the record, newer first). Baseline = mean return of the
    neighbourhood; A(skill) = mean return of the neighbourhood's records of that skill
    minus the baseline; an unseen skill gets 0. Everything is unweighted. The key is the
    skill name, so every parameterisation shares its skill's advantage. That is the
    default estimator; the others (equal-horizon returns, minimum support) and the
    arithmetic itself live in ``agent.estimators`` (``estimator=``).

Peers' share (issue 22: one compromised peer stored 8-12k records in every peer and made
    >99 % of a role's memory its own)
    A peer's records are stored at most ``max_records_per_sender`` rows and
    ``max_bytes_per_sender`` bytes (state text, invocation and tokens) per sender; beyond
    that, that sender's *oldest* stored records are evicted first (nobody else's), down to
    7/8 of the caps at once (so a flood at the cap costs one recount per cap/8 records). In a
    neighbourhood, a peer holding more records of the (task, role) group than this daemon
    itself (honest same-role peers hold about as many) gets at most
    ``max_sender_share`` of the K places; the places it loses go to the next-best records
    of others. Own records are never capped or evicted.

Speed
    SQLite is the durable store; retrieval runs on an in-memory inverted index per
    (task, role), loaded lazily from the table on first use and kept in sync on every
    write of this process (rows another process writes meanwhile join at the next open).
    Posting lists and per-record columns are ``array`` buffers. A query over a large
    group is one ``numpy.bincount`` over the postings of the query's tokens -- O(postings)
    with no Python loop over records -- then an O(n) threshold selection for the top K.
    Groups of up to ``SMALL_GROUP`` records (every simulated episode of up to 50 UAVs) are
    scored the same way in plain Python, so a daemon imports numpy (about 10 MB of resident
    memory) only once its memory outgrows that; both paths select the same records.

Not thread-safe: one owner thread (see ``AsyncExperienceMemory`` for the asyncio daemon).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import sqlite3
import time
import uuid
from array import array
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final, Literal, TypeVar

from aeroweaver_edge.agent.estimators import PAPER, Estimator, HorizonBook
from aeroweaver_edge.agent.state_tokens import TOKENIZER_VERSION, tokenise
from aeroweaver_edge.config import AgentConfig
from aeroweaver_edge.wire import MAX_TEXT, ExperienceRecord, Header

log = logging.getLogger(__name__)

MAX_RECORDS_PER_SENDER: Final = 4096
"""Peers' records stored per sender (oldest evicted first): about 170 episodes of 24 rounds."""
MAX_BYTES_PER_SENDER: Final = 4 * 1024 * 1024
"""Peers' stored text (state, invocation, tokens) per sender."""
MAX_SENDER_SHARE: Final = 0.5
"""Most of a neighbourhood one over-represented peer may fill (see the module docstring)."""

SMALL_GROUP: Final = 2048
"""Largest (task, role) group scored in plain Python; larger ones use numpy."""

SCHEMA_VERSION: Final = 2
LOCAL: Final = ""  # ``origin`` of records appended by this memory's own daemon
LEGACY_RUN: Final = "v1"  # run of the rows migrated from a version-1 file
BUSY_TIMEOUT_S: Final = 10.0  # a concurrent writer waits this long for the write lock

Key = tuple[str, int, int]  # (uav, episode, round) within one run
RunKey = tuple[str, str, int, int]  # (run, uav, episode, round): unique in a file
T = TypeVar("T")


class MemoryUnavailable(RuntimeError):
    """The experience memory cannot be opened or written, and it is required.

    ``during`` is ``"open"`` (start-up: a configuration or environment problem) or
    ``"write"`` (a write failed mid-run: disk full, read-only, I/O error)."""

    def __init__(self, message: str, *, during: Literal["open", "write"]) -> None:
        super().__init__(message)
        self.during = during


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

_COLUMNS = (
    "seq, task, role, uav, episode, round, state_text, skill, invocation, reward, ret, final, "
    "origin, reward_source, run"
)


@dataclass(frozen=True, slots=True)
class StoredRecord:
    """One stored decision with its provenance."""

    seq: int
    task: str
    role: str
    uav: str
    episode: int
    round: int
    state_text: str
    skill: str
    invocation: str
    reward: float | None
    ret: float | None
    final: bool
    origin: str  # "" = appended by this daemon, else the peer that published it
    reward_source: str
    run: str = ""

    def to_wire(self, h: Header) -> ExperienceRecord:
        """The payload a daemon publishes on ``.../experience`` (it supplies the header)."""
        return ExperienceRecord(
            h=h,
            task=self.task,
            role=self.role,
            uav=self.uav,
            episode=self.episode,
            round=self.round,
            state_text=self.state_text,
            skill=self.skill,
            invocation=self.invocation,
            reward=self.reward,
            ret=self.ret,
            final=self.final,
            reward_source=self.reward_source,
            run=self.run,
        )


@dataclass(frozen=True, slots=True)
class Neighbour:
    """One member of a retrieved neighbourhood (for inspection, tests and reports)."""

    key: Key
    skill: str
    ret: float
    similarity: float
    seq: int
    run: str = ""


def skill_of(name: str) -> str:
    """``cover_landmark(target=L2)`` -> ``cover_landmark``: a parameterisation shares its
    skill's advantage, so callers may pass invocations as well as skill names."""
    return name.split("(", 1)[0].strip()


class _Group:
    """In-memory inverted index of one (task, role): position i = i-th record by seq."""

    __slots__ = (
        "book",
        "dead",
        "final",
        "gone",
        "keys",
        "origin",
        "origin_count",
        "origin_ids",
        "origins",
        "pos",
        "postings",
        "ret",
        "seq",
        "size",
        "skill",
        "skill_ids",
        "skills",
    )

    def __init__(self, book: HorizonBook | None = None) -> None:
        self.book = book  # an estimator's per-record bookkeeping (agent.estimators)
        self.seq = array("q")
        self.size = array("i")  # token-set size
        self.ret = array("d")  # NaN = no return yet
        self.final = array("b")
        self.skill = array("i")
        self.skills: list[str] = []
        self.skill_ids: dict[str, int] = {}
        self.postings: dict[str, array[int]] = {}
        self.pos: dict[RunKey, int] = {}
        self.keys: list[RunKey] = []
        self.origin = array("i")  # id into origins ("" = this daemon's own)
        self.origins: list[str] = []
        self.origin_ids: dict[str, int] = {}
        self.origin_count: list[int] = []  # live records per origin id
        self.dead = 0  # evicted positions (never eligible; the group is rebuilt when many)
        self.gone = array("b")  # 1 = evicted: excluded under every estimator

    def __len__(self) -> int:
        return len(self.seq)

    def remove(self, key: RunKey) -> None:
        """An evicted record: never eligible again (positions stay, so the order does)."""
        i = self.pos.pop(key, None)
        if i is not None:
            self.ret[i] = math.nan
            self.gone[i] = 1
            self.origin_count[self.origin[i]] -= 1
            self.dead += 1

    def add(
        self,
        key: RunKey,
        seq: int,
        tokens: Iterable[str],
        skill: str,
        ret: float | None,
        final: bool,
        origin: str = LOCAL,
        rewards: Iterable[tuple[int, float]] = (),
    ) -> None:
        """``rewards``: (round, reward) of the record's trajectory known now (the book's)."""
        i = len(self.seq)
        oid = self.origin_ids.get(origin)
        if oid is None:
            oid = self.origin_ids[origin] = len(self.origins)
            self.origins.append(origin)
            self.origin_count.append(0)
        self.origin.append(oid)
        self.origin_count[oid] += 1
        n_tokens = 0
        postings = self.postings
        for tok in tokens:
            plist = postings.get(tok)
            if plist is None:
                plist = postings[tok] = array("i")
            plist.append(i)
            n_tokens += 1
        sid = self.skill_ids.get(skill)
        if sid is None:
            sid = self.skill_ids[skill] = len(self.skills)
            self.skills.append(skill)
        self.seq.append(seq)
        self.size.append(n_tokens)
        self.ret.append(math.nan if ret is None else ret)
        self.final.append(1 if final else 0)
        self.gone.append(0)
        self.skill.append(sid)
        self.pos[key] = i
        self.keys.append(key)
        if self.book is not None:
            self.book.added(i, key, rewards)


class ExperienceMemory:
    """Durable, role-indexed experience with fast Jaccard retrieval (module docstring)."""

    def __init__(
        self,
        path: str | Path | None = None,
        *,
        gamma: float = 0.95,
        neighbourhood: int = 32,
        finalised_only: bool = False,
        durable: bool = False,
        run: str | None = None,
        required: bool = False,
        max_records_per_sender: int = MAX_RECORDS_PER_SENDER,
        max_bytes_per_sender: int = MAX_BYTES_PER_SENDER,
        max_sender_share: float = MAX_SENDER_SHARE,
        estimator: Estimator = PAPER,
    ) -> None:
        """``durable=True`` sets ``synchronous=FULL`` (commits survive power loss); the
        default ``NORMAL`` is crash-consistent and may lose the last commits on power loss,
        which advisory memory can afford. ``run`` names this writer's run (default: a new
        one); ``required`` turns an unusable file or a failed write into
        ``MemoryUnavailable`` instead of a RAM fallback or a dropped write."""
        if not 0.0 <= gamma <= 1.0:
            raise ValueError(f"gamma {gamma} must be within [0, 1]")
        if neighbourhood < 1:
            raise ValueError(f"neighbourhood {neighbourhood} must be at least 1")
        if max_records_per_sender < 1 or max_bytes_per_sender < 1:
            raise ValueError("per-sender caps must be at least 1")
        if not 0.0 < max_sender_share <= 1.0:
            raise ValueError(f"max_sender_share {max_sender_share} must be within (0, 1]")
        self.max_records_per_sender = max_records_per_sender
        self.max_bytes_per_sender = max_bytes_per_sender
        self.max_sender_share = max_sender_share
        self.evicted = 0  # peers' records evicted by the per-sender caps
        self._usage: dict[str, list[int]] | None = None  # origin -> [records, bytes]
        self.path = Path(path) if path is not None else None
        self.gamma = gamma
        self.neighbourhood = neighbourhood
        self.finalised_only = finalised_only
        self.estimator = estimator
        self.run = run or new_run_id()
        self.required = required and self.path is not None
        self.quarantined: Path | None = None
        self.migrated_from: int | None = None  # schema version this open migrated
        self.degraded: str | None = None  # why we fell back to an in-memory database
        self.write_errors = 0
        self._last_error_log = -math.inf
        self._groups: dict[tuple[str, str], _Group] = {}
        self._durable = durable
        self._db = self._open()

    @classmethod
    def from_config(cls, cfg: AgentConfig, *, run: str | None = None) -> ExperienceMemory:
        return cls(
            cfg.memory_path,
            gamma=cfg.gamma,
            neighbourhood=cfg.neighbourhood,
            finalised_only=cfg.finalised_only,
            run=run or cfg.run_id,
            required=cfg.memory_required,
            estimator=Estimator.parse(cfg.estimator),
        )

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
            except (OSError, sqlite3.Error, _NewerSchema) as exc:
                if conn is not None:
                    conn.close()
                reason = str(exc) if isinstance(exc, _NewerSchema) else _why(exc)
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
        Raises ``_NewerSchema`` for a newer release's file, which is never touched."""
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
                raise _NewerSchema(
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
        mode = conn.execute("PRAGMA journal_mode=WAL").fetchone()[0]
        if mode not in ("wal", "memory"):
            log.warning("experience memory: journal mode is %s, not WAL", mode)
        conn.execute(f"PRAGMA synchronous={'FULL' if self._durable else 'NORMAL'}")
        self._db = conn
        with self._tx():
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
                raise _NewerSchema(f"schema version {version} comes from a newer release")
            meta = dict(conn.execute("SELECT key, value FROM meta").fetchall())
            if meta.get("tokenizer") != str(TOKENIZER_VERSION):
                self._retokenise()
            if "gamma" in meta and float(meta["gamma"]) != self.gamma:
                log.info(
                    "experience memory: gamma %s -> %s, recomputing returns",
                    meta["gamma"],
                    self.gamma,
                )
                self._recompute_returns()
            conn.executemany(
                "INSERT OR REPLACE INTO meta VALUES (?, ?)",
                [("tokenizer", str(TOKENIZER_VERSION)), ("gamma", repr(self.gamma))],
            )

    def _migrate_v1(self) -> None:
        """Version 1 -> 2 inside the open transaction: tables rebuilt with a ``run``
        column (SQLite cannot change a UNIQUE constraint in place); every v1 row keeps
        its values under run ``LEGACY_RUN``. Rows mixed by v1's run collisions cannot be
        told apart any more and stay as they were."""
        db = self._db
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
        rows = self._db.execute("SELECT seq, state_text FROM records").fetchall()
        self._db.executemany(
            "UPDATE records SET tokens = ? WHERE seq = ?",
            [(" ".join(sorted(tokenise(text))), seq) for seq, text in rows],
        )

    def _recompute_returns(self) -> None:
        rewards: dict[tuple[str, str, int], list[tuple[int, float]]] = {}
        for run, uav, episode, rnd, reward in self._db.execute(
            "SELECT run, uav, episode, round, reward FROM rewards"
        ):
            rewards.setdefault((run, uav, episode), []).append((rnd, reward))
        rows = self._db.execute(
            "SELECT seq, run, uav, episode, round FROM records WHERE origin = ''"
        ).fetchall()
        self._db.executemany(
            "UPDATE records SET ret = ? WHERE seq = ?",
            [(self._return_at(rewards.get((n, u, e), []), r), s) for s, n, u, e, r in rows],
        )

    def _return_at(self, rewards: Iterable[tuple[int, float]], rnd: int) -> float | None:
        total: float | None = None
        for u, r in sorted(rewards):
            if u >= rnd:
                total = (total or 0.0) + self.gamma ** (u - rnd) * r
        return total

    # ------------------------------------------------------------------ plumbing

    @contextlib.contextmanager
    def _tx(self) -> Iterator[None]:
        """One write transaction. IMMEDIATE takes the write lock up front, so a concurrent
        writer waits on the busy timeout instead of failing half-way (WAL cannot upgrade
        a read snapshot to a write without risking SQLITE_BUSY_SNAPSHOT)."""
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield
        except BaseException:
            if self._db.in_transaction:  # SQLite may already have rolled back (disk full)
                with contextlib.suppress(sqlite3.Error):
                    self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    def _guard(
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

    def _group(self, task: str, role: str) -> _Group:
        group = self._groups.get((task, role))
        if group is None:
            book = self.estimator.book(self.gamma)
            group = _Group(book)
            for seq, run, uav, episode, rnd, tokens, skill, ret, final, rw, origin in (
                self._db.execute(
                    "SELECT seq, run, uav, episode, round, tokens, skill, ret, final, reward, "
                    "origin FROM records WHERE task = ? AND role = ? ORDER BY seq",
                    (task, role),
                )
            ):
                group.add(
                    (run, uav, episode, rnd), seq, tokens.split(), skill, ret, bool(final),
                    origin, () if rw is None else ((rnd, rw),),
                )  # fmt: skip
            if book is not None:  # our own rewards, also of rounds without a record
                for run, uav, episode, rnd, rw in self._db.execute(
                    "SELECT run, uav, episode, round, reward FROM rewards"
                ):
                    if (run, uav, episode) in book.members:
                        book.reward((run, uav, episode, rnd), rw)
            self._groups[(task, role)] = group
        return group

    # ------------------------------------------------------------------ writing

    def append(
        self,
        *,
        task: str,
        role: str,
        uav: str,
        episode: int,
        round: int,
        state_text: str,
        skill: str,
        invocation: str,
    ) -> bool:
        """Store one decision of this run; ``False`` if (run, uav, episode, round) was
        already stored. When it returns ``True`` the record is committed (acknowledged).

        Rewards already delivered for this or later rounds of the trajectory are folded
        into its return at once, so delivery order does not matter."""
        tokens = tokenise(state_text)
        skill = skill_of(skill)
        run = self.run

        def go() -> tuple[int, float | None, float | None, list[tuple[int, float]]] | None:
            with self._tx():
                rewards = self._db.execute(
                    "SELECT round, reward, source FROM rewards "
                    "WHERE run = ? AND uav = ? AND episode = ? AND round >= ?",
                    (run, uav, episode, round),
                ).fetchall()
                own = next(((r, s) for u, r, s in rewards if u == round), (None, ""))
                ret = self._return_at(((u, r) for u, r, _ in rewards), round)
                cur = self._db.execute(
                    "INSERT OR IGNORE INTO records (run, task, role, uav, episode, round, "
                    "state_text, tokens, skill, invocation, reward, ret, reward_source, "
                    "created_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (
                        run,
                        task,
                        role,
                        uav,
                        episode,
                        round,
                        state_text,
                        " ".join(sorted(tokens)),
                        skill,
                        invocation,
                        own[0],
                        ret,
                        own[1],
                        time.time(),
                    ),
                )
                if cur.rowcount == 0:
                    return None
                assert cur.lastrowid is not None
                return cur.lastrowid, own[0], ret, [(u, r) for u, r, _ in rewards]

        done = self._guard("append", None, go)
        if done is None:
            return False
        group = self._groups.get((task, role))
        if group is not None:
            group.add(
                (run, uav, episode, round), done[0], tokens, skill, done[2], False,
                rewards=done[3],
            )
        return True

    def add_reward(self, uav: str, episode: int, round: int, reward: float, source: str) -> bool:
        """Store r_round of this run unchanged and credit gamma^(round-t) * r to every
        G_t, t <= round, of this run's trajectory (never another run's). Idempotent: the
        same reward delivered again changes nothing; a different value for the same round
        replaces the old one (returns are adjusted by the difference). Returns whether
        anything changed."""
        if not math.isfinite(reward):
            log.warning(
                "experience memory: non-finite reward %r for %s/%s/%s ignored",
                reward,
                uav,
                episode,
                round,
            )
            return False
        run = self.run

        def go() -> list[tuple[str, str, RunKey, float]] | None:
            with self._tx():
                old = self._db.execute(
                    "SELECT reward FROM rewards "
                    "WHERE run = ? AND uav = ? AND episode = ? AND round = ?",
                    (run, uav, episode, round),
                ).fetchone()
                if old is not None and old[0] == reward:
                    return None
                delta = reward - (old[0] if old is not None else 0.0)
                self._db.execute(
                    "INSERT OR REPLACE INTO rewards VALUES (?, ?, ?, ?, ?, ?)",
                    (run, uav, episode, round, reward, source),
                )
                self._db.execute(
                    "UPDATE records SET reward = ?, reward_source = ? WHERE run = ? AND uav = ? "
                    "AND episode = ? AND round = ? AND origin = ''",
                    (reward, source, run, uav, episode, round),
                )
                rows = self._db.execute(
                    "SELECT seq, task, role, round, ret FROM records "
                    "WHERE run = ? AND uav = ? AND episode = ? AND round <= ? AND origin = ''",
                    (run, uav, episode, round),
                ).fetchall()
                g = self.gamma
                updates = [
                    (task, role, (run, uav, episode, t), (ret or 0.0) + g ** (round - t) * delta)
                    for _, task, role, t, ret in rows
                ]
                self._db.executemany(
                    "UPDATE records SET ret = ? WHERE seq = ?",
                    [(u[3], row[0]) for u, row in zip(updates, rows, strict=True)],
                )
                return updates

        updates = self._guard("add_reward", None, go)
        if updates is None:
            return False
        books = set()
        for task, role, key, ret in updates:
            group = self._groups.get((task, role))
            i = group.pos.get(key) if group is not None else None
            if group is not None and i is not None:
                group.ret[i] = ret
                if group.book is not None:
                    books.add((task, role))
        for g in books:
            book = self._groups[g].book
            assert book is not None
            book.reward((run, uav, episode, round), reward)
        return True

    def finalise(self, uav: str, episode: int) -> int:
        """Mark this run's trajectory ended: its returns are complete. Returns records
        marked."""
        run = self.run

        def go() -> list[tuple[str, str, int]]:
            with self._tx():
                rows = self._db.execute(
                    "SELECT task, role, round FROM records "
                    "WHERE run = ? AND uav = ? AND episode = ? AND final = 0 AND origin = ''",
                    (run, uav, episode),
                ).fetchall()
                self._db.execute(
                    "UPDATE records SET final = 1 "
                    "WHERE run = ? AND uav = ? AND episode = ? AND origin = ''",
                    (run, uav, episode),
                )
                return rows

        nothing: list[tuple[str, str, int]] = []
        rows = self._guard("finalise", nothing, go)
        for task, role, rnd in rows:
            group = self._groups.get((task, role))
            i = group.pos.get((run, uav, episode, rnd)) if group is not None else None
            if group is not None and i is not None:
                group.final[i] = 1
        return len(rows)

    def ingest(self, record: ExperienceRecord) -> bool:
        """Merge a peer's record (shared swarm memory), deduplicated by (run, uav,
        episode, round). New keys are inserted; a stored peer record is replaced by a
        newer version (finalised beats in flight, then the publisher's (epoch, seq)),
        never downgraded from final. Records this daemon appended itself are
        authoritative and never overwritten, which also drops our own echo. Malformed
        records (non-finite numbers, oversize text) are refused. Returns whether
        anything changed."""
        problem = _invalid(record)
        if problem is not None:
            log.debug("experience memory: refused record from %s: %s", record.h.sender, problem)
            return False
        key: RunKey = (record.run, record.uav, record.episode, record.round)
        skill = skill_of(record.skill)
        tokens = tokenise(record.state_text)
        version = (record.final, record.h.epoch, record.h.seq)

        origin = record.h.sender or "?"
        tokens_text = " ".join(sorted(tokens))
        size = len(record.state_text) + len(record.invocation) + len(tokens_text)
        evicted: list[tuple[str, str, RunKey]] = []
        inserted = [False]

        def go() -> tuple[int, str, str] | None:
            """(seq, task, role) of the inserted or updated row, or None if unchanged."""
            evicted.clear()
            inserted[0] = False
            with self._tx():
                row = self._db.execute(
                    "SELECT seq, origin, final, src_epoch, src_seq, reward, ret, task, role "
                    "FROM records WHERE run = ? AND uav = ? AND episode = ? AND round = ?",
                    key,
                ).fetchone()
                if row is None:
                    if not self._make_room(origin, size, evicted):
                        return None
                    cur = self._db.execute(
                        "INSERT INTO records (run, task, role, uav, episode, round, state_text, "
                        "tokens, skill, invocation, reward, ret, final, origin, reward_source, "
                        "src_epoch, src_seq, created_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, "
                        "?, ?, ?, ?, ?, ?, ?, ?)",
                        (
                            record.run,
                            record.task,
                            record.role,
                            record.uav,
                            record.episode,
                            record.round,
                            record.state_text,
                            tokens_text,
                            skill,
                            record.invocation,
                            record.reward,
                            record.ret,
                            int(record.final),
                            origin,
                            record.reward_source,
                            record.h.epoch,
                            record.h.seq,
                            time.time(),
                        ),
                    )
                    assert cur.lastrowid is not None
                    inserted[0] = True
                    return cur.lastrowid, record.task, record.role
                seq, old_origin, final, epoch, src_seq, reward, ret, task, role = row
                if old_origin == LOCAL or version <= (bool(final), epoch, src_seq):
                    return None
                if old_origin != origin:
                    return None  # a record stays its first sender's (and counts to it)
                self._db.execute(
                    "UPDATE records SET reward = ?, ret = ?, final = ?, reward_source = ?, "
                    "src_epoch = ?, src_seq = ? WHERE seq = ?",
                    (
                        record.reward,
                        record.ret,
                        int(record.final),
                        record.reward_source,
                        record.h.epoch,
                        record.h.seq,
                        seq,
                    ),
                )
                if (reward, ret, bool(final)) == (record.reward, record.ret, record.final):
                    return None  # a newer copy of the same content
                return seq, task, role

        try:
            done = self._guard("ingest", None, go, own=False)
        except BaseException:
            self._usage = None  # the transaction may have rolled back: recount next time
            raise
        self._forget_evicted(evicted)
        if done is None:
            if evicted:  # rolled back or refused after eviction: recount next time
                self._usage = None
            return False
        if inserted[0]:
            usage = self._sender_usage(origin)
            usage[0] += 1
            usage[1] += size
        group = self._groups.get((done[1], done[2]))
        i = group.pos.get(key) if group is not None else None
        if group is not None:
            own = () if record.reward is None else ((record.round, record.reward),)
            if i is None:
                group.add(key, done[0], tokens, skill, record.ret, record.final, origin, own)
            else:
                group.ret[i] = math.nan if record.ret is None else record.ret
                group.final[i] = 1 if record.final else 0
                if group.book is not None and record.reward is not None:
                    group.book.reward(key, record.reward)
        return True

    def credit_peer(self, record: ExperienceRecord) -> int:
        """A peer's in-flight record of round t (shared as it happened) carries r_t and
        the rewards of the rounds it held since its previous record: credit each
        gamma^(u-s) * r_u, in round order, to that peer's stored in-flight records s < u of
        the same trajectory, as the peer credited its own (its finalised records replace
        these at the episode's end). Call once per newly stored record. Returns records
        credited."""
        t = record.round
        rewards = sorted((u, r) for u, r in record.held_rewards if u < t and math.isfinite(r)) + (
            [(t, record.reward)] if record.reward is not None else []
        )
        if record.final or not rewards or _invalid(record) is not None:
            return 0
        origin, g = record.h.sender or "?", self.gamma
        where = (record.run, record.uav, record.episode, t, origin)

        def go() -> list[tuple[int, str, str, int, float]]:
            with self._tx():
                rows = self._db.execute(
                    "SELECT seq, task, role, round, ret FROM records WHERE run = ? AND uav = ? "
                    "AND episode = ? AND round < ? AND origin = ? AND final = 0",
                    where,
                ).fetchall()
                out = []
                for q, k, o, s, ret in rows:
                    for u, r in rewards:
                        if s < u:
                            ret = (ret or 0.0) + g ** (u - s) * r
                    if ret is not None:  # s < t: credited at least r_t or a held reward
                        out.append((q, k, o, s, ret))
                self._db.executemany(
                    "UPDATE records SET ret = ? WHERE seq = ?", [(u[4], u[0]) for u in out]
                )
                return out

        nothing: list[tuple[int, str, str, int, float]] = []
        done = self._guard("credit_peer", nothing, go, own=False)
        for _, task, role, rnd, ret in done:
            group = self._groups.get((task, role))
            key = (record.run, record.uav, record.episode, rnd)
            i = group.pos.get(key) if group is not None else None
            if group is not None and i is not None:
                group.ret[i] = ret
        group = self._groups.get((record.task, record.role))
        if group is not None and group.book is not None:  # r_t came with the record itself
            for u, r in rewards[:-1] if record.reward is not None else rewards:
                group.book.reward((record.run, record.uav, record.episode, u), r)
        return len(done)

    def _sender_usage(self, origin: str) -> list[int]:
        """[records, bytes] stored of ``origin`` (peers only), counted once per open."""
        if self._usage is None:
            self._usage = {
                o: [n, b]
                for o, n, b in self._db.execute(
                    "SELECT origin, count(*), coalesce(sum(length(state_text) + "
                    "length(invocation) + length(tokens)), 0) FROM records "
                    "WHERE origin != '' GROUP BY origin"
                )
            }
        return self._usage.setdefault(origin, [0, 0])

    def _make_room(self, origin: str, size: int, evicted: list[tuple[str, str, RunKey]]) -> bool:
        """Inside the ingest transaction: evict ``origin``'s oldest records until one more
        of ``size`` bytes fits its caps. False if it can never fit (larger than the cap)."""
        cap_n, cap_b = self.max_records_per_sender, self.max_bytes_per_sender
        if size > cap_b:
            return False
        n, b = self._sender_usage(origin)
        if n + 1 <= cap_n and b + size <= cap_b:
            return True
        # Near the cap: count exactly (another process may write this file too).
        n, b = self._db.execute(
            "SELECT count(*), coalesce(sum(length(state_text) + length(invocation) + "
            "length(tokens)), 0) FROM records WHERE origin = ?",
            (origin,),
        ).fetchone()
        gone: list[int] = []
        if n + 1 > cap_n or b + size > cap_b:
            # Down to 7/8 of the caps at once: the next cap/8 records need no recount.
            cap_n, cap_b = cap_n - max(1, cap_n // 8), cap_b - cap_b // 8
            cur = self._db.execute(
                "SELECT seq, task, role, run, uav, episode, round, length(state_text) + "
                "length(invocation) + length(tokens) FROM records WHERE origin = ? ORDER BY seq",
                (origin,),
            )
            for seq, task, role, run, uav, episode, rnd, nbytes in cur:
                if n + 1 <= cap_n and b + size <= cap_b:
                    break
                gone.append(seq)
                evicted.append((task, role, (run, uav, episode, rnd)))
                n, b = n - 1, b - nbytes
            cur.close()
            self._db.executemany("DELETE FROM records WHERE seq = ?", [(q,) for q in gone])
        usage = self._sender_usage(origin)
        usage[0], usage[1] = n, b
        return True

    def _forget_evicted(self, evicted: list[tuple[str, str, RunKey]]) -> None:
        """Drop evicted records from the retrieval index; rebuild a group once half dead."""
        self.evicted += len(evicted)
        for task, role, key in evicted:
            group = self._groups.get((task, role))
            if group is None:
                continue
            group.remove(key)
            if group.dead > max(256, len(group) // 2):
                del self._groups[(task, role)]  # reloaded from the table on next use

    # ------------------------------------------------------------------ reading

    def warm(self, task: str, role: str) -> int:
        """Build the retrieval index of (task, role) now rather than on the first query
        (about 1.5 s at 10^5 records), e.g. right after the role is assigned, so the first
        decision after a restart is not the slow one. Returns the records indexed."""
        group = self._guard("warm", None, lambda: self._group(task, role), write=False)
        return 0 if group is None else len(group)

    def get(
        self, uav: str, episode: int, round: int, *, run: str | None = None
    ) -> StoredRecord | None:
        """One record of ``run`` (default: this memory's own run)."""
        row = self._db.execute(
            f"SELECT {_COLUMNS} FROM records "
            "WHERE run = ? AND uav = ? AND episode = ? AND round = ?",
            (self.run if run is None else run, uav, episode, round),
        ).fetchone()
        return _stored(row) if row is not None else None

    def export(self, uav: str, episode: int, *, final_only: bool = True) -> list[StoredRecord]:
        """This memory's own records of one trajectory of its run, by round, for
        publishing."""
        sql = (
            f"SELECT {_COLUMNS} FROM records "
            "WHERE run = ? AND uav = ? AND episode = ? AND origin = ''"
            + (" AND final = 1" if final_only else "")
            + " ORDER BY round"
        )
        return [_stored(r) for r in self._db.execute(sql, (self.run, uav, episode))]

    def export_final(self, uav: str, episode: int) -> list[StoredRecord]:
        return self.export(uav, episode, final_only=True)

    def records(self, task: str, role: str) -> list[StoredRecord]:
        """Every record of one (task, role) in stored order (inspection and tests)."""
        sql = f"SELECT {_COLUMNS} FROM records WHERE task = ? AND role = ? ORDER BY seq"
        return [_stored(r) for r in self._db.execute(sql, (task, role))]

    def __len__(self) -> int:
        return int(self._db.execute("SELECT count(*) FROM records").fetchone()[0])

    def _select(self, group: _Group, tokens: frozenset[str]) -> tuple[list[int], list[float]]:
        """Positions of the neighbourhood (best first) and their Jaccard similarities.
        Peers holding more of the group than this daemon are capped to
        ``max_sender_share`` of the places (none in a balanced, honest swarm: then this is
        exactly the uncapped selection)."""
        k = self.neighbourhood
        heavy = self._heavy_origins(group)
        if heavy:
            k = len(group)  # the whole order, then the capped pick below
        if len(group) > SMALL_GROUP:
            pos, sim = self._select_numpy(group, tokens, k)
        else:
            pos, sim = self._select_python(group, tokens, k)
        if not heavy:
            return pos, sim
        return self._capped(group, pos, sim, heavy)

    def _heavy_origins(self, group: _Group) -> set[int]:
        """Peers (origin ids) with more live records in ``group`` than this daemon's own."""
        if self.max_sender_share >= 1.0:
            return set()
        own_id = group.origin_ids.get(LOCAL)
        own = group.origin_count[own_id] if own_id is not None else 0
        return {
            oid for oid, n in enumerate(group.origin_count) if oid != own_id and n > max(own, 0)
        }

    def _capped(
        self, group: _Group, pos: list[int], sim: list[float], heavy: set[int]
    ) -> tuple[list[int], list[float]]:
        """The best-first ``pos`` cut to K places with each heavy origin at most its cap."""
        cap = max(1, int(self.max_sender_share * self.neighbourhood))
        taken: dict[int, int] = {}
        out_pos: list[int] = []
        out_sim: list[float] = []
        for i, s in zip(pos, sim, strict=True):
            oid = group.origin[i]
            if oid in heavy:
                if taken.get(oid, 0) >= cap:
                    continue
                taken[oid] = taken.get(oid, 0) + 1
            out_pos.append(i)
            out_sim.append(s)
            if len(out_pos) >= self.neighbourhood:
                break
        return out_pos, out_sim

    def _eligible(self, group: _Group, i: int) -> bool:
        if group.gone[i]:
            return False  # evicted (a peer over its caps): never eligible again
        if group.book is not None:
            final = group.final[i] != 0
            return group.book.eligible(i, final) and (not self.finalised_only or final)
        return not math.isnan(group.ret[i]) and (not self.finalised_only or group.final[i] != 0)

    @staticmethod
    def _values(group: _Group, pos: list[int]) -> list[float]:
        """The records' values for the estimator: returns, or the book's (agent.estimators)."""
        if group.book is None:
            return [group.ret[i] for i in pos]
        return group.book.values(pos, group.final)

    def _select_python(
        self, group: _Group, tokens: frozenset[str], k: int | None = None
    ) -> tuple[list[int], list[float]]:
        k = self.neighbourhood if k is None else k
        n = len(group)
        everywhere = 0
        inter: dict[int, int] = {}
        for tok in tokens:
            plist = group.postings.get(tok)
            if plist is None:
                continue
            if len(plist) == n:
                everywhere += 1  # in every record: counted once, not per record
                continue
            for i in plist:
                inter[i] = inter.get(i, 0) + 1
        if n == 0 or (not inter and not everywhere):
            return [], []
        overlap = range(n) if everywhere else sorted(inter)
        q = len(tokens)
        scored = [
            (ci / (group.size[i] + q - ci), i)
            for i in overlap
            if self._eligible(group, i) and (ci := everywhere + inter.get(i, 0)) > 0
        ]
        # best first: similarity desc, then recency (position) desc; the first K of that
        # order are the top K by similarity with ties broken toward the newest.
        scored.sort(key=lambda x: (-x[0], -x[1]))
        best = scored[:k]
        return [i for _, i in best], [sim for sim, _ in best]

    def _select_numpy(
        self, group: _Group, tokens: frozenset[str], k: int | None = None
    ) -> tuple[list[int], list[float]]:
        k = self.neighbourhood if k is None else k
        import numpy as np

        n = len(group)
        # Tokens every record holds (task, role, fixed field names) add 1 to every overlap:
        # count them instead of concatenating n-long posting lists.
        everywhere = 0
        lists = []
        for tok in tokens:
            plist = group.postings.get(tok)
            if plist is None:
                continue
            if len(plist) == n:
                everywhere += 1
            else:
                lists.append(np.frombuffer(plist, dtype=np.int32))
        if n == 0 or (not lists and not everywhere):
            return [], []
        inter = np.full(n, everywhere, dtype=np.int64)
        if lists:
            inter += np.bincount(np.concatenate(lists), minlength=n)
        final = np.frombuffer(group.final, dtype=np.int8) != 0
        if group.book is None:
            eligible = (inter > 0) & ~np.isnan(np.frombuffer(group.ret, dtype=np.float64))
        else:
            count = np.frombuffer(group.book.count, dtype=np.int32)
            eligible = (inter > 0) & ((count >= group.book.h) | (final & (count > 0)))
        if self.finalised_only:
            eligible &= final
        if group.dead:
            eligible &= np.frombuffer(group.gone, dtype=np.int8) == 0
        cand = np.flatnonzero(eligible)  # ascending position == ascending recency
        if cand.size == 0:
            return [], []
        ci = inter[cand]
        sim = ci / (np.frombuffer(group.size, dtype=np.int32)[cand] + len(tokens) - ci)
        if cand.size > k:
            kth = np.partition(sim, cand.size - k)[cand.size - k]  # k-th largest similarity
            above = np.flatnonzero(sim > kth)
            ties = np.flatnonzero(sim == kth)[-(k - above.size) :]  # newest of the tied
            keep = np.concatenate([above, ties])
        else:
            keep = np.arange(cand.size)
        # best first: similarity desc, then recency desc
        order = np.lexsort((-cand[keep], -sim[keep]))
        keep = keep[order]
        return [int(i) for i in cand[keep]], [float(x) for x in sim[keep]]

    def neighbourhood_of(self, task: str, role: str, state_text: str) -> list[Neighbour]:
        """The retrieved neighbourhood, best first (what ``advantages`` averages over)."""
        group = self._group(task, role)
        pos, sim = self._select(group, tokenise(state_text))
        return [
            Neighbour(
                group.keys[i][1:],
                group.skills[group.skill[i]],
                v,
                s,
                group.seq[i],
                group.keys[i][0],
            )
            for i, s, v in zip(pos, sim, self._values(group, pos), strict=True)
        ]

    def advantages(
        self, task: str, role: str, state_text: str, skills: Iterable[str]
    ) -> dict[str, float]:
        """A(s, skill) = mean return of the neighbourhood's records of that skill minus
        the neighbourhood's mean return; 0 for a skill the neighbourhood has not seen
        (the paper's rule; ``self.estimator`` may say otherwise: ``agent.estimators``).
        Keys are the strings given (skill names or invocations; both map to the skill)."""
        names = list(skills)
        group = self._guard("retrieval", None, lambda: self._group(task, role), write=False)
        if group is None:
            return dict.fromkeys(names, 0.0)
        pos, _ = self._select(group, tokenise(state_text))
        if not pos:
            return dict.fromkeys(names, 0.0)
        return self.estimator.advantages(
            self._values(group, pos),
            [group.skill[i] for i in pos],
            {name: group.skill_ids.get(skill_of(name), -1) for name in names},
        )

    def close(self) -> None:
        self._groups.clear()
        with contextlib.suppress(sqlite3.Error):
            self._db.close()

    def __enter__(self) -> ExperienceMemory:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _stored(row: tuple[Any, ...]) -> StoredRecord:
    seq, task, role, uav, episode, rnd, text, skill, inv, reward, ret, final, origin, src, run = row
    return StoredRecord(
        seq,
        task,
        role,
        uav,
        episode,
        rnd,
        text,
        skill,
        inv,
        reward,
        ret,
        bool(final),
        origin,
        src,
        run,
    )


class _NewerSchema(Exception):
    """The file belongs to a newer release: refuse it, never rewrite or set it aside."""


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


def _transient(exc: sqlite3.Error) -> bool:
    text = str(exc).lower()
    return "locked" in text or "busy" in text or "unable to open" in text


def _why(exc: BaseException) -> str:
    """One line for an environmental failure, with the errno text when there is one."""
    if isinstance(exc, OSError):
        return f"{exc.strerror or type(exc).__name__}: {exc.filename or ''}".rstrip(": ")
    return f"{type(exc).__name__}: {exc}"


def _invalid(record: ExperienceRecord) -> str | None:
    """Why a peer's record must not enter memory (memory poisoning is a threat model item)."""
    for name in ("reward", "ret"):
        value = getattr(record, name)
        if value is not None and not math.isfinite(value):
            return f"non-finite {name}"
    if len(record.state_text) > MAX_TEXT or len(record.invocation) > MAX_TEXT:
        return "oversize text"
    if not (record.task and record.role and record.uav and record.skill):
        return "empty task, role, uav or skill"
    return None


class AsyncExperienceMemory:
    """``ExperienceMemory`` for the asyncio daemon: one worker thread owns the SQLite
    connection (created in that thread) and runs every call in FIFO order, so the event
    loop never blocks on disk and writes keep their order. Create with ``open``."""

    def __init__(self, executor: ThreadPoolExecutor, memory: ExperienceMemory) -> None:
        self._executor = executor
        self._mem = memory
        self._closed = False

    @classmethod
    async def open(
        cls,
        path: str | Path | None = None,
        *,
        gamma: float = 0.95,
        neighbourhood: int = 32,
        finalised_only: bool = False,
        durable: bool = False,
        run: str | None = None,
        required: bool = False,
        estimator: Estimator = PAPER,
    ) -> AsyncExperienceMemory:
        executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="aw-memory")
        loop = asyncio.get_running_loop()
        try:
            memory = await loop.run_in_executor(
                executor,
                lambda: ExperienceMemory(
                    path,
                    gamma=gamma,
                    neighbourhood=neighbourhood,
                    finalised_only=finalised_only,
                    durable=durable,
                    run=run,
                    required=required,
                    estimator=estimator,
                ),
            )
        except BaseException:
            executor.shutdown(wait=False)
            raise
        return cls(executor, memory)

    @classmethod
    async def from_config(
        cls, cfg: AgentConfig, *, run: str | None = None
    ) -> AsyncExperienceMemory:
        return await cls.open(
            cfg.memory_path,
            gamma=cfg.gamma,
            neighbourhood=cfg.neighbourhood,
            finalised_only=cfg.finalised_only,
            run=run or cfg.run_id,
            required=cfg.memory_required,
            estimator=Estimator.parse(cfg.estimator),
        )

    @property
    def run(self) -> str:
        return self._mem.run

    @property
    def sync(self) -> ExperienceMemory:
        """The wrapped memory, for attributes only (calling it from the loop would block)."""
        return self._mem

    async def _run(self, fn: Callable[[], T]) -> T:
        if self._closed:
            raise RuntimeError("experience memory is closed")
        return await asyncio.get_running_loop().run_in_executor(self._executor, fn)

    async def append(
        self,
        *,
        task: str,
        role: str,
        uav: str,
        episode: int,
        round: int,
        state_text: str,
        skill: str,
        invocation: str,
    ) -> bool:
        m = self._mem
        return await self._run(
            lambda: m.append(
                task=task,
                role=role,
                uav=uav,
                episode=episode,
                round=round,
                state_text=state_text,
                skill=skill,
                invocation=invocation,
            )
        )

    async def add_reward(
        self, uav: str, episode: int, round: int, reward: float, source: str
    ) -> bool:
        return await self._run(lambda: self._mem.add_reward(uav, episode, round, reward, source))

    async def finalise(self, uav: str, episode: int) -> int:
        return await self._run(lambda: self._mem.finalise(uav, episode))

    async def ingest(self, record: ExperienceRecord) -> bool:
        return await self._run(lambda: self._mem.ingest(record))

    async def credit_peer(self, record: ExperienceRecord) -> int:
        return await self._run(lambda: self._mem.credit_peer(record))

    async def warm(self, task: str, role: str) -> int:
        return await self._run(lambda: self._mem.warm(task, role))

    async def get(
        self, uav: str, episode: int, round: int, *, run: str | None = None
    ) -> StoredRecord | None:
        return await self._run(lambda: self._mem.get(uav, episode, round, run=run))

    async def export(
        self, uav: str, episode: int, *, final_only: bool = True
    ) -> list[StoredRecord]:
        return await self._run(lambda: self._mem.export(uav, episode, final_only=final_only))

    async def export_final(self, uav: str, episode: int) -> list[StoredRecord]:
        return await self.export(uav, episode, final_only=True)

    async def advantages(
        self, task: str, role: str, state_text: str, skills: Iterable[str]
    ) -> dict[str, float]:
        names = list(skills)  # materialise here: the iterable may not be thread-safe
        return await self._run(lambda: self._mem.advantages(task, role, state_text, names))

    async def neighbourhood_of(self, task: str, role: str, state_text: str) -> list[Neighbour]:
        return await self._run(lambda: self._mem.neighbourhood_of(task, role, state_text))

    async def count(self) -> int:
        return await self._run(lambda: len(self._mem))

    async def aclose(self) -> None:
        """Close the database in its thread, then stop the thread (idempotent)."""
        if self._closed:
            return
        try:
            await self._run(self._mem.close)
        finally:
            self._closed = True
            self._executor.shutdown(wait=True)  # the queue is empty: returns at once
