"""``aeroweaver memory stats|export|check``: look into experience-memory files offline.

Every function opens the files read-only (a daemon may be writing them: WAL lets it), so
inspecting never changes a memory. ``check`` is the consistency oracle the kill -9
benchmark uses too: integrity, a schema this release knows, every reward attached to the
decision of its own run and round, and every stored return equal to the one recomputed
from the stored rewards.
"""

from __future__ import annotations

import json
import math
import sqlite3
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from aeroweaver_edge.agent.memory.experience import LEGACY_RUN, SCHEMA_VERSION
from aeroweaver_edge.contracts.errors import UserError

SQLITE_MAGIC = b"SQLite format 3\x00"
RET_TOLERANCE = 1e-9


def memory_files(target: Path) -> list[Path]:
    """The memory files at ``target``: the file itself, or every SQLite file directly in
    the directory (quarantined copies and ``-wal``/``-shm`` side files excluded)."""
    if target.is_file():
        return [target]
    if not target.is_dir():
        raise UserError(
            f"{target} does not exist",
            "give the --memory-dir of a run, or one memory file",
        )
    found = []
    for path in sorted(target.iterdir()):
        if not path.is_file() or ".corrupt-" in path.name or path.name.endswith(("-wal", "-shm")):
            continue
        with path.open("rb") as f:
            if f.read(len(SQLITE_MAGIC)) == SQLITE_MAGIC:
                found.append(path)
    if not found:
        raise UserError(f"{target} holds no experience-memory file", "point at a --memory-dir")
    return found


def _connect(path: Path) -> sqlite3.Connection:
    try:
        return sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=10.0)
    except sqlite3.Error as exc:
        raise UserError(f"{path}: cannot open: {exc}", "check the path and permissions") from None


@dataclass
class FileInfo:
    path: Path
    schema_version: int | None
    records: int = 0
    shared: int = 0  # copies of peers' records (origin != "")
    rewards: int = 0
    final: int = 0
    rewarded: int = 0
    runs: set[str] = field(default_factory=set)
    by_task: dict[str, dict[str, int]] = field(default_factory=dict)
    # who each record came from: a peer (its origin) or this file's own daemon (its uav id);
    # {"records", "bytes" (state text, invocation, tokens), "shared" (copies of a peer's)}
    by_sender: dict[str, dict[str, int]] = field(default_factory=dict)


def _version(conn: sqlite3.Connection) -> int | None:
    tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    if not {"schema_version", "records", "rewards"} <= tables:
        return None
    row = conn.execute("SELECT max(version) FROM schema_version").fetchone()
    return row[0] if row is not None and isinstance(row[0], int) else None


def _run_column(conn: sqlite3.Connection) -> str:
    """``run`` in a version-2 file; the legacy run name in a version-1 file."""
    cols = {r[1] for r in conn.execute("PRAGMA table_info(records)")}
    return "run" if "run" in cols else f"'{LEGACY_RUN}'"


def _info(path: Path, conn: sqlite3.Connection) -> FileInfo:
    version = _version(conn)
    info = FileInfo(path, version)
    if version is None:
        return info
    run = _run_column(conn)
    info.records, info.final, info.rewarded, info.shared = conn.execute(
        "SELECT count(*), coalesce(sum(final), 0), count(reward), "
        "coalesce(sum(origin != ''), 0) FROM records"
    ).fetchone()
    info.rewards = conn.execute("SELECT count(*) FROM rewards").fetchone()[0]
    info.runs = {r[0] for r in conn.execute(f"SELECT DISTINCT {run} FROM records")}
    for task, role, n in conn.execute(
        "SELECT task, role, count(*) FROM records GROUP BY task, role ORDER BY task, role"
    ):
        info.by_task.setdefault(task, {})[role] = n
    for sender, n, nbytes, shared in conn.execute(
        "SELECT CASE WHEN origin != '' THEN origin ELSE uav END AS sender, count(*), "
        "coalesce(sum(length(state_text) + length(invocation) + length(tokens)), 0), "
        "coalesce(sum(origin != ''), 0) FROM records GROUP BY sender ORDER BY sender"
    ):
        info.by_sender[sender] = {"records": n, "bytes": nbytes, "shared": shared}
    return info


