"""A mutation check you can rerun: plant small bugs in the core, see whether the tests notice.

Dev tooling (not part of the installed package). For every target below it lists every
candidate mutant of the target's source (operator swaps ``<``/``<=``, ``>``/``>=``,
``==``/``!=``, ``+``/``-``, ``*``/``/``, ``and``/``or``; numeric constants off by one; a
dropped ``not``; an ``if`` whose condition is dropped; one operand of ``and``/``or``
dropped; a call statement removed), draws a fixed sample with a seeded RNG, adds the
mandatory mutants (the three bugs issue 12 names), and for each mutant runs the target's
test subset on a scratch copy of the tree (``-x``, with a timeout). A mutant is *killed*
when the subset fails or times out, *survived* when it passes.

    python tools/mutation.py                      # this tree, every target
    python tools/mutation.py --root /tmp/main     # another checkout (e.g. main's tests)
    python tools/mutation.py --targets safety_gate tasks --list

The working tree is never written: mutants are applied to a copy in a temporary directory,
which is on ``PYTHONPATH`` (so daemons spawned by the tests import the mutant too). Byte
code is disabled, so a same-size mutant can never run stale code. Logging calls are never
mutated (their removal changes no behaviour the tests are meant to pin).
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

SWAP_CMP = {
    ast.Lt: ("<", "<="),
    ast.LtE: ("<=", "<"),
    ast.Gt: (">", ">="),
    ast.GtE: (">=", ">"),
    ast.Eq: ("==", "!="),
    ast.NotEq: ("!=", "=="),
}
SWAP_BIN = {ast.Add: ("+", "-"), ast.Sub: ("-", "+"), ast.Mult: ("*", "/"), ast.Div: ("/", "*")}
LOGGERS = {"log", "logger", "logging", "warnings"}


@dataclass(frozen=True)
class Target:
    name: str
    files: tuple[str, ...]
    tests: tuple[str, ...]  # run per mutant; paths missing in a checkout are left out
    sample: int
    scope: frozenset[str] | None = None  # only inside these functions / module constants


@dataclass(frozen=True)
class Mutant:
    target: str
    file: str
    line: int
    col: int
    kind: str
    start: int  # byte offsets of the replaced span
    end: int
    new: bytes
    mandatory: str = ""  # why it is in every run
    variant: int = 0  # tells apart mutants of one kind at one place (which operand is kept)

    @property
    def id(self) -> str:
        tail = f"#{self.variant}" if self.variant else ""
        return f"{self.file}:{self.line}:{self.col}:{self.kind}{tail}"


@dataclass
class Outcome:
    mutant: str
    target: str
    status: str  # killed | survived | timeout | invalid
    seconds: float
    failed: str = ""  # first failing test (killed)


T = "tests/aeroweaver_edge/"
TASK_FILES = tuple(
    f"aeroweaver_edge/tasks/{m}.py"
    for m in (
        "coverage",
        "formation",
        "guided_navigation",
        "pursuit_evasion",
        "collection_delivery",
        "private_communication",
        "base",
    )
)
TARGETS: tuple[Target, ...] = (
    Target(
        "scoring",
        ("aeroweaver_edge/agent/scoring.py", "aeroweaver_edge/contracts/scores.py"),
        (
            f"{T}agent/test_scoring.py",
            f"{T}agent/test_llm_selector.py",
            f"{T}daemon/test_decision_round.py",
        ),
        10,
    ),
    Target(
        "memory",
        (
            "aeroweaver_edge/agent/memory/experience.py",
            "aeroweaver_edge/agent/memory/store.py",
            "aeroweaver_edge/agent/memory/index.py",
            "aeroweaver_edge/agent/memory/returns.py",
            "aeroweaver_edge/agent/memory/senders.py",
        ),
        (
            f"{T}agent/memory/test_experience.py",
            f"{T}agent/memory/test_memory_runs.py",
            f"{T}agent/memory/test_index.py",
            f"{T}agent/memory/test_senders.py",
            f"{T}cli/test_cli_memory.py",
        ),
        15,
    ),
    Target(
        "safety_gate",
        ("aeroweaver_edge/safety/gate.py",),
        (
            f"{T}safety/test_gate.py",
            f"{T}daemon/test_decision_round.py",
            f"{T}sim/test_envelope.py",
            f"{T}orchestration/test_swarm_envelope.py",
            "tests/commander/test_no_flight_authority.py",
        ),
        12,
    ),
    Target(
        "peers+inbox",
        ("aeroweaver_edge/mesh/peers.py", "aeroweaver_edge/mesh/inbox.py"),
        (
            f"{T}mesh/test_peers.py",
            f"{T}mesh/test_peers_limits.py",
            f"{T}mesh/test_peer_memory.py",
            f"{T}security/test_relay.py",
            f"{T}mesh/test_secured.py",
        ),
        15,
    ),
    Target(
        "decision_round",
        ("aeroweaver_edge/daemon/decision_round.py",),
        (
            f"{T}daemon/test_decision_round.py",
            f"{T}daemon/test_uav_daemon.py",
            f"{T}orchestration/test_swarm_envelope.py",
            "tests/commander/test_no_flight_authority.py",
            f"{T}orchestration/test_swarm.py",
        ),
        12,
    ),
    Target(
        "tasks",
        TASK_FILES,
        (
            f"{T}tasks",
            f"{T}sim/test_sim_episode.py",
            f"{T}orchestration/test_tasks_e2e.py",
            f"{T}orchestration/test_swarm.py",
        ),
        20,
        frozenset(
            {
                "complete",
                "rewards",
                "after_step",
                "record_guess",
                "_nearest_m",
                "_slot_dists",
                "_goal_dist",
                "_catchers",
                "stable_rounds_needed",
                "COVER_RADIUS_M",
                "SLOT_RADIUS_M",
                "GOAL_RADIUS_M",
                "CATCH_M",
                "ROUNDS",
            }
        ),
    ),
    Target(
        "episode",
        ("aeroweaver_edge/sim/episode.py",),
        (f"{T}sim/test_sim_episode.py", f"{T}sim/test_runner.py", f"{T}tasks"),
        10,
    ),
)

# The three bugs issue 12 names: each must make the suite fail.
BYPASS = b"""    _m = intent.motion  # MUTANT: the gate is wired around; the raw intent is applied
    if isinstance(_m, SetVelocity):
        gated = GatedCommand(_m.vel, False)
    elif isinstance(_m, MoveTo):
        _d = [t - p for t, p in zip(_m.target, own.pos, strict=True)]
        gated = GatedCommand((_d[0] / 0.5, _d[1] / 0.5, _d[2] / 0.5), False)
    else:
        gated = GatedCommand(ZERO, True)
