"""``aeroweaver sim --share-experience``: the switch between sharing experience as each
episode ends (default) and from the next round on, as docs/adaptation.md runs it."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from aeroweaver_edge.cli.main import build_parser, main


def test_the_default_shares_between_episodes() -> None:
    assert build_parser().parse_args(["sim"]).share_experience == "episode"


def test_a_bad_value_exits_2_with_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["sim", "--share-experience", "often"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'often'" in err


def test_sim_round_sharing_puts_peers_records_into_memory_within_the_episode(
    tmp_path: Path,
) -> None:
    out = tmp_path / "run.json"
    argv = [
        "sim", "collection_delivery", "--selector", "scripted", "--episodes", "1",
        "--rounds", "4", "--share-experience", "round", "--memory-dir", str(tmp_path),
        "--quiet", "--json", str(out),
    ]  # fmt: skip
    assert main(argv) == 0
    assert json.loads(out.read_text())["episodes"]
    with sqlite3.connect(tmp_path / "uav0.sqlite3") as conn:
        rows = conn.execute("SELECT origin, round FROM records ORDER BY seq").fetchall()
    own = {r: i for i, (o, r) in enumerate(rows) if o == ""}
    peers = [(i, r) for i, (o, r) in enumerate(rows) if o != ""]
    assert peers  # its fellow collector's records
    for i, r in peers:  # stored at the start of round r + 1: after own r, before own r + 1
        assert own[r] < i
        assert r + 1 not in own or i < own[r + 1]
