"""The published benchmark rebuilds from its archive: the command docs/benchmark.md gives runs
on a copy of docs/benchmark/n10 and writes the committed table, CSV and summary byte for byte,
and the tables in docs/benchmark.md are that table.md. So neither the doc nor the archive can
drift from the cells they describe."""

from __future__ import annotations

import re
import shlex
import shutil
import struct
from pathlib import Path

import pytest

from aeroweaver_edge.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "benchmark.md"
ARCHIVE = ROOT / "docs" / "benchmark" / "n10"
TEXT_OUTPUTS = ["table.md", "results.csv", "summary.json"]
PLOTS = ["returns.png", "tokens.png"]
PLOTS_MADE_WITH = "3.11.2"  # matplotlib; another version draws the same plot in other bytes
REBUILD = re.compile(r"^aeroweaver bench run --out docs/benchmark/n10 --report-only.*$", re.M)


def _rebuild_argv(out: Path) -> list[str]:
    found = REBUILD.findall(DOC.read_text(encoding="utf-8"))
    assert len(found) == 1, "docs/benchmark.md gives one command that rebuilds its tables"
    argv = shlex.split(found[0].split("#")[0])[1:]
    return [str(out) if a == "docs/benchmark/n10" else a for a in argv]


def _png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def test_the_archive_rebuilds_the_published_outputs(tmp_path: Path) -> None:
    out = tmp_path / "n10"
    shutil.copytree(ARCHIVE / "runs", out / "runs")
    shutil.copytree(ARCHIVE / "setup", out / "setup")
    assert main(_rebuild_argv(out)) == 0
    for name in TEXT_OUTPUTS:
        assert (out / name).read_bytes() == (ARCHIVE / name).read_bytes(), name
    matplotlib = pytest.importorskip("matplotlib")
    for name in PLOTS:
        made, kept = (out / name).read_bytes(), (ARCHIVE / name).read_bytes()
        if matplotlib.__version__ == PLOTS_MADE_WITH:
            assert made == kept, name
        else:
            assert _png_size(made) == _png_size(kept), name


def test_the_doc_shows_the_archived_table() -> None:
    doc = DOC.read_text(encoding="utf-8")
    block = re.search(r"<!-- table -->\n(.*?)<!-- /table -->\n", doc, re.S)
    assert block, "docs/benchmark.md marks its tables with <!-- table --> ... <!-- /table -->"
    assert block.group(1) == (ARCHIVE / "table.md").read_text(encoding="utf-8")
