from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from aeroweaver_edge.skills import SkillRegistry, load_skills
from aeroweaver_lab.retrieval_eval import (
    DATA,
    VARIANTS,
    load_phrasings,
    main,
    recall_at_k,
    retriever_rows,
    run_study,
)
from commander.task_record import TASK_TYPES


@pytest.fixture(scope="module")
def registry() -> SkillRegistry:
    return load_skills()


def test_recall_at_k() -> None:
    assert recall_at_k(["a", "b", "c"], ["a", "c"], 2) == 0.5
    assert recall_at_k(["a", "b", "c"], ["a", "c"], 3) == 1.0
    assert recall_at_k([], ["a"], 8) == 0.0


def test_phrasings_are_well_formed(registry: SkillRegistry) -> None:
    data = load_phrasings()
    assert set(data) == set(TASK_TYPES)
    raw = json.loads(DATA.read_text())
    for task, tp in data.items():
        assert all(s in registry for s in tp.required), task
        original = tp.phrasings["original"]
        sentences = re.findall(r"[^.!?]+[.!?]", original)
        assert len(sentences) >= 2, task
        assert tp.phrasings["reordered"] == " ".join(s.strip() for s in reversed(sentences))
        assert tp.phrasings["distractor"].startswith(original + " ")
        assert tp.phrasings["distractor"][len(original) + 1 :] in raw["distractors"].values()
        assert len({tp.phrasings[v] for v in VARIANTS}) == len(VARIANTS)


def test_coverage_original_recall_at_8_finds_cover_landmark(registry: SkillRegistry) -> None:
    rows = retriever_rows(registry, load_phrasings(), ks=(8,))
    row = next(r for r in rows if r.task == "coverage" and r.variant == "original")
    assert "cover_landmark" in row.found


def test_study_and_cli(
    registry: SkillRegistry, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    study = run_study(registry, load_phrasings(), ks=(3, 8))
    assert set(study["summary"]) == {"text", "text+body", "harness"}
    for table in study["summary"].values():
        assert set(table) == {*VARIANTS, "overall"}
        assert all(0.0 <= v <= 1.0 for row in table.values() for v in row.values())
    out = tmp_path / "study.json"
    assert main(["--json", str(out), "--k", "3", "8"]) == 0
    printed = capsys.readouterr().out
    assert "| **overall** |" in printed
    assert "text R@8" in printed
    assert json.loads(out.read_text())["ks"] == [3, 8]
