"""Boot epochs from a persisted counter, not from the wall clock.

Every start of a process increments its counter in the state directory (temp file, fsync,
rename, fsync the directory), so a restart is always a strictly larger epoch even when the
clock jumped back, and a genuine step between two epochs is small: receivers can refuse an
unauthenticated epoch that leaps far ahead (``ReplayFilter(max_epoch_step=...)``).
"""

from __future__ import annotations

from pathlib import Path

from aeroweaver_edge.config import check_id
from aeroweaver_edge.security.pki import write_file

# A genuine sender's epoch grows by one per start; allow many unseen restarts in between.
MAX_EPOCH_STEP = 1024


class BootCounterError(OSError):
    """The counter file cannot be read or written; the message names it."""


def next_epoch(state_dir: str | Path, identity: str) -> int:
    """Increment and return the boot counter of ``identity`` (first start: 1).

    A corrupt counter file is an error, never a silent reset: restarting from 1 would make
    receivers refuse this process's traffic as a replay of its old epochs.
    """
    check_id(identity, "identity")
    path = Path(state_dir) / f"{identity}.boot"
    try:
        text = path.read_text(encoding="ascii").strip()
    except FileNotFoundError:
        text = "0"
    except (OSError, UnicodeDecodeError) as exc:
        raise BootCounterError(f"{path}: cannot read boot counter: {exc}") from None
    if not text.isdigit():
        raise BootCounterError(f"{path}: boot counter is not a number: {text[:20]!r}")
    epoch = int(text) + 1
    try:
        write_file(path, f"{epoch}\n".encode())
    except OSError as exc:
        raise BootCounterError(
            f"{path}: cannot write boot counter: {exc.strerror or exc}"
        ) from None
    return epoch
