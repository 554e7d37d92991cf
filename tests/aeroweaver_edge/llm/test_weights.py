"""The weight-format conversion on the real shipped model, and its cache's checks.

The conversion takes a few seconds (numpy), so one module-scoped conversion to Q8_0 serves
every check that needs a converted file; the cache tests then damage that file and watch
``prepare`` notice and rebuild it.
"""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
import threading
from pathlib import Path
from typing import Any

import gguf
import httpx
import numpy as np
import pytest

from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.llm import embedded, weights
from aeroweaver_edge.llm.embedded import EmbeddedServer

# Converting and parsing a 98 MB model takes seconds idle, minutes on a loaded 2-core box.
pytestmark = pytest.mark.timeout(900)


def _shipped() -> Path:
    return embedded.find_model()


@pytest.fixture(scope="module")
def converted(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """(shipped, cache dir, the Q8_0 file) converted once for this module."""
    source = _shipped()
    cache = tmp_path_factory.mktemp("xdg") / "aeroweaver"  # $XDG_CACHE_HOME/aeroweaver
    return source, cache, weights.prepare(source, "q8_0", cache)


def _fields(path: Path) -> dict[str, Any]:
    """Each metadata key's encoded bytes (name, type and value), and general.file_type."""
    reader = gguf.GGUFReader(str(path))
    out: dict[str, Any] = {
        name: b"".join(part.tobytes() for part in field.parts)
        for name, field in reader.fields.items()
        if not name.startswith("GGUF.")
    }
    file_type = reader.get_field("general.file_type")
    out["file_type"] = None if file_type is None else int(file_type.contents())
    return out


@pytest.mark.embedded
def test_conversion_keeps_every_key_and_sets_file_type(converted: tuple[Path, Path, Path]) -> None:
    source, _, output = converted
    before, after = _fields(source), _fields(output)
    assert before.keys() == after.keys()
    for name in before:
        if name not in ("general.file_type", "file_type"):
            assert after[name] == before[name], name  # the same bytes: name, type, value
    assert after["file_type"] == int(gguf.LlamaFileType.MOSTLY_Q8_0)
    assert before["file_type"] == int(gguf.LlamaFileType.MOSTLY_Q4_1)


@pytest.mark.embedded
def test_conversion_round_trips_the_weights(converted: tuple[Path, Path, Path]) -> None:
    """Every tensor is there with its shape; Q4_1 ones are now Q8_0 and decode to within
    Q8_0's rounding of the Q4_1 values (half a step of amax/127 per 32-weight block)."""
    source, _, output = converted
    old = {t.name: t for t in gguf.GGUFReader(str(source)).tensors}
    new = {t.name: t for t in gguf.GGUFReader(str(output)).tensors}
    assert old.keys() == new.keys()
    q4_1, q8_0 = gguf.GGMLQuantizationType.Q4_1, gguf.GGMLQuantizationType.Q8_0
    converted_count = 0
    for name, a in old.items():
        b = new[name]
        assert list(a.shape) == list(b.shape), name
        if a.tensor_type != q4_1:
            assert b.tensor_type == a.tensor_type, name
            assert np.array_equal(a.data, b.data), name
            continue
        converted_count += 1
        assert b.tensor_type == q8_0, name
        x = gguf.quants.dequantize(a.data, q4_1).reshape(-1, 32)
        y = gguf.quants.dequantize(b.data, q8_0).reshape(-1, 32)
        step = np.abs(x).max(axis=1, keepdims=True) / 127
        # half a step, plus the f16 rounding of the block scale
        assert np.all(np.abs(x - y) <= step * 0.5 + np.abs(x) * 2e-3 + 1e-7), name
    assert converted_count == 210  # 30 blocks x 7 matrices


@pytest.mark.embedded
def test_the_server_loads_the_converted_file(
    converted: tuple[Path, Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """llama.cpp accepts the written file and answers with label log-probs from it."""
    _, cache, output = converted
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache.parent))
    monkeypatch.delenv(weights.WEIGHTS_ENV, raising=False)
    with EmbeddedServer(threads=1) as server:  # the default format: Q8_0
        assert server.served_path == output
        body = {
            "model": server.model,
            "messages": [{"role": "user", "content": "Options:\nA. land\nB. hold\nAnswer:"}],
            "max_tokens": 1,
            "logprobs": True,
            "top_logprobs": 20,
        }
        answer = httpx.post(f"{server.base_url}/chat/completions", json=body, timeout=300).json()
    top = answer["choices"][0]["logprobs"]["content"][0]["top_logprobs"]
    assert len(top) == 20
    assert all(math.isfinite(t["logprob"]) and t["logprob"] <= 0 for t in top)


@pytest.mark.embedded
def test_a_valid_cache_is_reused(converted: tuple[Path, Path, Path]) -> None:
    source, cache, output = converted
    stamp = output.stat().st_mtime_ns
    assert weights.verify(source, output, "q8_0") is None
    assert weights.prepare(source, "q8_0", cache) == output
    assert output.stat().st_mtime_ns == stamp  # not rewritten
    manifest = json.loads(weights.manifest_path(output).read_text())
    assert manifest["source_sha256"] == weights.sha256_file(source)
    assert manifest["output_sha256"] == weights.sha256_file(output)


def _flip_byte(path: Path, offset: int) -> None:
    with path.open("r+b") as f:
        f.seek(offset)
        byte = f.read(1)
        f.seek(offset)
        f.write(bytes([byte[0] ^ 0xFF]))


@pytest.mark.embedded
@pytest.mark.parametrize("damage", ["flip", "truncate", "no_manifest", "bad_manifest"])
def test_a_damaged_cache_is_rebuilt(
    converted: tuple[Path, Path, Path], damage: str, caplog: pytest.LogCaptureFixture
) -> None:
    source, cache, output = converted
    good = weights.sha256_file(output)
    if damage == "flip":
        _flip_byte(output, output.stat().st_size // 2)
        expected = "sha256 does not match"
    elif damage == "truncate":
        os.truncate(output, output.stat().st_size - 4096)
        expected = "bytes, the manifest"
    elif damage == "no_manifest":
        weights.manifest_path(output).unlink()
        expected = "no readable manifest"
    else:
        weights.manifest_path(output).write_text("{not json")
        expected = "no readable manifest"
    assert expected in (weights.verify(source, output, "q8_0") or "")
    with caplog.at_level(logging.WARNING, logger="aeroweaver_edge.llm.weights"):
        assert weights.prepare(source, "q8_0", cache) == output
    assert "rebuilding" in caplog.text
    assert weights.sha256_file(output) == good  # the conversion is deterministic
    assert weights.verify(source, output, "q8_0") is None
    assert not [p for p in cache.iterdir() if p.name.endswith(".tmp")]  # no temp file left


@pytest.mark.embedded
def test_a_changed_source_is_reconverted(
    converted: tuple[Path, Path, Path], tmp_path: Path
) -> None:
    source, _, output = converted
    other = tmp_path / source.name
    shutil.copyfile(source, other)
    _flip_byte(other, other.stat().st_size - 1)  # the last weight byte
    assert weights.verify(other, output, "q8_0") == "the source model changed"
    fresh = weights.prepare(other, "q8_0", tmp_path / "cache")
    assert weights.verify(other, fresh, "q8_0") is None


@pytest.mark.embedded
def test_concurrent_first_uses_convert_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    source = _shipped()
    calls: list[str] = []
    real = weights.convert

    def counting(src: Path, dest: Path, fmt: str) -> None:
        calls.append(fmt)
        real(src, dest, fmt)

    monkeypatch.setattr(weights, "convert", counting)
    results: list[Path] = []
    errors: list[BaseException] = []

    def use() -> None:
        try:
            results.append(weights.prepare(source, "q4_0", tmp_path))
        except BaseException as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=use) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert calls == ["q4_0"]
    assert len(set(results)) == 1
    assert weights.verify(source, results[0], "q4_0") is None
    assert _fields(results[0])["file_type"] == int(gguf.LlamaFileType.MOSTLY_Q4_0)


def test_formats_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(weights.WEIGHTS_ENV, raising=False)
    assert weights.default_format() == weights.DEFAULT == "q8_0"
    monkeypatch.setenv(weights.WEIGHTS_ENV, " Q4_1 ")
    assert EmbeddedServer().weights == "q4_1"
    assert EmbeddedServer(weights="f16").weights == "f16"  # an explicit format wins
    for bad in ("q5_k", "8", "fast"):
        monkeypatch.setenv(weights.WEIGHTS_ENV, bad)
        with pytest.raises(UserError, match=f"AEROWEAVER_LLM_WEIGHTS='{bad}'.*q4_1, q8_0"):
            EmbeddedServer()
    monkeypatch.delenv(weights.WEIGHTS_ENV)
    with pytest.raises(UserError, match="weights='int3'"):
        EmbeddedServer(weights="int3")


def test_cache_dir_follows_xdg(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert weights.cache_dir() == tmp_path / "aeroweaver"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/dir")  # not absolute: ignored (XDG spec)
    assert weights.cache_dir() == Path.home() / ".cache" / "aeroweaver"


@pytest.mark.embedded
def test_an_unwritable_cache_serves_the_shipped_file(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    source = _shipped()
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))
    with pytest.raises(weights.WeightsUnavailable, match="cannot create the cache directory"):
        weights.prepare(source, "q8_0")
    with caplog.at_level(logging.WARNING, logger="aeroweaver_edge.llm.embedded"):
        assert EmbeddedServer(weights="q8_0")._prepared_model() == source
    assert "serving the shipped q4_1 weights instead of q8_0" in caplog.text
    assert EmbeddedServer(weights="q4_1")._prepared_model() == source  # no conversion at all
