"""The skill loader: shipped packages load, broken ones are refused naming file and field."""

from __future__ import annotations

import math
import signal
from pathlib import Path

import pytest

from aeroweaver_edge.contracts.actions import Hold, Intent, MoveTo
from aeroweaver_edge.contracts.observation import Observation, VehicleState
from aeroweaver_edge.contracts.skill_api import SkillContext
from aeroweaver_edge.runtime.signals import Stopped, forget_early_stops, stop_before_loop
from aeroweaver_edge.skills import (
    SkillError,
    SkillParamError,
    SkillRegistry,
    default_root,
    load_skills,
)

SHIPPED = {
    # the paper's 22-skill task catalogue
    "cover_landmark", "explore_local", "return_in_bounds", "hold_position", "pursue_target",
    "follow_peer", "evade_peer", "signal_goal", "follow_signal", "encode_message",
    "decode_message", "guess_message", "take_formation_slot", "signal_target", "seek_food",
    "seek_cover", "collect_treasure", "deliver_treasure", "meet_collector", "approach_goal",
    "approach_decoy", "infer_goal",
    # flight skills
    "take_off", "go_to", "orbit", "land", "return_home",
}  # fmt: skip

GOOD_MD = """\
---
name: {name}
description: Fly somewhere useful.
tags: [test]
aliases: [{name}_alias]
inputs:
  speed: cruise speed in m/s
  label: free text
conditions:
  - always
executor: skill.py
provenance: tests
effects: [actuates]
---
Prose for the LLM.
"""

GOOD_PY = """\
from __future__ import annotations

from aeroweaver_edge.contracts.actions import Intent, MoveTo
from aeroweaver_edge.contracts.skill_api import Observation, SkillContext, SkillParams


class Params(SkillParams):
    speed: float = 1.0
    label: str = "x"


def options(obs: Observation, ctx: SkillContext) -> list[Params]:
    return [Params()]


def execute(params: Params, obs: Observation, ctx: SkillContext) -> Intent:
    return Intent(MoveTo(({north}, 0.0, -ctx.altitude_m), speed=params.speed))
"""

OBS = Observation(uav="u0", episode=0, round=0, own=VehicleState((0.0, 0.0, -5.0), (0.0,) * 3))
CTX = SkillContext(uav="u0", uav_index=0, role="searcher", task="coverage")


def write_pkg(
    root: Path,
    name: str,
    md: str | None = GOOD_MD,
    py: str | None = GOOD_PY,
    north: float = 1.0,
) -> Path:
    folder = root / name
    folder.mkdir(parents=True)
    if md is not None:
        (folder / "skill.md").write_text(md.format(name=name), encoding="utf-8")
    if py is not None:
        (folder / "skill.py").write_text(py.replace("{north}", repr(north)), encoding="utf-8")
    return folder


@pytest.fixture
def root(tmp_path: Path) -> Path:
    root = tmp_path / "skills"
    write_pkg(root, "good")
    return root


def refusal(root: Path) -> str:
    with pytest.raises(SkillError) as info:
        load_skills(root)
    return str(info.value)


# ------------------------------------------------------------------ shipped packages


def test_shipped_packages_load() -> None:
    reg = load_skills()
    assert set(reg.names()) == SHIPPED
    assert default_root().name == "skills"


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_json_schema_is_generated_from_params(name: str) -> None:
    skill = load_skills().get(name)
    schema = skill.json_schema()
    assert schema["type"] == "object"
    assert schema["additionalProperties"] is False
    assert schema["title"] == name
    assert set(schema["properties"]) == set(skill.params.model_fields)
    schema["title"] = "mutated"  # a copy: callers cannot corrupt the registry
    assert skill.json_schema()["title"] == name


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_documents_are_complete(name: str) -> None:
    skill = load_skills().get(name)
    assert skill.body
    assert skill.doc.tags
    assert skill.doc.aliases
    assert skill.doc.conditions
    assert skill.doc.executor == "skill.py"
    assert skill.doc.provenance
    text = skill.prompt_text()
    assert text.startswith(f"{name}: {skill.description}")
    assert " Parameters: " in text
    assert " Conditions: " in text


