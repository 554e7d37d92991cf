"""The layering rules, checked on the source (every import statement, including those inside
functions and under TYPE_CHECKING).

The product's packages stand in layers; a package imports only packages of lower layers
(and itself). So no two packages import each other, and nothing at the bottom reaches up:

====  ==========================================================================
layer packages (``aeroweaver_edge.*`` unless named)
====  ==========================================================================
0     ``contracts``: ports, observation, wire payloads, endpoints, errors, defaults
1     ``runtime`` (process plumbing), ``config``, ``skills`` (the loader)
2     ``world`` (kinematics), ``security`` (PKI, signatures, ACL), ``llm``
3     ``mesh`` (Zenoh facade, peers, presence), ``tasks``
4     ``agent``, ``vehicle``, ``safety``, ``provision``, the ``commander`` package
5     ``daemon``, ``sim``
6     ``orchestration``
7     ``console``
8     ``mcp_server``
9     ``cli``
10    ``__main__`` (``python -m aeroweaver_edge``)
11    ``aeroweaver_lab``: the research tools, which may import any of the above
====  ==========================================================================

Beside the layers: the skill packages (``skills/``) import only ``aeroweaver_edge.contracts``;
the product never imports ``aeroweaver_lab`` (it finds the lab's commands and selectors
through entry points, ``runtime.plugins``); and the daemon's core (``daemon.uav_daemon``,
``daemon.decision_round``) imports no backend (LLM, vehicle, simulator). Finally no module
imports itself through others: the import graph of every module has no circle.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SOURCES = {"aeroweaver_edge": ROOT, "commander": ROOT, "skills": ROOT,
           "aeroweaver_lab": ROOT / "lab"}  # fmt: skip

LAYERS: list[tuple[str, ...]] = [
    ("contracts", "aeroweaver_edge"),  # and the package's own __init__, which imports nothing
    ("runtime", "config", "skills"),
    ("world", "security", "llm"),
    ("mesh", "tasks"),
    ("agent", "vehicle", "safety", "provision", "commander"),
    ("daemon", "sim"),
    ("orchestration",),
    ("console",),
    ("mcp_server",),
    ("cli",),
    ("__main__",),
    ("aeroweaver_lab",),
]
LAYER = {name: i for i, names in enumerate(LAYERS) for name in names}
CORE = ("aeroweaver_edge.daemon.uav_daemon", "aeroweaver_edge.daemon.decision_round")
BACKENDS = ("aeroweaver_edge.llm", "aeroweaver_edge.vehicle", "aeroweaver_edge.sim")


def modules() -> dict[str, Path]:
    """Every module of the four top-level packages, by dotted name."""
    out: dict[str, Path] = {}
    for top, base in SOURCES.items():
        for path in sorted((base / top).rglob("*.py")):
            parts = list(path.relative_to(base).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


MODULES = modules()


def _resolve(name: str) -> str | None:
    """The module ``name`` refers to (a name imported from a module is that module)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def imports(module: str) -> set[str]:
    """The project modules ``module`` imports, anywhere in its source."""
    path = MODULES[module]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                head = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*head, *([base] if base else [])])
            names = [f"{base}.{a.name}" for a in node.names]
        else:
            continue
        out.update(m for n in names if (m := _resolve(n)) is not None and m != module)
    return out


GRAPH = {m: imports(m) for m in MODULES}


def package(module: str) -> str:
    """The layered unit a module belongs to."""
    parts = module.split(".")
    if parts[0] == "aeroweaver_edge" and len(parts) > 1:
        return parts[1]
    return parts[0]


def test_every_product_package_has_a_layer() -> None:
    unplaced = {package(m) for m in MODULES if not m.startswith("skills")} - set(LAYER)
    assert not unplaced, f"place these in LAYERS: {sorted(unplaced)}"


def _violations() -> Iterator[str]:
    for a, targets in GRAPH.items():
        if a.startswith("skills"):
            continue
        for b in targets:
            pa, pb = package(a), package(b)
            if pa != pb and not (pb in LAYER and LAYER[pb] < LAYER[pa]):
                yield f"{a} -> {b} ({pa} is layer {LAYER.get(pa)}, {pb} is {LAYER.get(pb)})"


def test_packages_import_only_lower_layers() -> None:
    bad = sorted(_violations())
    assert not bad, "\n".join(bad)


def test_skill_packages_import_only_the_contracts() -> None:
    bad = sorted(
        f"{a} -> {b}"
        for a, targets in GRAPH.items()
        if a.startswith("skills")
        for b in targets
        if not b.startswith(("skills", "aeroweaver_edge.contracts"))
    )
    assert not bad, bad


@pytest.mark.parametrize("core", CORE)
def test_the_daemons_core_imports_no_backend(core: str) -> None:
    bad = sorted(b for b in GRAPH[core] if b.startswith(BACKENDS))
    assert not bad, bad


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected sets of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                part = []
                while True:
                    top = stack.pop()
                    on_stack.discard(top)
                    part.append(top)
                    if top == node:
                        break
                if len(part) > 1:
                    found.append(sorted(part))
    return found


def test_no_module_imports_itself_through_others() -> None:
    assert circles(GRAPH) == []


def test_the_checker_sees_a_circle_and_imports_inside_functions() -> None:
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    found = GRAPH["aeroweaver_edge.orchestration.swarm"]
    assert "aeroweaver_edge.sim.runner" in found  # a top-level import
    assert "aeroweaver_edge.sim.emulator.swarm_link" in found  # one inside a function
    assert "aeroweaver_edge.daemon.app" in GRAPH["aeroweaver_edge.orchestration.daemons"]
