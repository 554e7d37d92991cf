"""Task names as users type them: the registry's spelling, other case and separators, and
the mpe2 scenario names the tasks follow."""

from __future__ import annotations

import pytest

from aeroweaver_edge.cli.main import main
from aeroweaver_edge.tasks import MPE_NAMES, TASK_NAMES, canonical_task, get_spec


@pytest.mark.parametrize(
    ("typed", "task"),
    [
        ("coverage", "coverage"),
        ("Pursuit-Evasion", "pursuit_evasion"),
        (" line formation ", "line_formation"),
        ("simple_spread", "coverage"),
        ("simple_spread_v3", "coverage"),
        ("SIMPLE_TAG_V3", "pursuit_evasion"),
        ("collect_treasure", "collection_delivery"),
    ],
)
def test_accepted_spellings(typed: str, task: str) -> None:
    assert canonical_task(typed) == task


@pytest.mark.parametrize("typed", ["", "coverag", "simple", "simple_push", "coverage_v3", "../x"])
def test_anything_else_comes_back_unchanged(typed: str) -> None:
    assert canonical_task(typed) == typed


def test_mpe_names_are_the_specs_own() -> None:
    assert {get_spec(t).mpe_module: t for t in TASK_NAMES} == MPE_NAMES


def test_the_cli_takes_an_mpe_name_and_refuses_an_unknown_one(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["sim", "simple-crypto", "--selector", "scripted", "--rounds", "1", "--quiet"]) == 0
    assert "private_communication" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        main(["sim", "simple_push", "--selector", "scripted"])
    assert exc.value.code == 2
    assert "invalid choice: 'simple_push'" in capsys.readouterr().err