def test_prompt_text_lists_parameters() -> None:
    text = load_skills().get("cover_landmark").prompt_text()
    assert "Parameters: target_id (string): " in text
    assert "Parameters: none." in load_skills().get("hold_position").prompt_text()


def test_shipped_folders_are_python_packages() -> None:
    """setuptools ships skill.py only from packages (pyproject ships skill.md as data)."""
    folders = [p for p in default_root().iterdir() if p.is_dir() and p.name[0] not in "_."]
    assert {p.name for p in folders} == SHIPPED
    for folder in folders:
        assert (folder / "__init__.py").is_file(), folder


def test_documents_and_subset() -> None:
    reg = load_skills()
    docs = {d.name: d for d in reg.documents()}
    assert set(docs) == SHIPPED
    assert "cover_target" in docs["cover_landmark"].aliases
    sub = reg.subset(["hold_position", "cover_landmark", "hold_position"])
    assert isinstance(sub, SkillRegistry)
    assert sub.names() == ("hold_position", "cover_landmark")
    assert "explore_local" not in sub
    assert len(sub) == 2
    with pytest.raises(KeyError, match="nope"):
        reg.subset(["hold_position", "nope"])
    with pytest.raises(KeyError, match="nope"):
        reg.get("nope")


# ------------------------------------------------------------------ external directories


def test_external_directory_loads_and_runs(root: Path) -> None:
    reg = load_skills(root)
    skill = reg.get("good")
    [params] = skill.options(OBS, CTX)
    assert skill.execute(params, OBS, CTX) == Intent(MoveTo((1.0, 0.0, -5.0), speed=1.0))
    assert skill.invocation(params) == "good(speed=1.0, label=x)"