def stats(files: list[Path]) -> dict[str, Any]:
    """Counts per file and in total, by task and role (the shape ``stats --json`` prints)."""
    infos = []
    for path in files:
        conn = _connect(path)
        try:
            infos.append(_info(path, conn))
        except sqlite3.DatabaseError as exc:
            raise UserError(
                f"{path}: not a readable memory ({exc})", "run 'aeroweaver memory check'"
            ) from None
        finally:
            conn.close()
    by_task: dict[str, dict[str, int]] = {}
    by_sender: dict[str, dict[str, int]] = {}
    for info in infos:
        for task, roles in info.by_task.items():
            for role, n in roles.items():
                by_task.setdefault(task, {})[role] = by_task.get(task, {}).get(role, 0) + n
        for sender, counts in info.by_sender.items():
            total = by_sender.setdefault(sender, {"records": 0, "bytes": 0, "shared": 0})
            for name, n in counts.items():
                total[name] += n
    return {
        "records": sum(i.records for i in infos),
        "shared_records": sum(i.shared for i in infos),
        "rewards": sum(i.rewards for i in infos),
        "rewarded_records": sum(i.rewarded for i in infos),
        "final_records": sum(i.final for i in infos),
        "runs": len(set().union(*(i.runs for i in infos))) if infos else 0,
        "by_task": {t: dict(sorted(r.items())) for t, r in sorted(by_task.items())},
        "by_sender": dict(sorted(by_sender.items())),
        "files": [
            {
                "path": str(i.path),
                "schema_version": i.schema_version,
                "records": i.records,
                "rewards": i.rewards,
                "runs": sorted(i.runs),
                "by_sender": i.by_sender,
            }
            for i in infos
        ],
    }


def _finite_or_none(value: object) -> object:
    return value if not isinstance(value, float) or math.isfinite(value) else None


def export_rows(files: list[Path]) -> Iterator[dict[str, Any]]:
    """Every record of every file, oldest first per file, as plain JSON-able dicts."""
    for path in files:
        conn = _connect(path)
        try:
            if _version(conn) is None:
                continue
            run = _run_column(conn)
            cur = conn.execute(
                f"SELECT {run}, seq, task, role, uav, episode, round, state_text, skill, "
                "invocation, reward, ret, final, origin, reward_source, created_at "
                "FROM records ORDER BY seq"
            )
            names = [d[0] for d in cur.description]
            names[0] = "run"
            for row in cur:
                rec = {n: _finite_or_none(v) for n, v in zip(names, row, strict=True)}
                rec["final"] = bool(rec["final"])
                rec["file"] = path.name
                yield rec
        finally:
            conn.close()


def export_jsonl(files: list[Path], out: TextIO) -> int:
    """Write one JSON object per record; returns the count."""
    n = 0
    for rec in export_rows(files):
        out.write(json.dumps(rec, allow_nan=False, ensure_ascii=False) + "\n")
        n += 1
    return n


def check_file(path: Path) -> list[str]:
    """Problems of one file (empty: healthy). Never writes."""
    try:
        conn = _connect(path)
    except UserError as exc:
        return [str(exc)]
    problems: list[str] = []
    try:
        rows = conn.execute("PRAGMA integrity_check").fetchall()
        if rows != [("ok",)]:
            return ["integrity_check: " + "; ".join(str(r[0]) for r in rows[:5])]
        version = _version(conn)
        if version is None:
            return ["not an experience memory (no schema_version/records/rewards tables)"]
        if version > SCHEMA_VERSION:
            return [f"schema version {version} is newer than this release ({SCHEMA_VERSION})"]
        run = _run_column(conn)
        gamma_row = conn.execute("SELECT value FROM meta WHERE key = 'gamma'").fetchone()
        gamma = float(gamma_row[0]) if gamma_row else 0.95
        rewards: dict[tuple[str, str, int], dict[int, float]] = {}
        for r_run, uav, episode, rnd, reward in conn.execute(
            f"SELECT {run}, uav, episode, round, reward FROM rewards"
        ):
            if not math.isfinite(reward):
                problems.append(f"reward {reward!r} of {r_run}/{uav}/{episode}/{rnd} not finite")
            rewards.setdefault((r_run, uav, episode), {})[rnd] = reward
        for seq, r_run, uav, episode, rnd, reward, ret in conn.execute(
            f"SELECT seq, {run}, uav, episode, round, reward, ret FROM records "
            "WHERE origin = '' ORDER BY seq"
        ):
            where = f"record {seq} ({r_run}/{uav}/episode {episode}/round {rnd})"
            got = rewards.get((r_run, uav, episode), {})
            if reward != got.get(rnd):
                problems.append(f"{where}: reward {reward!r} but delivered {got.get(rnd)!r}")
            want = None
            for u, r in sorted(got.items()):
                if u >= rnd:
                    want = (want or 0.0) + gamma ** (u - rnd) * r
            if (ret is None) != (want is None) or (
                ret is not None
                and want is not None
                and not math.isclose(ret, want, rel_tol=RET_TOLERANCE, abs_tol=RET_TOLERANCE)
            ):
                problems.append(f"{where}: return {ret!r}, rewards give {want!r}")
        for seq, ret in conn.execute("SELECT seq, ret FROM records WHERE ret IS NOT NULL"):
            if not math.isfinite(ret):
                problems.append(f"record {seq}: return {ret!r} not finite")
    except sqlite3.DatabaseError as exc:
        problems.append(f"{type(exc).__name__}: {exc}")
    finally:
        conn.close()
    return problems


def check(files: list[Path]) -> dict[str, list[str]]:
    """Problems per file (every file appears, healthy ones with an empty list)."""
    return {str(path): check_file(path) for path in files}
