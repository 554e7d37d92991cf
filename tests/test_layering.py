"""The layering rules, checked on the source (every import statement, including those inside
functions and under TYPE_CHECKING):

* the Commander never imports the simulator or the orchestration that wires it;
* the simulator and the task definitions never import the Commander or the orchestration;
* the plain types at the bottom (ports, scores, observation, wire, defaults) import nothing
  above them (no agent, LLM, simulator, task or Commander module);
* the daemon's core (daemon, decision_round) imports no backend (LLM, vehicle, simulator).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            base = node.module
            if node.level:  # relative: resolve against the package
                pkg = list(path.relative_to(ROOT).with_suffix("").parts[:-1])
                pkg = pkg[: len(pkg) - node.level + 1]
                base = ".".join([*pkg, node.module])
            out.add(base)
    return out


def files(*parts: str) -> list[Path]:
    p = ROOT.joinpath(*parts)
    return sorted(p.rglob("*.py")) if p.is_dir() else [p]


RULES = [
    (files("commander"), ("aeroweaver_edge.sim", "aeroweaver_edge.orchestration")),
    (files("aeroweaver_edge", "sim"), ("commander", "aeroweaver_edge.orchestration")),
    (files("aeroweaver_edge", "tasks"), ("commander", "aeroweaver_edge.orchestration",
                                         "aeroweaver_edge.sim", "aeroweaver_edge.agent")),
    (
        [*files("aeroweaver_edge", "ports.py"), *files("aeroweaver_edge", "scores.py"),
         *files("aeroweaver_edge", "observation.py"), *files("aeroweaver_edge", "wire.py"),
         *files("aeroweaver_edge", "defaults.py")],
        ("aeroweaver_edge.agent", "aeroweaver_edge.llm", "aeroweaver_edge.sim",
         "aeroweaver_edge.tasks", "aeroweaver_edge.orchestration", "commander"),
    ),
    (
        [*files("aeroweaver_edge", "daemon.py"), *files("aeroweaver_edge", "decision_round.py")],
        ("aeroweaver_edge.llm", "aeroweaver_edge.vehicle", "aeroweaver_edge.sim",
         "aeroweaver_edge.orchestration", "commander"),
    ),
]  # fmt: skip


@pytest.mark.parametrize(("paths", "forbidden"), RULES)
def test_no_forbidden_imports(paths: list[Path], forbidden: tuple[str, ...]) -> None:
    assert paths
    bad = {
        f"{p.relative_to(ROOT)}: {m}"
        for p in paths
        for m in imports(p)
        if any(m == f or m.startswith(f + ".") for f in forbidden)
    }
    assert not bad, sorted(bad)


def test_the_checker_sees_imports_inside_functions(tmp_path: Path) -> None:
    src = ROOT / "aeroweaver_edge" / "orchestration" / "swarm.py"
    found = imports(src)
    assert "aeroweaver_edge.sim.runner" in found
    assert "commander.commander" in found
