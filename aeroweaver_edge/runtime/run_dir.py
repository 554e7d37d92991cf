"""A run's temporary directory that nobody leaves behind, whoever is killed.

A simulated run keeps its daemons' configs, logs and (by default) experience memory in a
temporary directory. Every process of the run holds a *shared* ``flock`` on the directory's
lock file while it uses it: the run itself from creation to removal, each daemon process
from its start to its exit. The kernel drops a process's locks when it dies, even by
SIGKILL, so "an exclusive lock can be taken" means "nobody of this run is left":

- the run removes the directory at its end, as before;
- a daemon process that exits tries the exclusive lock; if it gets it, it was the last one
  out (its run was killed), so it removes the directory;
- every new run sweeps the temporary directory for run directories whose lock it can take
  exclusively (a run killed with no daemon process left, e.g. in-process mode).

The lock file is created under a temporary name and renamed into place only once locked,
so a sweep never finds the lock of a run that is still being created unlocked.
"""

from __future__ import annotations

import fcntl
import logging
import os
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Self

log = logging.getLogger(__name__)

PREFIX = "aeroweaver-"
LOCK_NAME = ".aw-run.lock"
OWNER_NAME = ".aw-run.owner"  # pid of the run, for people (the lock decides)
ENV_DIR = "AEROWEAVER_RUN_DIR"  # set for the daemon processes of a run
ENV_PARENT = "AEROWEAVER_PARENT_PID"


def _try_exclusive(fd: int) -> bool:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _remove_if_last(path: Path, fd: int) -> bool:
    """With ``fd`` (the lock, opened) held shared or not at all: remove ``path`` if no other
    process of the run holds the lock. Returns whether it was removed."""
    if not _try_exclusive(fd):
        return False
    shutil.rmtree(path, ignore_errors=True)
    return not path.exists()


class RunDir:
    """The run's side: create, lock shared, remove at the end (``with RunDir.create()``)."""

    def __init__(self, path: Path, fd: int) -> None:
        self.path = path
        self._fd: int | None = fd

    @classmethod
    def create(cls, prefix: str = PREFIX, parent: Path | None = None) -> RunDir:
        path = Path(tempfile.mkdtemp(prefix=prefix, dir=parent))
        staging = path / f"{LOCK_NAME}.new"
        fd = os.open(staging, os.O_RDWR | os.O_CREAT, 0o600)
        fcntl.flock(fd, fcntl.LOCK_SH)
        (path / OWNER_NAME).write_text(f"{os.getpid()}\n", encoding="ascii")
        os.replace(staging, path / LOCK_NAME)
        return cls(path, fd)

    def close(self) -> None:
        """Remove the directory (daemons still in it are the caller's to stop first)."""
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        try:
            shutil.rmtree(self.path, ignore_errors=True)
        finally:
            os.close(fd)

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class RunMember:
    """A daemon process's side: hold the run's lock while alive; the last one out removes
    the directory (``with RunMember.join(path)``)."""

    def __init__(self, path: Path, fd: int) -> None:
        self.path = path
        self._fd: int | None = fd
        self.removed = False

    @classmethod
    def join(cls, path: Path) -> RunMember | None:
        """Take a shared lock on the run's directory; None if it is gone already (the run
        ended or was cleaned up before this process got here: it has nothing to run)."""
        try:
            fd = os.open(path / LOCK_NAME, os.O_RDWR)
        except OSError:
            return None
        fcntl.flock(fd, fcntl.LOCK_SH)
        if not (path / LOCK_NAME).exists():  # removed while we waited: an orphan lock
            os.close(fd)
            return None
        return cls(path, fd)

    def leave(self) -> bool:
        """Drop our lock; remove the directory if nobody of the run holds it any more."""
        if self._fd is None:
            return self.removed
        fd, self._fd = self._fd, None
        try:
            self.removed = _remove_if_last(self.path, fd)
        finally:
            os.close(fd)
        if self.removed:
            log.info("removed %s: the last process of its run is gone", self.path)
        return self.removed

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.leave()


def attach_to_run(environ: Mapping[str, str]) -> RunMember | None:
    """For a daemon process a run started (``ENV_DIR``/``ENV_PARENT`` set): die with the
    run's process and hold the run directory's lock. None when not started by a run."""
    from aeroweaver_edge.contracts.errors import RunFailed
    from aeroweaver_edge.runtime.lifecycle import die_with_parent

    parent = environ.get(ENV_PARENT, "")
    if parent.isdigit():
        die_with_parent(int(parent))
    where = environ.get(ENV_DIR)
    if not where:
        return None
    member = RunMember.join(Path(where))
    if member is None:
        raise RunFailed(f"run directory {where} is gone: the run that started this daemon ended")
    return member


def sweep_stale(parent: Path | None = None, prefix: str = PREFIX) -> list[Path]:
    """Remove run directories under ``parent`` (default: the temporary directory) whose
    run and daemons are all gone. Directories without our lock file are never touched."""
    root = Path(parent or tempfile.gettempdir())
    try:
        candidates = sorted(p for p in root.iterdir() if p.name.startswith(prefix))
    except OSError:
        return []
    removed: list[Path] = []
    for path in candidates:
        try:
            fd = os.open(path / LOCK_NAME, os.O_RDWR)
        except OSError:
            continue
        try:
            if _remove_if_last(path, fd):
                removed.append(path)
        finally:
            os.close(fd)
    if removed:
        log.info("removed %d stale run directories: %s", len(removed), removed)
    return removed


__all__ = ["ENV_DIR", "ENV_PARENT", "RunDir", "RunMember", "attach_to_run", "sweep_stale"]