"""
MANDATORY: tuple[tuple[str, str, str, bytes | tuple[bytes, ...], bytes], ...] = (
    (
        "decision_round",
        "aeroweaver_edge/daemon/decision_round.py",
        "gate bypassed: the executor's raw intent reaches the vehicle",
        (  # the call as it reads now, and as it read on main before issue 12
            b"    gated = rc.gate.gate(intent.motion, own.pos, neighbours, others)\n",
            b"    gated = rc.gate.gate(intent.motion, own.pos, neighbours)\n",
        ),
        BYPASS,
    ),
    (
        "tasks",
        "aeroweaver_edge/tasks/coverage.py",
        "coverage: '<' for '<=' at the 3 m rule",
        b"return all(d <= COVER_RADIUS_M for d in self._nearest_m(world).values())",
        b"return all(d < COVER_RADIUS_M for d in self._nearest_m(world).values())",
    ),
    (
        "tasks",
        "aeroweaver_edge/tasks/spec.py",
        "2 stable rounds for 3 (every task that needs 3)",
        b"    stable_rounds: int = 3\n",
        b"    stable_rounds: int = 2\n",
    ),
    (
        "tasks",
        "aeroweaver_edge/tasks/coverage.py",
        "2 stable rounds for 3 (coverage only)",
        b'    team_size=3,\n    mpe_module="simple_spread",\n',
        b'    team_size=3,\n    stable_rounds=2,\n    mpe_module="simple_spread",\n',
    ),
)
# Survivors judged equivalent (no test can tell them apart from the original), with why.
# They are run and reported like every other mutant; the report gives the kill rate both
# over all mutants and over the others.
EQUIVALENT: dict[str, str] = {
    "aeroweaver_edge/contracts/scores.py:51:43:>->>=": "leftover mass exactly 1e-12 never occurs",
    "aeroweaver_edge/agent/memory/store.py:177:11:if-dropped": (
        "sqlite creates the missing file empty, which passes every check: None either way"
    ),
    "aeroweaver_edge/agent/memory/store.py:200:15:and-operand-dropped#1": (
        "only OperationalError says locked/busy/unable to open"
    ),
    "aeroweaver_edge/agent/memory/experience.py:634:33:and->or": (
        "a loaded group indexes every row of this run (appends add to it): i is never None"
    ),
    "aeroweaver_edge/mesh/peers.py:237:27:const 1.0->2.0": (
        "collect_inbox's default timeout: every caller passes its own"
    ),
    "aeroweaver_edge/mesh/peers.py:394:12:call-removed": (
        "_beacon_seen is read only beside a _beacons entry and both are written together:"
        " a departed peer's stale arrival time is never read, the next beacon overwrites it"
    ),
}
BYPASS_IMPORT = (
    b"from aeroweaver_edge.contracts.actions import HOLD, Intent, VehicleAction\n",
    b"from aeroweaver_edge.contracts.actions import HOLD, Intent, MoveTo, SetVelocity, "
    b"VehicleAction\n",
)


# ------------------------------------------------------------------ finding mutants


def _offsets(src: bytes) -> list[int]:
    starts = [0]
    for i, b in enumerate(src):
        if b == 0x0A:
            starts.append(i + 1)
    return starts


class _Finder(ast.NodeVisitor):
    """Every candidate mutant of one file, inside ``scope`` (None: anywhere)."""

    def __init__(self, target: str, file: str, src: bytes, scope: frozenset[str] | None):
        self.target, self.file, self.src, self.scope = target, file, src, scope
        self.lines = _offsets(src)
        self.where: list[str] = []
        self.found: list[Mutant] = []

    def _pos(self, line: int, col: int) -> int:
        return self.lines[line - 1] + col

    def _span(self, node: ast.AST) -> tuple[int, int]:
        n: ast.expr | ast.stmt = node  # type: ignore[assignment]
        assert n.end_lineno is not None
        assert n.end_col_offset is not None
        return self._pos(n.lineno, n.col_offset), self._pos(n.end_lineno, n.end_col_offset)

    def _in_scope(self) -> bool:
        return self.scope is None or any(w in self.scope for w in self.where)

    def _add(self, node: ast.AST, kind: str, start: int, end: int, new: bytes) -> None:
        if self._in_scope():
            line = self.src.count(b"\n", 0, start) + 1
            col = start - self.lines[line - 1]
            same = sum(m.start == start and m.kind == kind for m in self.found)
            self.found.append(
                Mutant(self.target, self.file, line, col, kind, start, end, new, variant=same)
            )

    def _op_between(self, a: ast.AST, b: ast.AST, op: str, new: str, kind: str) -> None:
        lo, hi = self._span(a)[1], self._span(b)[0]
        seg = self.src[lo:hi].decode()
        m = re.search(r"(?<![<>=!*/+-])" + re.escape(op) + r"(?![<>=*/])", seg)
        if m is not None:
            self._add(a, kind, lo + m.start(), lo + m.end(), new.encode())

    # -- scopes ---------------------------------------------------------------------------

    def visit_FunctionDef(self, node: ast.FunctionDef) -> None:
        self.where.append(node.name)
        self.generic_visit(node)
        self.where.pop()

    visit_AsyncFunctionDef = visit_FunctionDef  # type: ignore[assignment]

    def visit_Assign(self, node: ast.Assign) -> None:
        names = [t.id for t in node.targets if isinstance(t, ast.Name)]
        self.where.extend(names)
        self.generic_visit(node)
        del self.where[len(self.where) - len(names) :]

    def visit_AnnAssign(self, node: ast.AnnAssign) -> None:
        name = node.target.id if isinstance(node.target, ast.Name) else ""
        self.where.append(name)
        if node.value is not None:
            self.visit(node.value)  # never the annotation
        self.where.pop()

    def visit_arg(self, node: ast.arg) -> None:
        return  # annotations

    def visit_If(self, node: ast.If) -> None:
        test = node.test
        if isinstance(test, ast.Name) and test.id == "TYPE_CHECKING":
            return
        s, e = self._span(test)
        self._add(node, "if-dropped", s, e, b"False")
        self.generic_visit(node)

    # -- operators ------------------------------------------------------------------------

    def visit_Compare(self, node: ast.Compare) -> None:
        left: ast.AST = node.left
        for op, right in zip(node.ops, node.comparators, strict=True):
            swap = SWAP_CMP.get(type(op))
            if swap is not None:
                self._op_between(left, right, swap[0], swap[1], f"{swap[0]}->{swap[1]}")
            left = right
        self.generic_visit(node)

    def visit_BinOp(self, node: ast.BinOp) -> None:
        swap = SWAP_BIN.get(type(node.op))
        strings = (ast.JoinedStr,)
        if swap is not None and not any(
            isinstance(x, strings) or (isinstance(x, ast.Constant) and isinstance(x.value, str))
            for x in (node.left, node.right)
        ):
            self._op_between(node.left, node.right, swap[0], swap[1], f"{swap[0]}->{swap[1]}")
        self.generic_visit(node)

    def visit_AugAssign(self, node: ast.AugAssign) -> None:
        swap = SWAP_BIN.get(type(node.op))
        if swap is not None:
            self._op_between(
                node.target, node.value, swap[0] + "=", swap[1] + "=", f"{swap[0]}=->{swap[1]}="
            )
        self.generic_visit(node)

    def visit_BoolOp(self, node: ast.BoolOp) -> None:
        word, other = ("and", "or") if isinstance(node.op, ast.And) else ("or", "and")
        a, b = node.values[0], node.values[1]
        lo, hi = self._span(a)[1], self._span(b)[0]
        m = re.search(rf"\b{word}\b", self.src[lo:hi].decode())
        if m is not None:
            self._add(node, f"{word}->{other}", lo + m.start(), lo + m.end(), other.encode())
        if len(node.values) == 2:
            s, e = self._span(node)
            for keep in (a, b):
                ks, ke = self._span(keep)
                self._add(node, f"{word}-operand-dropped", s, e, b"(" + self.src[ks:ke] + b")")
        self.generic_visit(node)

    def visit_UnaryOp(self, node: ast.UnaryOp) -> None:
        if isinstance(node.op, ast.Not):
            s, e = self._span(node)
            os_, oe = self._span(node.operand)
            self._add(node, "not-dropped", s, e, b"(" + self.src[os_:oe] + b")")
        self.generic_visit(node)

    def visit_Constant(self, node: ast.Constant) -> None:
        v = node.value
        if isinstance(v, bool) or not isinstance(v, int | float):
            return
        s, e = self._span(node)
        self._add(node, f"const {v!r}->{v + 1!r}", s, e, repr(v + 1).encode())

    def visit_Expr(self, node: ast.Expr) -> None:
        call = node.value.value if isinstance(node.value, ast.Await) else node.value
        if isinstance(call, ast.Call) and not _is_logging(call):
            s, e = self._span(node)
            self._add(node, "call-removed", s, e, b"pass")
        self.generic_visit(node)


def _is_logging(call: ast.Call) -> bool:
    f = call.func
    while isinstance(f, ast.Attribute):
        f = f.value
    return isinstance(f, ast.Name) and f.id in LOGGERS


def candidates(root: Path, target: Target) -> list[Mutant]:
    out: list[Mutant] = []
    for rel in target.files:
        src = (root / rel).read_bytes()
        finder = _Finder(target.name, rel, src, target.scope)
        finder.visit(ast.parse(src))
        out += finder.found
    return sorted(out, key=lambda m: (m.file, m.start, m.kind))


def mandatory(root: Path, target: Target) -> list[Mutant]:
    out = []
    for name, rel, why, old, new in MANDATORY:
        if name != target.name:
            continue
        src = (root / rel).read_bytes()
        found = [(src.find(o), o) for o in ((old,) if isinstance(old, bytes) else old)]
        at, old = max(found)
        if at < 0:
            raise SystemExit(f"mutation: mandatory mutant '{why}' no longer matches {rel}")
        line = src.count(b"\n", 0, at) + 1
        col = at - (src.rfind(b"\n", 0, at) + 1)
        out.append(Mutant(name, rel, line, col, "mandatory", at, at + len(old), new, why))
    return out


def select(
    root: Path, target: Target, seed: int, only_mandatory: bool = False, sample: int | None = None
) -> list[Mutant]:
    """The mandatory mutants plus ``sample`` drawn ones (default: the target's own size)."""
    if only_mandatory:
        return mandatory(root, target)
    pool = candidates(root, target)
    rng = random.Random(f"{seed}:{target.name}")
    size = target.sample if sample is None else sample
    picked = rng.sample(pool, min(size, len(pool)))
    return mandatory(root, target) + sorted(picked, key=lambda m: (m.file, m.start, m.kind))


# ------------------------------------------------------------------ running


def _scratch(root: Path, into: Path) -> Path:
    dst = into / "tree"
    shutil.copytree(
        root,
        dst,
        ignore=shutil.ignore_patterns(
            ".venv", ".git", "__pycache__", ".hypothesis", ".pytest_cache", "*.egg-info", ".mypy*"
        ),
        symlinks=True,
    )
    return dst


def _env(tree: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree) + os.pathsep + env.get("PYTHONPATH", "")
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def _pytest(
    tree: Path, tests: list[str], timeout_s: float, every: bool = False
) -> tuple[str, float, str]:
    cmd = [
        sys.executable, "-m", "pytest", *([] if every else ["-x"]), "-q", "-p", "no:cacheprovider",
        "-m", "not slow and not embedded", "--hypothesis-seed=0",
        f"--timeout={int(timeout_s)}", *tests,
    ]  # fmt: skip
    started = time.monotonic()
    try:
        proc = subprocess.run(
            cmd, cwd=tree, env=_env(tree), capture_output=True, text=True,
            timeout=timeout_s * 2, check=False,
        )  # fmt: skip
    except subprocess.TimeoutExpired:
        return "timeout", time.monotonic() - started, ""
    took = time.monotonic() - started
    lines = proc.stdout.splitlines()
    failures = [ln.split(" - ")[0] for ln in lines if ln.startswith(("FAILED ", "ERROR tests"))]
    failed = "\n      ".join(failures) if every else (failures[0] if failures else "")
    if proc.returncode == 0:
        return "survived", took, ""
    if "Timeout" in proc.stdout and not failed:
        return "timeout", took, ""
    return "killed", took, failed or proc.stdout.strip().splitlines()[-1:][0]


def _apply(tree: Path, m: Mutant, original: bytes) -> bool:
    new = original[: m.start] + m.new + original[m.end :]
    if m.mandatory.startswith("gate bypassed"):
        new = new.replace(*BYPASS_IMPORT)
    try:
        compile(new, m.file, "exec")
    except SyntaxError:
        return False
    (tree / m.file).write_bytes(new)
    return True


def run(
    root: Path,
    targets: list[Target],
    seed: int,
    timeout_s: float,
    only_mandatory: bool = False,
    every: bool = False,
    sample: int | None = None,
) -> list[Outcome]:
    outcomes: list[Outcome] = []
    with tempfile.TemporaryDirectory(prefix="aw-mutation-") as tmp:
        tree = _scratch(root, Path(tmp))
        probe = subprocess.run(
            [sys.executable, "-c", "import aeroweaver_edge; print(aeroweaver_edge.__file__)"],
            cwd=tree, env=_env(tree), capture_output=True, text=True, check=True,
        )  # fmt: skip
        if not probe.stdout.strip().startswith(str(tree)):
            raise SystemExit(f"mutation: the scratch tree is not imported ({probe.stdout.strip()})")
        for target in targets:
            if only_mandatory and not mandatory(root, target):
                continue
            tests = [t for t in target.tests if (tree / t).exists()]
            status, took, failed = _pytest(tree, tests, timeout_s)
            if status != "survived":
                raise SystemExit(f"mutation: {target.name}: tests fail unmutated: {failed}")
            print(f"== {target.name}: {len(tests)} test paths, {took:.0f} s unmutated", flush=True)
            for m in select(root, target, seed, only_mandatory, sample):
                original = (tree / m.file).read_bytes()
                try:
                    if not _apply(tree, m, original):
                        outcomes.append(Outcome(m.id, target.name, "invalid", 0.0))
                        continue
                    status, took, failed = _pytest(tree, tests, timeout_s, every)
                finally:
                    (tree / m.file).write_bytes(original)
                outcomes.append(Outcome(m.id, target.name, status, round(took, 1), failed))
                label = m.mandatory or m.kind
                print(f"  {status:8} {took:5.0f} s  {m.id}  [{label}]  {failed}", flush=True)
    return outcomes


def report(outcomes: list[Outcome], targets: list[Target]) -> dict[str, dict[str, float]]:
    table: dict[str, dict[str, float]] = {}
    for t in [*targets, None]:
        rows = [o for o in outcomes if t is None or o.target == t.name]
        valid = [o for o in rows if o.status != "invalid"]
        killed = sum(o.status in ("killed", "timeout") for o in valid)
        equivalent = sum(o.status == "survived" and o.mutant in EQUIVALENT for o in valid)
        name = "all" if t is None else t.name
        rate = 100.0 * killed / len(valid) if valid else 0.0
        judged = len(valid) - equivalent
        rate_eq = 100.0 * killed / judged if judged else 0.0
        table[name] = {
            "mutants": len(valid),
            "killed": killed,
            "equivalent": equivalent,
            "rate": round(rate, 1),
            "rate_without_equivalent": round(rate_eq, 1),
        }
    head = ("target", "mutants", "killed", "equiv.", "kill rate", "w/o eq.")
    print("\n{:16} {:>8} {:>8} {:>7} {:>10} {:>8}".format(*head))
    for name, row in table.items():
        print(
            f"{name:16} {row['mutants']:>8.0f} {row['killed']:>8.0f} {row['equivalent']:>7.0f} "
            f"{row['rate']:>9.1f}% {row['rate_without_equivalent']:>7.1f}%"
        )
    survivors = [o.mutant for o in outcomes if o.status == "survived"]
    if survivors:
        print("survived:")
        for m in survivors:
            print(f"  {m}" + (f"  (equivalent: {EQUIVALENT[m]})" if m in EQUIVALENT else ""))
    return table


def _iter_targets(names: list[str] | None) -> Iterator[Target]:
    known = {t.name: t for t in TARGETS}
    for n in names or list(known):
        if n not in known:
            raise SystemExit(f"mutation: unknown target {n!r}; known: {', '.join(known)}")
        yield known[n]


def main(argv: list[str] | None = None) -> int:
    doc = (__doc__ or "").split("\n")[0]
    p = argparse.ArgumentParser(prog="python tools/mutation.py", description=doc)
    p.add_argument("--root", type=Path, default=REPO, help="checkout to mutate and test")
    names = ", ".join(t.name for t in TARGETS)
    p.add_argument("--targets", nargs="+", help=f"default: all ({names})")
    p.add_argument("--seed", type=int, default=12)
    p.add_argument(
        "--sample",
        type=int,
        metavar="N",
        help="mutants drawn per target instead of each target's own size (a shorter run)",
    )
    p.add_argument("--timeout", type=float, default=120.0, help="seconds per test run")
    p.add_argument("--list", action="store_true", help="print the mutants, run nothing")
    p.add_argument(
        "--mandatory", action="store_true", help="only the bugs issue 12 names (each must fail)"
    )
    p.add_argument("--every", action="store_true", help="run every test, list every failure")
    p.add_argument("--json", type=Path, help="write every outcome as JSON")
    args = p.parse_args(argv)
    if args.sample is not None and args.sample < 0:
        p.error("--sample must be at least 0")
    root = args.root.resolve()
    targets = list(_iter_targets(args.targets))
    if args.list:
        for t in targets:
            pool = candidates(root, t)
            size = t.sample if args.sample is None else args.sample
            print(f"== {t.name}: {len(pool)} candidates, {size} drawn (seed {args.seed})")
            for m in select(root, t, args.seed, args.mandatory, args.sample):
                print(f"  {m.id}  [{m.mandatory or m.kind}]")
        return 0
    outcomes = run(root, targets, args.seed, args.timeout, args.mandatory, args.every, args.sample)
    table = report(outcomes, [t for t in targets if any(o.target == t.name for o in outcomes)])
    if args.json:
        args.json.write_text(
            json.dumps({"root": str(root), "seed": args.seed, "sample": args.sample, "table": table,
                        "outcomes": [asdict(o) for o in outcomes]}, indent=2) + "\n",
            encoding="utf-8",
        )  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
