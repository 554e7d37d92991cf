"""The adaptation bench: variants on the same layouts, traces kept, resumable."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from aeroweaver_lab.bench.adaptation import Variant, main


def test_variant_parsing() -> None:
    assert Variant.parse("0.8") == Variant(0.8)
    assert Variant.parse("0.8:final") == Variant(0.8, True)
    assert Variant.parse("0").name == "beta=0"
    assert Variant(0.8, True).slug == "b0.8-final"
    for bad in ("x", "-1", "0.8:other", "nan"):
        with pytest.raises(argparse.ArgumentTypeError):
            Variant.parse(bad)


def test_two_variants_two_episodes_scripted(tmp_path: Path) -> None:
    argv = [
        "--tasks",
        "coverage",
        "--episodes",
        "2",
        "--variants",
        "0.8",
        "0.8:final",
        "0",
        "--selector",
        "scripted",
        "--out",
        str(tmp_path),
    ]
    assert main(argv) == 0
    data = json.loads((tmp_path / "results.json").read_text())
    runs = {r["variant"]: r for r in data["runs"]}
    assert set(runs) == {"beta=0.8", "beta=0.8 final-only", "beta=0"}
    for r in runs.values():
        assert [e["episode"] for e in r["episodes"]] == [0, 1]
        assert Path(r["trace"]).is_file()
    # episode 0 starts from an empty memory: identical in every variant
    first = {round(r["episodes"][0]["team_return"], 9) for r in runs.values()}
    assert len(first) == 1
    # final-only: no in-flight evidence, so nothing can be corrected in the first episode
    assert runs["beta=0.8 final-only"]["episodes"][0]["corrected"] == 0
    assert runs["beta=0"]["episodes"][1]["corrected"] == 0
    table = (tmp_path / "table.md").read_text()
    assert "Paired by episode against `beta=0`" in table
    stamp = (tmp_path / "runs" / "coverage" / "seed1" / "b0.8" / "result.json").stat().st_mtime
    assert main(argv) == 0  # resumed: nothing rerun
    assert (
        tmp_path / "runs" / "coverage" / "seed1" / "b0.8" / "result.json"
    ).stat().st_mtime == stamp