def test_same_skill_name_in_two_roots_does_not_clash(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    write_pkg(a, "same", north=1.0)
    write_pkg(b, "same", north=2.0)
    ra, rb = load_skills(a), load_skills(b)
    sa, sb = ra.get("same"), rb.get("same")
    intent_a = sa.execute(sa.options(OBS, CTX)[0], OBS, CTX)
    intent_b = sb.execute(sb.options(OBS, CTX)[0], OBS, CTX)
    assert isinstance(intent_a.motion, MoveTo)
    assert intent_a.motion.target[0] == 1.0
    assert isinstance(intent_b.motion, MoveTo)
    assert intent_b.motion.target[0] == 2.0
    assert sa.params is not sb.params


def test_private_folders_are_ignored(root: Path) -> None:
    (root / "__pycache__").mkdir()
    (root / "_drafts").mkdir()
    (root / "__init__.py").write_text("")
    assert load_skills(root).names() == ("good",)


def test_missing_root_is_refused(tmp_path: Path) -> None:
    with pytest.raises(SkillError, match="not found"):
        load_skills(tmp_path / "absent")


# ------------------------------------------------------------------ broken packages

TOO_LONG = "x" * 1025

BROKEN_MD = [
    pytest.param(
        "Prose without front matter.\n",
        "skills/bad/skill.md: line 1: missing YAML front matter",
        id="no-front-matter",
    ),
    pytest.param(
        "---\nname: bad\ndescription: Fly.\neffects: [actuates]\nProse, never closed.\n",
        "skills/bad/skill.md: line 1: front matter is not closed",
        id="unclosed-front-matter",
    ),
    pytest.param(
        "---\nname: bad\ndescription: [unclosed\neffects: [actuates]\n---\nProse.\n",
        "skills/bad/skill.md: line 4: YAML syntax error",
        id="bad-yaml",
    ),
    pytest.param(
        "---\nname: bad\nname: bad\ndescription: Fly.\neffects: [actuates]\n---\nProse.\n",
        "skills/bad/skill.md: line 3: YAML syntax error: duplicate key 'name'",
        id="duplicate-key",
    ),
    pytest.param(
        "---\n- name\n- bad\n---\nProse.\n",
        "skills/bad/skill.md: line 2: front matter must be a YAML mapping",
        id="not-a-mapping",
    ),
    pytest.param(
        GOOD_MD.replace("name: {name}", "name: other"),
        "skills/bad/skill.md: front matter field 'name': 'other' must equal the folder name 'bad'",
        id="name-folder-mismatch",
    ),
    pytest.param(
        GOOD_MD.replace("name: {name}", "name: Bad Name"),
        "skills/bad/skill.md: front matter field 'name': String should match pattern",
        id="name-not-lowercase",
    ),
    pytest.param(
        GOOD_MD.replace("Fly somewhere useful.", TOO_LONG),
        "skills/bad/skill.md: front matter field 'description': String should have at most 1024",
        id="description-too-long",
    ),
    pytest.param(
        GOOD_MD.replace("description: Fly somewhere useful.\n", ""),
        "skills/bad/skill.md: front matter field 'description': Field required",
        id="description-missing",
    ),
    pytest.param(
        GOOD_MD.replace("description: Fly somewhere useful.", "description: '   '"),
        "skills/bad/skill.md: front matter field 'description': String should have at least 1",
        id="description-blank",
    ),
    pytest.param(
        GOOD_MD.replace("provenance: tests", "provenance: tests\ncolour: red"),
        "skills/bad/skill.md: front matter field 'colour': unknown field",
        id="unknown-field",
    ),
    pytest.param(
        GOOD_MD.replace("[actuates]", "[teleports]"),
        "skills/bad/skill.md: front matter field 'effects': [0] Input should be 'actuates'",
        id="effect-not-in-vocabulary",
    ),
    pytest.param(
        GOOD_MD.replace("[actuates]", "[none, actuates]"),
        "skills/bad/skill.md: front matter field 'effects': Value error, 'none' cannot be",
        id="effect-none-combined",
    ),
    pytest.param(
        GOOD_MD.replace("effects: [actuates]\n", ""),
        "skills/bad/skill.md: front matter field 'effects': Field required",
        id="effects-missing",
    ),
    pytest.param(
        GOOD_MD.replace("tags: [test]", "tags: test"),
        "skills/bad/skill.md: front matter field 'tags': Input should be a valid tuple",
        id="tags-not-a-list",
    ),
    pytest.param(
        GOOD_MD.replace("executor: skill.py", "executor: ../evil.py"),
        "skills/bad/skill.md: front matter field 'executor': Value error, must be a relative",
        id="executor-escapes-package",
    ),
    pytest.param(
        GOOD_MD.replace("  label: free text\n", ""),
        "skills/bad/skill.md: front matter field 'inputs': keys ['speed'] must equal",
        id="inputs-drift-from-params",
    ),
    pytest.param(
        GOOD_MD.replace("Prose for the LLM.\n", "\n   \n"),
        "skills/bad/skill.md: empty body",
        id="empty-body",
    ),
]


@pytest.mark.parametrize(("md", "expected"), BROKEN_MD)
def test_broken_skill_md_is_refused(root: Path, md: str, expected: str) -> None:
    write_pkg(root, "bad", md=md)
    assert expected in refusal(root)


BROKEN_PY = [
    pytest.param(
        None,
        "skills/bad/skill.py: missing executor file",
        id="missing-skill-py",
    ),
    pytest.param(
        "import math\n\nraise RuntimeError('boom')\n",
        "skills/bad/skill.py: line 3: import failed: RuntimeError: boom",
        id="raises-at-import",
    ),
    pytest.param(
        "def options(obs, ctx)\n",
        "skills/bad/skill.py: line 1: import failed: SyntaxError",
        id="syntax-error",
    ),
    pytest.param(
        "import sys\nsys.exit(3)\n",
        "skills/bad/skill.py: line 2: import failed: SystemExit: 3",
        id="exits-at-import",
    ),
    pytest.param(
        GOOD_PY.replace("def options(", "def not_options("),
        "skills/bad/skill.py: missing function 'options'",
        id="missing-options",
    ),
    pytest.param(
        GOOD_PY.replace("def execute(", "def not_execute("),
        "skills/bad/skill.py: missing function 'execute'",
        id="missing-execute",
    ),
    pytest.param(
        GOOD_PY + "\nexecute = 3\n",
        "skills/bad/skill.py: 'execute' must be a function",
        id="execute-not-callable",
    ),
    pytest.param(
        GOOD_PY.replace("def execute(params: Params, obs", "def execute(obs"),
        "skills/bad/skill.py: function 'execute' must accept (params, obs, ctx)",
        id="execute-wrong-signature",
    ),
    pytest.param(
        GOOD_PY.replace("class Params(SkillParams):", "class NotParams(SkillParams):"),
        "skills/bad/skill.py: missing class 'Params'",
        id="missing-params",
    ),
    pytest.param(
        GOOD_PY.replace(
            "class Params(SkillParams):",
            "from pydantic import BaseModel\n\n\nclass Params(BaseModel):",
        ),
        "skills/bad/skill.py: Params must subclass SkillParams",
        id="params-not-skillparams",
    ),
    pytest.param(
        GOOD_PY.replace(
            "    speed: float = 1.0",
            "    model_config = {'extra': 'allow'}\n    speed: float = 1.0",
        ),
        "skills/bad/skill.py: Params must keep SkillParams' extra='forbid'",
        id="params-loosened",
    ),
]


@pytest.mark.parametrize(("py", "expected"), BROKEN_PY)
def test_broken_skill_py_is_refused(root: Path, py: str | None, expected: str) -> None:
    write_pkg(root, "bad", py=py)
    assert expected in refusal(root)


def test_missing_skill_md_is_refused(root: Path) -> None:
    write_pkg(root, "bad", md=None)
    assert "skills/bad/skill.md: missing skill.md" in refusal(root)


def test_alias_shadowing_another_skill_is_refused(root: Path) -> None:
    write_pkg(root, "other", md=GOOD_MD.replace("aliases: [{name}_alias]", "aliases: [good]"))
    assert "skills/other/skill.md: front matter field 'aliases': alias 'good'" in refusal(root)


def test_one_broken_package_refuses_all_and_every_problem_is_reported(root: Path) -> None:
    write_pkg(root, "bad1", md=GOOD_MD.replace("tags: [test]", "tags: [test]\nextra: 1"))
    write_pkg(root, "bad2", py=None)
    with pytest.raises(SkillError) as info:
        load_skills(root)
    err = info.value
    assert len(err.problems) == 2
    text = str(err)
    assert text.startswith(f"refusing skill packages under {root}")
    assert "skills/bad1/skill.md: front matter field 'extra'" in text
    assert "skills/bad2/skill.py: missing executor file" in text


def test_a_stop_signalled_while_a_skill_is_imported_is_a_stop_not_a_broken_package(
    root: Path,
) -> None:
    """``systemctl stop`` while a daemon imports its skills: the signal lands inside the
    loader's ``exec_module``, which reports what an import raises as a broken package. The
    daemon must stop (exit 0), not refuse its skills (exit 2)."""
    write_pkg(
        root, "signalled", py="import os, signal\n\nos.kill(os.getpid(), signal.SIGTERM)\nx = 1\n"
    )
    previous = signal.signal(signal.SIGTERM, stop_before_loop)
    try:
        with pytest.raises(Stopped) as info:
            load_skills(root)
    finally:
        signal.signal(signal.SIGTERM, previous)
        forget_early_stops()
    assert info.value.signum == signal.SIGTERM


def test_broken_markdown_and_code_are_reported_together(root: Path) -> None:
    write_pkg(root, "bad", md=GOOD_MD.replace("Fly somewhere useful.", TOO_LONG), py="1/0\n")
    text = refusal(root)
    assert "skills/bad/skill.md: front matter field 'description'" in text
    assert "skills/bad/skill.py: line 1: import failed: ZeroDivisionError" in text


# ------------------------------------------------------------------ parameters


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        pytest.param({"speed": 1.0, "colour": "red"}, "'colour': unknown parameter", id="unknown"),
        pytest.param({"speed": "fast"}, "'speed': Input should be a valid number", id="type"),
        pytest.param({"speed": "2.5"}, "'speed': Input should be a valid number", id="no-coerce"),
        pytest.param({"speed": True}, "'speed': Input should be a valid number", id="bool"),
        pytest.param({"speed": math.nan}, "'speed': Input should be a finite number", id="nan"),
        pytest.param({"speed": -math.inf}, "'speed': Input should be a finite number", id="inf"),
        pytest.param({"label": "y" * 65}, "'label': String should have at most 64", id="long"),
        pytest.param({"label": object()}, "not JSON-serialisable", id="not-json"),
    ],
)
def test_invalid_params_are_refused(root: Path, data: dict[str, object], expected: str) -> None:
    skill = load_skills(root).get("good")
    with pytest.raises(SkillParamError) as info:
        skill.parse_params(data)
    assert str(info.value).startswith("good: invalid parameters: ")
    assert expected in str(info.value)


