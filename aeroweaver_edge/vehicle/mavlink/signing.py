"""MAVLink 2 signing material: a per-vehicle key file and a persisted timestamp.

The key file holds 32 raw bytes or 64 hex characters and must not be readable by anyone
but its owner (mode 0600 or stricter, owned by this user or root): a key others can read
is refused, not used. The signing timestamp (10 us units since 2015-01-01) must never go
backwards, also across restarts with a clock that is behind, so it is stored next to the
key and rewritten atomically (temp file, fsync, rename, fsync of the directory).
"""

from __future__ import annotations

import contextlib
import os
import stat
import time
from pathlib import Path

EPOCH_2015 = 1_420_070_400  # 2015-01-01T00:00:00Z
KEY_BYTES = 32


class SigningError(ValueError):
    """The key file is missing, malformed or too widely readable."""

    def explain(self) -> tuple[int, str]:
        return 2, f"signing: {self}"


def now_timestamp() -> int:
    return int((time.time() - EPOCH_2015) * 100_000)


def load_key(path: str | Path) -> bytes:
    """Read a key file after checking owner and permissions."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError as exc:
        raise SigningError(f"{p}: cannot read signing key: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise SigningError(f"{p}: signing key must be a regular file")
    if st.st_mode & 0o077:
        raise SigningError(
            f"{p}: signing key is accessible by group/others (mode {stat.S_IMODE(st.st_mode):o});"
            " chmod 600 it"
        )
    if st.st_uid not in (os.geteuid(), 0):
        raise SigningError(f"{p}: signing key must be owned by this user or root")
    raw = p.read_bytes()
    text = raw.strip()
    if len(raw) == KEY_BYTES:
        return raw
    try:
        key = bytes.fromhex(text.decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        key = b""
    if len(key) != KEY_BYTES:
        raise SigningError(f"{p}: a signing key is 32 raw bytes or 64 hex characters")
    return key


def write_key(path: str | Path, key: bytes | None = None) -> bytes:
    """Create a key file (0600) with ``key`` or a fresh random one; returns the key."""
    key = os.urandom(KEY_BYTES) if key is None else key
    if len(key) != KEY_BYTES:
        raise SigningError(f"a signing key is {KEY_BYTES} bytes, got {len(key)}")
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.fchmod(fd, 0o600)
        os.write(fd, key.hex().encode() + b"\n")
        os.fsync(fd)
    finally:
        os.close(fd)
    return key


class TimestampStore:
    """The last signing timestamp used, persisted so it only ever moves forward."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.saved = 0

    def load(self) -> int:
        """Start value: the max of the stored value (+1) and the clock."""
        stored = 0
        with contextlib.suppress(OSError, ValueError):
            stored = int(self.path.read_text(encoding="ascii").strip())
        self.saved = stored
        return max(stored + 1, now_timestamp())

    def save(self, timestamp: int) -> None:
        """Atomically record ``timestamp`` (never a smaller one than saved before)."""
        if timestamp <= self.saved:
            return
        tmp = self.path.with_name(self.path.name + ".tmp")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            os.write(fd, f"{timestamp}\n".encode("ascii"))
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, self.path)
        dfd = os.open(self.path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
        self.saved = timestamp


def timestamp_path(key_path: str | Path) -> Path:
    p = Path(key_path)
    return p.with_name(p.name + ".timestamp")
