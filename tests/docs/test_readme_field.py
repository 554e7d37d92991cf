"""README's "In the field" rehearsal is the one docs/field.md runs (tests/docs/
test_field_rehearsal.py): every command it shows is a command of that block."""

from __future__ import annotations

import re
import shlex

from tests.docs.test_field_rehearsal import ROOT, doc_commands


def test_readme_rehearsal_commands_are_the_tested_ones() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## In the field", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```bash\n(.*?)```", section, re.S)
    assert block is not None
    shown = [shlex.split(line, comments=True) for line in block.group(1).splitlines()]
    shown = [words for words in shown if words]
    tested = [argv + (["&"] if bg else []) for argv, bg in doc_commands()]
    assert len(shown) >= 6
    assert all(words in tested for words in shown), [w for w in shown if w not in tested]