def test_params_must_be_a_mapping(root: Path) -> None:
    skill = load_skills(root).get("good")
    with pytest.raises(SkillParamError, match="expected an object"):
        skill.parse_params(["speed", 1.0])  # type: ignore[arg-type]


def test_valid_params_parse(root: Path) -> None:
    skill = load_skills(root).get("good")
    params = skill.parse_params({"speed": 2, "label": "north"})
    assert isinstance(params, skill.params)
    assert params.model_dump() == {"speed": 2.0, "label": "north"}
    assert skill.parse_params({}) == skill.options(OBS, CTX)[0]


def test_cover_landmark_params_need_a_target() -> None:
    skill = load_skills().get("cover_landmark")
    with pytest.raises(SkillParamError, match="'target_id': Field required"):
        skill.parse_params({})
    with pytest.raises(SkillParamError, match="'target_id': Input should be a valid string"):
        skill.parse_params({"target_id": 2})
    assert skill.parse_params({"target_id": "L2"}).model_dump() == {"target_id": "L2"}


def test_execute_refuses_another_skills_params(root: Path) -> None:
    reg = load_skills()
    hold = reg.get("hold_position")
    with pytest.raises(SkillParamError, match="expected hold_position Params"):
        hold.execute(reg.get("explore_local").options(OBS, CTX)[0], OBS, CTX)


def test_executor_breaking_its_contract_at_run_time_names_the_file(root: Path) -> None:
    py = GOOD_PY.replace("return [Params()]", "return [1]").replace(
        "return Intent(MoveTo(", "return (MoveTo("
    )
    write_pkg(root, "liar", md=GOOD_MD, py=py)
    skill = load_skills(root).get("liar")
    with pytest.raises(SkillError, match=r"skills/liar/skill.py: options\(\) must return"):
        skill.options(OBS, CTX)
    with pytest.raises(
        SkillError, match=r"skills/liar/skill.py: execute\(\) returned MoveTo, not Intent"
    ):
        skill.execute(skill.parse_params({}), OBS, CTX)


def test_hold_position_from_registry_holds() -> None:
    skill = load_skills().get("hold_position")
    assert skill.execute(skill.options(OBS, CTX)[0], OBS, CTX).motion == Hold()


def test_one_bad_field_is_one_problem(root: Path) -> None:
    write_pkg(root, "bad", md=GOOD_MD.replace("[actuates]", "[teleports]"))
    with pytest.raises(SkillError) as info:
        load_skills(root)
    [problem] = info.value.problems
    assert problem.field == "effects"
    assert problem.path == root / "bad" / "skill.md"
