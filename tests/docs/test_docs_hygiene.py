"""Docs that cannot contradict the repository: every relative link points at a file (and a
heading) that exists, and every command a doc gives for a field swarm is a secured one.

The field model is TLS only (docs/security.md): a ground command that dials a swarm off this
machine carries ``--keys DIR`` (the directory ``keys init`` wrote), and no doc tells a user
to dial one in plain ``tcp/``.
"""

from __future__ import annotations

import ipaddress
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)|!\[[^\]]*\]\(([^)\s]+)\)")
HEADING = re.compile(r"^#{1,6}\s+(.*?)\s*#*\s*$", re.M)
FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)


def markdown_files() -> list[Path]:
    listed = subprocess.run(
        ["git", "ls-files", "*.md"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    return [ROOT / f for f in listed if (ROOT / f).is_file()]


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"`|\*\*|__|\[([^\]]*)\]\([^)]*\)", r"\1", heading).strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    seen: dict[str, int] = {}
    out = set()
    for heading in HEADING.findall(text):
        base = slug(heading)
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def broken_links(path: Path) -> list[str]:
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    text = re.sub(r"`[^`\n]*`", "", text)  # a link written inside code is not a link
    bad = []
    for m in LINK.finditer(text):
        target = m.group(1) or m.group(2)
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading #{anchor} in {dest.name}")
    return bad


@pytest.mark.parametrize(
    "path", markdown_files(), ids=lambda p: str(p.relative_to(ROOT))
)  # fmt: skip
def test_every_relative_link_resolves(path: Path) -> None:
    assert broken_links(path) == []


def test_the_link_checker_sees_a_missing_file_and_heading(tmp_path: Path) -> None:
    (tmp_path / "b.md").write_text("# A heading here\n\ntext\n", encoding="utf-8")
    page = tmp_path / "a.md"
    page.write_text(
        "[ok](b.md) [ok](b.md#a-heading-here) [gone](c.md) [no](b.md#nowhere) "
        "[web](https://example.org/x) `[code](d.md)`\n",
        encoding="utf-8",
    )
    assert broken_links(page) == ["c.md: no such file", "b.md#nowhere: no heading #nowhere in b.md"]


GROUND = ("mission", "console", "approve", "mcp", "status")
ENDPOINT = re.compile(r"(?:--connect[ =\"',]+|\"--connect\",\s*\")(\w+)/([^\s\"',:]+|\[[^\]]+\])")


def commands(text: str) -> list[str]:
    """``aeroweaver ...`` commands in a page (continuation lines joined), code or JSON."""
    joined = re.sub(r"\\\n\s*", " ", text)
    found = [m.group(0) for m in re.finditer(r"aeroweaver\s+[^\n`]*", joined)]
    found += [m.group(0) for m in re.finditer(r"\"args\":\s*\[[^\]]*\]", joined)]
    return found


def off_loopback(host: str) -> bool:
    try:
        return not ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return host != "localhost"


def insecure_field_commands(text: str) -> list[str]:
    bad = []
    for cmd in commands(text):
        ground = re.search(r"aeroweaver\s+(\w+)", cmd)
        name = ground.group(1) if ground else cmd.split('"')[3] if '"args"' in cmd else ""
        for proto, host in ENDPOINT.findall(cmd):
            if not off_loopback(host):
                continue
            if proto == "tcp":
                bad.append(f"plain tcp/ to a field host: {cmd.strip()}")
            elif name in GROUND and "--keys" not in cmd:
                bad.append(f"a field command without --keys: {cmd.strip()}")
    return bad


@pytest.mark.parametrize(
    "path", markdown_files(), ids=lambda p: str(p.relative_to(ROOT))
)  # fmt: skip
def test_every_field_command_is_secured(path: Path) -> None:
    assert insecure_field_commands(path.read_text(encoding="utf-8")) == []


def test_the_field_command_check_sees_both_mistakes() -> None:
    text = (
        "aeroweaver console --swarm f --connect tcp/10.0.0.1:7447\n"
        "aeroweaver approve --connect tls/10.0.0.1:7447 --uav uav0\n"
        'aeroweaver mission start "x" --keys k --connect tls/10.0.0.1:7447\n'
        "aeroweaver sim coverage --connect tcp/127.0.0.1:7447\n"
        '"args": ["mcp", "--swarm", "field", "--connect", "tcp/10.0.0.1:7447"]\n'
    )
    bad = insecure_field_commands(text)
    assert len(bad) == 3
    assert "plain tcp/" in bad[0]
    assert "without --keys" in bad[1]
    assert "mcp" in bad[2]
