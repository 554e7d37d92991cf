"""docs/configuration.md's reference is the config schema: every section and key of
``uav.toml`` with its type, bounds, default and comment, generated and compared here."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import get_args

from pydantic import BaseModel

from aeroweaver_edge.config import UavConfig
from aeroweaver_edge.provision import config_reference

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "configuration.md"
COMMAND = [sys.executable, "-m", "aeroweaver_edge.provision.config_reference"]


def test_the_page_holds_the_generated_reference() -> None:
    """The command the page tells a developer to run, in its checking form."""
    out = subprocess.run([*COMMAND, "--check", str(PAGE)], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def test_every_key_of_every_section_is_in_the_reference() -> None:
    text = config_reference.render()

    def keys(model: type[BaseModel], path: str) -> set[str]:
        found: set[str] = set()
        for name, info in model.model_fields.items():
            models = [a for a in (info.annotation, *get_args(info.annotation))
                      if isinstance(a, type) and issubclass(a, BaseModel)]  # fmt: skip
            if models:
                found |= keys(models[0], f"{path}{name}.")
            else:
                found.add(f"{path}{name}")
        return found

    for key in keys(UavConfig, ""):
        assert f"| `{key.rpartition('.')[2]}` |" in text, key
    for section in ("[mesh]", "[mesh.security]", "[llm]", "[agent]", "[safety]", "[vehicle]",
                    "[field]", "[[field.points]]", "[approval]"):  # fmt: skip
        assert f"### `{section}`" in text


def test_a_stale_page_is_caught_and_rewritten(tmp_path: Path) -> None:
    stale = PAGE.read_text(encoding="utf-8").replace("| `lease_ms` |", "| `lease` |")
    page = tmp_path / "configuration.md"
    page.write_text(stale, encoding="utf-8")
    check = subprocess.run([*COMMAND, "--check", str(page)], capture_output=True, text=True)
    assert check.returncode == 1
    assert "stale" in check.stdout
    subprocess.run([*COMMAND, str(page)], check=True)
    assert page.read_text(encoding="utf-8") == PAGE.read_text(encoding="utf-8")


def test_a_page_without_the_markers_is_one_line_exit_2(tmp_path: Path) -> None:
    page = tmp_path / "plain.md"
    page.write_text("# nothing generated here\n", encoding="utf-8")
    out = subprocess.run([*COMMAND, "--check", str(page)], capture_output=True, text=True)
    assert out.returncode == 2
    assert len(out.stderr.strip().splitlines()) == 1
    assert "no generated block" in out.stderr
