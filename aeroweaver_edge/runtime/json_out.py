"""JSON that other tools can read: never NaN or Infinity (``null`` instead), written
atomically (temporary file in the same directory, fsync, rename) so a crash mid-write
leaves the old file or the new one, never half of one."""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any


def json_safe(value: Any) -> Any:
    """``value`` with every non-finite float replaced by ``None``; other leaves kept."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [json_safe(v) for v in value]
    return value


def dumps(value: Any, *, indent: int | None = 2) -> str:
    """Strict JSON text (``allow_nan=False`` after ``json_safe``); unknown leaves as str."""
    return json.dumps(json_safe(value), indent=indent, default=str, allow_nan=False)


def write_json_file(path: Path, value: Any) -> None:
    _write_text(path, dumps(value) + "\n")


def write_jsonl_file(path: Path, rows: Iterable[Any]) -> None:
    """JSON Lines (one strict JSON object per line), written atomically like the above."""
    _write_text(path, "".join(dumps(row, indent=None) + "\n" for row in rows))


def _write_text(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
