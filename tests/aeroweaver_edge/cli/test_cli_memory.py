"""``aeroweaver memory stats|export|check DIR`` on real memory files."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from aeroweaver_edge.agent.memory.experience import ExperienceMemory
from aeroweaver_edge.cli.main import main

T, R = "coverage", "searcher"


@pytest.fixture
def memory_dir(tmp_path: Path) -> Path:
    for uav in ("uav0", "uav1"):
        for run in ("run-a", "run-b"):
            with ExperienceMemory(tmp_path / f"{uav}.sqlite3", run=run, gamma=0.5) as m:
                for rnd in range(3):
                    m.append(
                        task=T,
                        role=R,
                        uav=uav,
                        episode=0,
                        round=rnd,
                        state_text=f"landmark l{rnd}",
                        skill="cover",
                        invocation="cover()",
                    )
                    m.add_reward(uav, 0, rnd, float(rnd), "sim")
                m.finalise(uav, 0)
    with ExperienceMemory(tmp_path / "uav0.sqlite3", run="run-c", gamma=0.5) as m:
        m.append(
            task=T,
            role="speaker",
            uav="uav0",
            episode=0,
            round=0,
            state_text="s",
            skill="talk",
            invocation="talk()",
        )
    return tmp_path


def test_stats_json(memory_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["memory", "stats", str(memory_dir), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["records"] == 13
    assert data["by_task"] == {"coverage": {"searcher": 12, "speaker": 1}}
    assert (data["runs"], data["rewards"], data["final_records"]) == (3, 12, 12)
    assert [f["records"] for f in data["files"]] == [7, 6]


def test_stats_text(memory_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["memory", "stats", str(memory_dir)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("13 records (0 shared by peers), 12 rewards, 3 runs in 2 file(s)")
    assert "coverage: searcher 12, speaker 1" in out


def test_export_jsonl(memory_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["memory", "export", str(memory_dir)]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = [json.loads(line) for line in lines]
    assert len(rows) == 13
    first = rows[0]
    assert {k: first[k] for k in ("file", "run", "uav", "episode", "round", "skill")} == {
        "file": "uav0.sqlite3", "run": "run-a", "uav": "uav0", "episode": 0, "round": 0,
        "skill": "cover",
    }  # fmt: skip
    assert first["ret"] == 0.0 + 0.5 * 1.0 + 0.25 * 2.0
    unrewarded = [r for r in rows if r["role"] == "speaker"]
    assert unrewarded[0]["ret"] is None


def test_export_to_a_file(memory_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "out" / "records.jsonl"
    assert main(["memory", "export", str(memory_dir / "uav1.sqlite3"), "-o", str(out)]) == 0
    assert len(out.read_text().splitlines()) == 6


def test_check_ok_then_a_problem(memory_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["memory", "check", str(memory_dir)]) == 0
    assert capsys.readouterr().out.count(": ok") == 2
    conn = sqlite3.connect(memory_dir / "uav1.sqlite3")
    conn.execute("UPDATE records SET reward = 42.0 WHERE run = 'run-b' AND round = 2")
    conn.commit()
    conn.close()
    assert main(["memory", "check", str(memory_dir)]) == 1
    out = capsys.readouterr().out
    assert "uav1.sqlite3: 1 problem(s)" in out
    assert "reward 42.0 but delivered 2.0" in out
