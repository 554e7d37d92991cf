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
    Groups of up to ``SMALL_GROUP`` records (every simulated episode of up to 50 UAVs) are
    scored in plain Python, so a daemon imports numpy (about 10 MB of resident memory) only
    once its memory outgrows that; larger ones use a pruned, exact numpy selection
    (``agent.memory_index``). Every path selects the same records. Bulk intake can share one
    transaction (``batch``, ``ingest_many``).

Modules
    ``memory.store`` (SQLite file, schema, migration, quarantine, transactions),
    ``memory.index`` (the group index and its scoring), ``memory.neighbourhood`` (the
    neighbourhood: K places, sender caps), ``memory.returns`` (G_t bookkeeping),
    ``memory.senders`` (per-sender caps), ``memory.records`` (record types),
    ``memory.async_memory`` (the asyncio wrapper); this module ties them into one memory and keeps
    the names other modules import.

Not thread-safe: one owner thread (see ``AsyncExperienceMemory`` for the asyncio daemon).
"""

from __future__ import annotations

import contextlib
import logging
import math
import sqlite3
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Final, TypeVar

from aeroweaver_edge.agent.estimators import PAPER, Estimator
from aeroweaver_edge.agent.memory.index import SMALL_GROUP, Group, prepare, values
from aeroweaver_edge.agent.memory.neighbourhood import Retrieval, neighbours
from aeroweaver_edge.agent.memory.records import (
    COLUMNS,
    LOCAL,
    Key,
    Neighbour,
    RunKey,
    StoredRecord,
    invalid,
    skill_of,
    stored,
)
from aeroweaver_edge.agent.memory.returns import install_functions, peer_credit, return_at
from aeroweaver_edge.agent.memory.senders import (
    MAX_BYTES_PER_SENDER,
    MAX_RECORDS_PER_SENDER,
    SenderCaps,
)
from aeroweaver_edge.agent.memory.store import (
    BUSY_TIMEOUT_S,
    LEGACY_RUN,
    SCHEMA_VERSION,
    MemoryUnavailable,
    Store,
    new_run_id,
)
from aeroweaver_edge.agent.state_tokens import tokenise
from aeroweaver_edge.config import AgentConfig
from aeroweaver_edge.contracts.wire import ExperienceRecord

log = logging.getLogger(__name__)

MAX_SENDER_SHARE: Final = 0.5
"""Most of a neighbourhood one over-represented peer may fill (see the module docstring)."""

T = TypeVar("T")


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
        if not 0.0 < max_sender_share <= 1.0:
            raise ValueError(f"max_sender_share {max_sender_share} must be within (0, 1]")
        self._caps = SenderCaps(max_records_per_sender, max_bytes_per_sender)
        self.evicted = 0  # peers' records evicted by the per-sender caps
        self.gamma = gamma
        self.retrieval = Retrieval(neighbourhood, max_sender_share, finalised_only)
        self.estimator = estimator
        self.run = run or new_run_id()
        self._groups: dict[tuple[str, str], Group] = {}
        self._store = Store(
            Path(path) if path is not None else None,
            gamma=gamma,
            durable=durable,
            required=required,
        )
        install_functions(self._store.db)

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

    # ------------------------------------------------------------------ the store

    @property
    def path(self) -> Path | None:
        return self._store.path

    @property
    def required(self) -> bool:
        return self._store.required

    @property
    def quarantined(self) -> Path | None:
        """Where an unusable file was set aside at open, if it was."""
        return self._store.quarantined

    @property
    def migrated_from(self) -> int | None:
        """The schema version this open migrated, if it did."""
        return self._store.migrated_from

    @property
    def degraded(self) -> str | None:
        """Why the memory fell back to an in-memory database, if it did."""
        return self._store.degraded

    @property
    def write_errors(self) -> int:
        return self._store.write_errors

    @property
    def max_records_per_sender(self) -> int:
        return self._caps.max_records

    @max_records_per_sender.setter
    def max_records_per_sender(self, value: int) -> None:
        self._caps.max_records = value

    @property
    def max_bytes_per_sender(self) -> int:
        return self._caps.max_bytes

    @max_bytes_per_sender.setter
    def max_bytes_per_sender(self, value: int) -> None:
        self._caps.max_bytes = value

    @property
    def _db(self) -> sqlite3.Connection:
        return self._store.db

    def _tx(self) -> contextlib.AbstractContextManager[None]:
        return self._store.tx()

    def _guard(
        self, what: str, default: T, fn: Callable[[], T], *, write: bool = True, own: bool = True
    ) -> T:
        return self._store.guard(what, default, fn, write=write, own=own)

    @contextlib.contextmanager
    def batch(self, *, own: bool = True) -> Iterator[None]:
        """Many writes in one transaction (``Store.batch``): each write inside returns as
        usual but is committed, and so acknowledged, only when the block ends, all or
        nothing. For bulk intake (a peer's backlog, a restore, the bench's fill); a
        decision that must be durable on return is written outside a batch. A database
        failure rolls the block back and is handled like a failed write (``own=False``:
        peers' records, logged and dropped even when the memory is required); the
        retrieval index is then reloaded from the table, so it never shows rolled-back
        rows."""
        try:
            with self._store.batch():
                yield
        except BaseException as exc:
            self._groups.clear()
            self._caps.forget()
            if isinstance(exc, sqlite3.Error) and not isinstance(
                exc, (sqlite3.ProgrammingError, sqlite3.IntegrityError, sqlite3.InterfaceError)
            ):
                self._store.failed("batch", exc, own=own)
                return
            raise

    def _group(self, task: str, role: str) -> Group:
        group = self._groups.get((task, role))
        if group is None:
            book = self.estimator.book(self.gamma)
            group = Group(book)
            for (
                seq,
                run,
                uav,
                episode,
                rnd,
                tokens,
                skill,
                ret,
                final,
                rw,
                origin,
            ) in self._db.execute(
                "SELECT seq, run, uav, episode, round, tokens, skill, ret, final, reward, "
                "origin FROM records WHERE task = ? AND role = ? ORDER BY seq",
                (task, role),
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
            if len(group) > SMALL_GROUP:
                prepare(group)
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
                ret = return_at(self.gamma, ((u, r) for u, r, _ in rewards), round)
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
                (run, uav, episode, round),
                done[0],
                tokens,
                skill,
                done[2],
                False,
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
                row = (run, uav, episode, round, reward, source)
                # The usual case, a first delivery, is one statement; a repeat reads the
                # old value to credit the difference.
                old = None
                if (
                    self._db.execute(
                        "INSERT OR IGNORE INTO rewards VALUES (?, ?, ?, ?, ?, ?)", row
                    ).rowcount
                    == 0
                ):
                    old = self._db.execute(
                        "SELECT reward FROM rewards "
                        "WHERE run = ? AND uav = ? AND episode = ? AND round = ?",
                        (run, uav, episode, round),
                    ).fetchone()
                    if old is not None and old[0] == reward:
                        return None
                    self._db.execute(
                        "INSERT OR REPLACE INTO rewards VALUES (?, ?, ?, ?, ?, ?)", row
                    )
                delta = reward - (old[0] if old is not None else 0.0)
                # One statement: r_round on its own record, G_t of every t <= round
                # credited (``credited``, the same Python arithmetic, as an SQL function).
                rows = self._db.execute(
                    "UPDATE records SET "
                    "reward = CASE WHEN round = ?1 THEN ?2 ELSE reward END, "
                    "reward_source = CASE WHEN round = ?1 THEN ?3 ELSE reward_source END, "
                    "ret = aw_credited(?4, ret, round, ?1, ?5) "
                    "WHERE run = ?6 AND uav = ?7 AND episode = ?8 AND round <= ?1 "
                    "AND origin = '' RETURNING task, role, round, ret",
                    (round, reward, source, self.gamma, delta, run, uav, episode),
                ).fetchall()
                updates = [(task, role, (run, uav, episode, t), ret) for task, role, t, ret in rows]
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
        problem = invalid(record)
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
                    if not self._caps.make_room(self._db, origin, size, evicted):
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
            self._caps.forget()  # the transaction may have rolled back: recount next time
            raise
        self._forget_evicted(evicted)
        if done is None:
            if evicted:  # rolled back or refused after eviction: recount next time
                self._caps.forget()
            return False
        if inserted[0]:
            usage = self._caps.of(self._db, origin)
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
        if record.final or not rewards or invalid(record) is not None:
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
                    ret = peer_credit(g, ret, s, rewards)
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

    def ingest_many(self, records: Iterable[ExperienceRecord]) -> int:
        """``ingest`` each record in one transaction (a peer's backlog, a late joiner's
        fetch): committed together when all are stored. Returns how many changed."""
        return self.store_peers((record, True) for record in records)  # no crediting

    def store_peers(self, batch: Iterable[tuple[ExperienceRecord, bool]]) -> int:
        """Store one round's intake of peers' records in one transaction: ``ingest``
        each, then ``credit_peer`` each newly stored in-flight record unless it was
        ``fetched`` (a backlog's record carries returns its publisher already credited).
        In the given order, so retrieval's recency tie-break sees the same memory however
        the records were stored. Returns how many changed memory. One commit per round
        instead of one per record: a late joiner's backlog stores at bulk speed."""
        changed, errors = 0, self.write_errors
        with self.batch(own=False):
            for record, fetched in batch:
                if self.ingest(record):
                    changed += 1
                    if not record.final and not fetched:
                        self.credit_peer(record)
        return changed if self.write_errors == errors else 0  # rolled back: nothing stored

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
            f"SELECT {COLUMNS} FROM records "
            "WHERE run = ? AND uav = ? AND episode = ? AND round = ?",
            (self.run if run is None else run, uav, episode, round),
        ).fetchone()
        return stored(row) if row is not None else None

    def export(self, uav: str, episode: int, *, final_only: bool = True) -> list[StoredRecord]:
        """This memory's own records of one trajectory of its run, by round, for
        publishing."""
        sql = (
            f"SELECT {COLUMNS} FROM records "
            "WHERE run = ? AND uav = ? AND episode = ? AND origin = ''"
            + (" AND final = 1" if final_only else "")
            + " ORDER BY round"
        )
        return [stored(r) for r in self._db.execute(sql, (self.run, uav, episode))]

    def export_final(self, uav: str, episode: int) -> list[StoredRecord]:
        return self.export(uav, episode, final_only=True)

    def records(self, task: str, role: str) -> list[StoredRecord]:
        """Every record of one (task, role) in stored order (inspection and tests)."""
        sql = f"SELECT {COLUMNS} FROM records WHERE task = ? AND role = ? ORDER BY seq"
        return [stored(r) for r in self._db.execute(sql, (task, role))]

    def __len__(self) -> int:
        return int(self._db.execute("SELECT count(*) FROM records").fetchone()[0])

    @property
    def neighbourhood(self) -> int:
        """K, the places of a neighbourhood."""
        return self.retrieval.k

    @neighbourhood.setter
    def neighbourhood(self, k: int) -> None:
        self.retrieval.k = k

    @property
    def finalised_only(self) -> bool:
        return self.retrieval.finalised_only

    @property
    def max_sender_share(self) -> float:
        return self.retrieval.max_sender_share

    def neighbourhood_of(self, task: str, role: str, state_text: str) -> list[Neighbour]:
        """The retrieved neighbourhood, best first (what ``advantages`` averages over)."""
        group = self._group(task, role)
        return neighbours(group, *self.retrieval.select(group, tokenise(state_text)))

    def whole_group_neighbourhood(self, task: str, role: str, state_text: str) -> list[Neighbour]:
        """``Retrieval.whole_group``: what ``neighbourhood_of`` must equal, found with no
        index and no early stop; for tests and benchmarks."""
        group = self._group(task, role)
        return neighbours(group, *self.retrieval.whole_group(group, tokenise(state_text)))

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
        pos, _ = self.retrieval.select(group, tokenise(state_text))
        if not pos:
            return dict.fromkeys(names, 0.0)
        return self.estimator.advantages(
            values(group, pos),
            [group.skill[i] for i in pos],
            {name: group.skill_ids.get(skill_of(name), -1) for name in names},
        )

    def close(self) -> None:
        self._groups.clear()
        self._store.close()

    def __enter__(self) -> ExperienceMemory:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = [
    "BUSY_TIMEOUT_S",
    "LEGACY_RUN",
    "LOCAL",
    "MAX_BYTES_PER_SENDER",
    "MAX_RECORDS_PER_SENDER",
    "MAX_SENDER_SHARE",
    "SCHEMA_VERSION",
    "SMALL_GROUP",
    "ExperienceMemory",
    "Key",
    "MemoryUnavailable",
    "Neighbour",
    "RunKey",
    "StoredRecord",
    "new_run_id",
    "skill_of",
]
