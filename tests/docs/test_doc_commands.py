"""Every command the docs tell a user to type is one the CLI accepts.

Commands are collected from README.md and docs/**/*.md: fenced code lines and inline code
spans that start with ``aeroweaver`` or ``python -m aeroweaver_edge...`` (or ``_lab``; after
``$`` prompts and ``VAR=value`` prefixes; continuation lines joined; comments, redirections,
pipes and a trailing ``&`` cut). Placeholders (``N``, ``DIR``, ``HOST:PORT``...) get a
sample value. Each command is parsed by the real parser and stopped right after its first
successful parse, so nothing is flown, started or written: the test checks the command
line (subcommands, flags, choices, value types), which is what rots when code moves on.
Commands that run for real are tested elsewhere (test_readme_field, test_field_rehearsal).
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import re
import shlex
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
# A bench's table.md in an archive records the command that produced it, when it ran (the
# module path of that day); it is an output, not an instruction.
DOCS = [
    ROOT / "README.md",
    *(
        p
        for p in sorted((ROOT / "docs").rglob("*.md"))
        if not (p.name == "table.md" and p.parent != ROOT / "docs")
    ),
]
START = re.compile(
    r"^(?:\$\s+)?(?:[A-Z][A-Z0-9_]*=\S*\s+)*"
    r"((?:aeroweaver|python -m aeroweaver_(?:edge|lab)\S*)(?:\s.*)?)$"
)
SHELL_FENCES = {"", "bash", "sh", "shell", "console"}
SAMPLES = {
    "N": "10",
    "K": "3",
    "S": "3",
    "M": "some-model",
    "B": "reference",
    "E": "paper",
    "DIR": "/tmp/aw-doc-dir",
    "OUT": "/tmp/aw-doc-out.json",
    "$OUT": "/tmp/aw-doc-out",
    "CELLS": "/tmp/aw-doc-cells",
    "URL": "http://127.0.0.1:8080/v1",
    "VAR": "SOME_API_KEY",
    "P": "8765",
}


def _cut(line: str) -> str:
    """The command without comments, pipes, redirections, ``&&`` tails and a trailing ``&``."""
    out, quote = [], ""
    for i, ch in enumerate(line):
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif (ch == "#" and (i == 0 or line[i - 1].isspace())) or ch in "|;>&":
            break  # a comment, a pipe, a redirection, ``&&`` or a trailing ``&``
        out.append(ch)
    return "".join(out).strip()


def _commands(path: Path) -> Iterator[tuple[str, str, bool]]:
    """(where, command, fenced) for every command line of a Markdown file."""
    text = path.read_text(encoding="utf-8")
    fenced = shell = False
    pending = ""
    for n, raw in enumerate(text.splitlines(), 1):
        if raw.lstrip().startswith("```"):
            fenced, pending = not fenced, ""
            shell = raw.strip()[3:].strip() in SHELL_FENCES
            continue
        if fenced and (shell or raw.startswith("$ ")):  # a transcript: its prompt lines
            line = pending + raw.strip()
            if line.endswith("\\"):
                pending = line[:-1] + " "
                continue
            pending = ""
            m = START.match(line)
            if m:
                yield f"{path.relative_to(ROOT)}:{n}", _cut(m.group(1)), True
        elif not fenced:  # in prose, a span with a flag is a command line; a bare name is a mention
            for span in re.findall(r"`([^`]+)`", raw):
                m = START.match(span.strip())
                if m and " -" in m.group(1):
                    yield f"{path.relative_to(ROOT)}:{n}", _cut(m.group(1)), False


def _argv(command: str) -> list[str] | None:
    """The command's arguments with placeholders filled, or None if it is not literal."""
    if "..." in command or "<" in command or "…" in command:
        return None
    if any("$" in w and w not in SAMPLES for w in command.split()):
        return None  # a shell variable of a loop around it
    command = re.sub(r"\[([^\]]*)\]", r"\1", command)  # optional parts: include them
    try:
        words = shlex.split(command)
    except ValueError:
        return None
    return [SAMPLES.get(w, w) for w in words]


ALL = sorted({c for p in DOCS for c in _commands(p)})
CASES = [c for c in ALL if _argv(c[1]) is not None]
# In prose a span may name a command with one of its flags and leave the rest out
# ("`aeroweaver approve --action` takes ..."): unknown flags and bad values still fail.
PARTIAL = ("the following arguments are required", "expected one argument")


class Parsed(BaseException):
    """Not an ``Exception``: the CLI's error reporting must not catch it."""


@pytest.fixture
def parse_only(monkeypatch: pytest.MonkeyPatch) -> None:
    original = argparse.ArgumentParser.parse_args

    def parse_args(self: argparse.ArgumentParser, *a: Any, **kw: Any) -> argparse.Namespace:
        original(self, *a, **kw)  # exits 2 on a bad command line
        raise Parsed

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parse_args)


def test_the_docs_give_commands_to_check() -> None:
    assert len(CASES) > 100
    assert sum(fenced for _, _, fenced in CASES) > 50
    assert any(cmd.startswith("python -m aeroweaver_edge") for _, cmd, _ in CASES)


@pytest.mark.parametrize(
    ("where", "command", "fenced"), CASES, ids=[f"{w} {c}"[:120] for w, c, _ in CASES]
)
@pytest.mark.usefixtures("parse_only")
def test_documented_command_parses(
    where: str, command: str, fenced: bool, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = _argv(command)
    assert argv is not None
    if argv[0] == "aeroweaver":
        from aeroweaver_edge.cli.main import main

        run, args = main, argv[1:]
    else:
        assert argv[:2] == ["python", "-m"], command
        module = importlib.import_module(argv[2])
        main = getattr(module, "main", None)
        if main is None or "argv" not in inspect.signature(main).parameters:
            pytest.skip(f"{argv[2]} has no main(argv) to parse with")
        run, args = main, argv[3:]
    try:
        status = run(args)
    except Parsed:
        return
    except SystemExit as exc:
        err = capsys.readouterr().err.strip()
        if exc.code == 2 and not fenced and any(p in err for p in PARTIAL):
            return
        pytest.fail(f"{where}: `{command}` is refused by the CLI (exit {exc.code}): {err}")
    pytest.fail(f"{where}: `{command}` returned {status} without parsing a command line")
