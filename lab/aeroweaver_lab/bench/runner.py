"""``aeroweaver bench run``: tasks x conditions x seeds, resumable, with tables and plots.

Every cell (task, condition, seed) is one simulated run of ``--episodes`` consecutive
episodes (experience memory persists across them) that writes, under ``--out``:

* ``runs/<task>/<condition>/seed<S>.trace.jsonl.gz`` -- the per-round trace (docs/traces.md),
  gzip-compressed (mtime 0: the same trace gives the same bytes);
* ``runs/<task>/<condition>/seed<S>.json`` -- the run summary, the per-episode figures
  computed from the trace (``bench.episodes``) and a check that they add up to the summary;
* ``setup/<task>.json`` -- the tokens of one LLM Commander activation of the task's mission
  text (``bench.setup_cost``), counted once per run in AeroWeaver's totals.

Every condition lists each UAV's skills, hence its option letters, in one seeded order per
(task, seed, UAV) (``orchestration.planning.with_seeded_order``): a model that answers ``A``
gets the same skill under every condition that offers it first.

A cell whose JSON exists and is complete (same configuration) is skipped, so an interrupted
run resumes with the same command. ``--jobs N`` runs N cells at once (default: the physical
cores; each embedded model server then gets one thread). At the end (and with
``--report-only``, from the stored cells alone, byte for byte) ``results.csv``, ``table.md``,
``summary.json``, ``returns.png`` and ``tokens.png`` are written from all complete cells.
Progress and an ETA go to stderr; the machine's load is recorded at start and end of every
session in ``manifest.json``.

``--quick`` (CI): all nine tasks, all conditions, one seed, 2 rounds, the fake provider (a
real loopback HTTP server that also answers the baselines' JSON requests).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import dataclasses
import os
import platform
import shlex
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final

from aeroweaver_edge.cli.checks import check_api_key_env, check_llm_url, finite, int_in
from aeroweaver_edge.cli.errors import ArgumentParser
from aeroweaver_edge.config import LLMConfig, parse_config
from aeroweaver_edge.contracts.errors import RunFailed, UserError
from aeroweaver_edge.llm.embedded import THREADS_ENV
from aeroweaver_edge.llm.embedded import default_threads as embedded_threads
from aeroweaver_edge.llm.peak import cpu_identity
from aeroweaver_edge.runtime.json_out import write_json_file
from aeroweaver_edge.tasks import TASK_NAMES, canonical_task
from aeroweaver_lab.bench.conditions import CONDITIONS, Condition, swarm_options
from aeroweaver_lab.bench.episodes import check_against_summary, episode_metrics, read_trace
from aeroweaver_lab.bench.setup_cost import SETUP_CONDITIONS, measure_setups

# 2: seeded option order, compressed traces; 3: HMAS-2 revises only on disagreement
RESULT_VERSION = 3
OPTION_ORDER: Final = "seeded"
DEFAULT_LLM_DEADLINE_S = 60.0
DEFAULT_SEEDS = 3


@dataclass(frozen=True)
class Cell:
    task: str
    condition: str
    seed: int

    def stem(self, out: Path) -> Path:
        return out / "runs" / self.task / self.condition / f"seed{self.seed}"

    def json_path(self, out: Path) -> Path:
        return self.stem(out).with_suffix(".json")

    def trace_path(self, out: Path) -> Path:
        """Where the run writes its trace; ``archive_trace`` compresses it when it ends."""
        return self.stem(out).with_suffix(".trace.jsonl")

    def __str__(self) -> str:
        return f"{self.task} / {self.condition} / seed {self.seed}"


def plan_cells(tasks: Sequence[str], conditions: Sequence[str], seeds: Sequence[int]) -> list[Cell]:
    """Seed-major: a complete first seed of every task and condition comes first, so an
    interrupted long run still has every cell of the table."""
    return [Cell(t, c, s) for s in seeds for t in tasks for c in conditions]


def config_key(rounds: int, episodes: int, llm: LLMConfig, source: str) -> dict[str, Any]:
    """What must match for a stored cell to count as done."""
    return {
        "version": RESULT_VERSION,
        "rounds": rounds,
        "episodes": episodes,
        "llm": source,
        "model": llm.model,
        "option_order": OPTION_ORDER,
    }


def load_done(path: Path, key: dict[str, Any], cond: Condition) -> dict[str, Any] | None:
    """The stored result if it is complete and of this configuration; None: run it. A
    result of another configuration is an error (nothing is overwritten)."""
    import json

    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None  # half written or damaged: run the cell again
    if not isinstance(data, dict) or not data.get("bench", {}).get("complete"):
        return None
    stored = data["bench"].get("config", {})
    mine = dict(key)
    if cond.selector == "scripted":  # the reference row does not depend on the endpoint
        stored = {k: v for k, v in stored.items() if k not in ("llm", "model")}
        mine = {k: v for k, v in mine.items() if k not in ("llm", "model")}
    if stored != mine:
        raise UserError(
            f"{path} holds a result of another configuration ({stored} vs {mine})",
            "use another --out directory, or delete that directory's runs",
        )
    return data


def _load() -> list[float]:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return []


def _fmt_s(seconds: float) -> str:
    seconds = int(max(0, seconds))
    return f"{seconds // 3600}:{seconds % 3600 // 60:02d}:{seconds % 60:02d}"


class Progress:
    """One stderr line per cell with a bar and an ETA from the cells timed so far (per
    condition: a baseline's cell takes several times an AeroWeaver cell)."""

    def __init__(self, total: int, skipped: int, jobs: int = 1) -> None:
        self.jobs = max(1, jobs)
        self.total = total
        self.done = skipped
        self.started = time.monotonic()
        self.times: dict[str, list[float]] = {}

    def eta(self, remaining: Sequence[Cell]) -> float | None:
        all_times = [t for ts in self.times.values() for t in ts]
        if not all_times:
            return None
        overall = sum(all_times) / len(all_times)
        est = 0.0
        for c in remaining:
            ts = self.times.get(c.condition)
            est += sum(ts) / len(ts) if ts else overall
        return est / self.jobs

    def line(self, cell: Cell, seconds: float, outcome: str, remaining: Sequence[Cell]) -> str:
        self.done += 1
        self.times.setdefault(cell.condition, []).append(seconds)
        width = 24
        filled = int(width * self.done / max(1, self.total))
        eta = self.eta(remaining)
        return (
            f"[{'#' * filled}{'.' * (width - filled)}] {self.done}/{self.total} "
            f"{cell}: {outcome} in {seconds:.1f} s | elapsed "
            f"{_fmt_s(time.monotonic() - self.started)}, ETA "
            f"{_fmt_s(eta) if eta is not None else '?'}"
        )


@contextlib.asynccontextmanager
async def endpoint(args: argparse.Namespace) -> AsyncIterator[tuple[LLMConfig, str]]:
    """(LLM config, source name): the fake provider (--quick), a URL, or the embedded model
    (started per run by the orchestration, with one cache slot per UAV)."""
    deadline = args.llm_deadline or (10.0 if args.quick else DEFAULT_LLM_DEADLINE_S)
    if args.quick and not args.llm:
        from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy

        async with FakeProvider(Policy(prefer="A"), n_slots=8) as fp:
            cfg = LLMConfig(base_url=fp.base_url, model=fp.model, deadline_s=deadline)
            yield cfg, "fake"
        return
    fields: dict[str, Any] = {"base_url": args.llm, "deadline_s": deadline}
    if args.model:
        fields["model"] = args.model
    if args.api_key_env:
        fields["api_key_env"] = args.api_key_env
    cfg = parse_config(fields, LLMConfig, "LLM flags")
    yield cfg, (args.llm if args.llm else "embedded")


async def run_cell(
    cell: Cell, args: argparse.Namespace, llm: LLMConfig, key: dict[str, Any]
) -> dict[str, Any]:
    from aeroweaver_edge.orchestration.swarm import run_swarm

    out = Path(args.out)
    cond = CONDITIONS[cell.condition]
    trace = cell.trace_path(out)
    trace.parent.mkdir(parents=True, exist_ok=True)
    load_before = _load()
    started = time.monotonic()
    plain = trace
    try:
        with tempfile.TemporaryDirectory(prefix="aw-bench-mem-") as mem:
            opts = swarm_options(
                cond,
                task=cell.task,
                seed=cell.seed,
                episodes=args.episodes,
                rounds=args.rounds,
                llm=llm,
                deadline_s=args.deadline,
                trace_path=trace,
                memory_dir=Path(mem),
            )
            # holds only: no result; option letters in the seeded order all conditions share
            opts = dataclasses.replace(opts, require_llm_answer=True, option_order=OPTION_ORDER)
            summary = (await run_swarm(opts)).as_dict()
        wall = time.monotonic() - started
        # off the loop: other cells' daemons share it
        episodes = episode_metrics(await asyncio.to_thread(read_trace, trace))
        trace = await asyncio.to_thread(archive_trace, trace)
    except asyncio.CancelledError:
        # half a cell is no result: its plain trace goes, a resume reruns it (a .gz that a
        # stop left without its JSON is read by no report and overwritten by the rerun)
        plain.unlink(missing_ok=True)
        raise
    unusable = llm_failure_problem(episodes)
    data = {
        "bench": {
            "task": cell.task,
            "condition": cell.condition,
            "title": cond.title,
            "seed": cell.seed,
            "config": key,
            "deadline_s": opts.deadline_s,
            "llm_deadline_s": llm.deadline_s,
            "finished": datetime.now(UTC).isoformat(timespec="seconds"),
            "wall_s": round(wall, 2),
            "load_before": load_before,
            "load_after": _load(),
            "trace": str(trace.relative_to(out)),
            "trace_check": check_against_summary(episodes, summary),
            # one LLM Commander activation of this task on this endpoint (bench.setup_cost):
            # counted once per run in the totals of the conditions that use the activation
            "setup_tokens": _setup_tokens(out, cell),
            # the embedded server's llama.cpp threads: speed only, not the answers' source
            "llm_threads": embedded_threads() if key["llm"] == "embedded" else None,
            "complete": unusable is None,
            "unusable": unusable,
        },
        "episodes": episodes,
        "summary": summary,
    }
    write_json_file(cell.json_path(out), data)  # incomplete: kept to read, rerun on resume
    if unusable is not None:
        raise CellUnusable(unusable)
    return data


def _setup_tokens(out: Path, cell: Cell) -> int | None:
    from aeroweaver_lab.bench.setup_cost import load_setup

    if cell.condition not in SETUP_CONDITIONS:
        return 0
    setup = load_setup(out, cell.task)
    value = None if setup is None else setup.get("setup_tokens")
    return value if isinstance(value, int) else None


def archive_trace(path: Path) -> Path:
    """``path`` gzip-compressed beside it (level 9, no name or time in the header, so the
    same trace is the same bytes), the plain file removed; returns the ``.gz`` path."""
    import gzip

    gz = path.with_name(path.name + ".gz")
    tmp = gz.with_name(gz.name + ".part")
    with (
        path.open("rb") as src,
        tmp.open("wb") as raw,
        gzip.GzipFile(filename="", mode="wb", compresslevel=9, fileobj=raw, mtime=0) as z,
    ):
        z.write(src.read())
    tmp.replace(gz)
    path.unlink(missing_ok=True)  # a stopped cell may have removed it meanwhile
    return gz


def physical_cores() -> int:
    """Physical cores this process may use: distinct (package, core) pairs in
    ``/proc/cpuinfo`` (hyper-threads share a core's FMA units), capped by the usable CPUs
    (affinity mask and CPU quota, ``llm.cpus``); the usable CPUs where cpuinfo says nothing."""
    from aeroweaver_edge.llm.cpus import usable_cpus

    usable = usable_cpus()
    try:
        text = Path("/proc/cpuinfo").read_text(encoding="ascii", errors="replace")
    except OSError:
        return usable
    cores: set[tuple[str, str]] = set()
    for block in text.split("\n\n"):
        fields = dict(
            (k.strip(), v.strip()) for k, _, v in (ln.partition(":") for ln in block.splitlines())
        )
        if "core id" in fields:
            cores.add((fields.get("physical id", "0"), fields["core id"]))
    return max(1, min(usable, len(cores))) if cores else usable


class CellUnusable(Exception):
    """The episode ran but its decisions mostly failed at the LLM: not a result."""


MAX_LLM_FAILURE_SHARE = 0.25
"""Above this share of decisions held for ``llm_failure`` a cell measures the endpoint's
outage, not the method: it is kept for reading but not counted, and a resume reruns it.
(The embedded run's worst finished cell had 3 of 72.)"""


def llm_failure_problem(episodes: Sequence[dict[str, Any]]) -> str | None:
    """Why a cell says more about its endpoint than its method, or None. HMAS-2's local
    reviews count too: a failed review does not hold the UAV (the plan stands), so without
    them a cell whose reviews all timed out would pass as HMAS-2 without feedback."""
    decisions = sum(int(e.get("decisions", 0)) for e in episodes)
    held = sum(int(e.get("holds_by_cause", {}).get("llm_failure", 0)) for e in episodes)
    asked = sum(int(e.get("central_reviews", {}).get("asked", 0)) for e in episodes)
    lost = sum(int(e.get("central_reviews", {}).get("failed", 0)) for e in episodes)
    if decisions and held / decisions > MAX_LLM_FAILURE_SHARE:
        return (
            f"{held} of {decisions} decisions held because the LLM call failed "
            f"(over {MAX_LLM_FAILURE_SHARE:.0%}): the endpoint was failing, not the method"
        )
    if asked and lost / asked > MAX_LLM_FAILURE_SHARE:
        return (
            f"{lost} of {asked} local reviews were lost because the LLM call failed "
            f"(over {MAX_LLM_FAILURE_SHARE:.0%}): the plan went unreviewed, so this is not "
            "HMAS-2; raise --llm-deadline or lower --jobs"
        )
    return None


def _outcome(data: dict[str, Any]) -> str:
    rets = [e["team_return"] for e in data["episodes"]]
    shown = ", ".join("n/a" if r is None else f"{r:.2f}" for r in rets)
    problems = data["bench"]["trace_check"]
    return f"return {shown}" + (f" (trace mismatch: {problems})" if problems else "")


def _record_session(out: Path, entry: dict[str, Any]) -> None:
    import json

    path = out / "manifest.json"
    try:
        manifest = json.loads(path.read_text(encoding="utf-8")) if path.exists() else {}
    except ValueError:
        manifest = {}
    manifest.setdefault("sessions", []).append(entry)
    write_json_file(path, manifest)


async def run_all(args: argparse.Namespace, cells: list[Cell]) -> int:
    out = Path(args.out)
    failures: list[str] = []
    async with endpoint(args) as (llm, source):
        key = config_key(args.rounds, args.episodes, llm, source)
        todo = [
            c for c in cells if load_done(c.json_path(out), key, CONDITIONS[c.condition]) is None
        ]
        if source != "embedded" and any(CONDITIONS[c.condition].selector == "llm" for c in todo):
            await preflight(llm)  # before any cell: hours of holds are no benchmark
        jobs = max(1, min(args.jobs, len(todo) or 1))
        session: dict[str, Any] = {
            "command": "aeroweaver bench run " + " ".join(shlex.quote(a) for a in args.argv),
            "started": datetime.now(UTC).isoformat(timespec="seconds"),
            "load_start": _load(),
            "machine": {
                "cpus": os.cpu_count(),
                "physical_cores": physical_cores(),
                "platform": platform.platform(),
                "python": platform.python_version(),
                "cpu": cpu_identity(),
            },
            "llm": source,
            "model": llm.model,
            "llm_threads": embedded_threads() if source == "embedded" else None,
            "llm_deadline_s": llm.deadline_s,
            "jobs": jobs,
            "cells_planned": len(cells),
            "cells_skipped": len(cells) - len(todo),
        }
        progress = Progress(len(cells), len(cells) - len(todo), jobs)
        print(
            f"bench: {len(cells)} cells, {len(cells) - len(todo)} already done, "
            f"{len(todo)} to run, {jobs} at a time; LLM: {source} ({llm.model}); "
            f"results in {out}",
            file=sys.stderr,
            flush=True,
        )
        ran: list[Cell] = []  # filled as cells finish: an interrupted session counts them too
        try:
            if any(c.condition in SETUP_CONDITIONS for c in cells) and source != "scripted":
                await measure_setups(out, sorted({c.task for c in cells}), llm, source)
            await _run_cells(args, todo, llm, key, jobs, progress, failures, ran)
        finally:
            session.update(
                finished=datetime.now(UTC).isoformat(timespec="seconds"),
                load_end=_load(),
                cells_run=len(ran),
                failures=failures,
            )
            _record_session(out, session)
    from aeroweaver_lab.bench.report import write_report

    write_report(out, tasks=args.tasks, conditions=args.conditions)
    print(f"bench: report written to {out / 'table.md'}", file=sys.stderr)
    if failures:
        print(
            f"bench: {len(failures)} cell(s) failed; rerun the same command to retry them:",
            file=sys.stderr,
        )
        for f in failures:
            print(f"  {f}", file=sys.stderr)
        return 1
    return 0


async def _run_cells(
    args: argparse.Namespace,
    todo: list[Cell],
    llm: LLMConfig,
    key: dict[str, Any],
    jobs: int,
    progress: Progress,
    failures: list[str],
    ran: list[Cell],
) -> None:
    """``todo`` with up to ``jobs`` cells running at once: a worker takes the next cell as
    soon as its last one ends, so no core waits for the slowest cell of a batch. Cells that
    ran to a result are appended to ``ran``. Two unusable cells in a row (in finishing
    order) stop all."""
    queue = list(todo)
    unusable_in_a_row = 0
    stop: BaseException | None = None

    async def worker() -> None:
        nonlocal unusable_in_a_row, stop
        while queue and stop is None:
            cell = queue.pop(0)
            t0 = time.monotonic()
            try:
                data = await run_cell(cell, args, llm, key)
                outcome = _outcome(data)
                ran.append(cell)
                unusable_in_a_row = 0
            except (asyncio.CancelledError, KeyboardInterrupt):
                raise
            except UserError as exc:  # e.g. the endpoint stopped answering: stop the run
                stop = stop or exc
                return
            except Exception as exc:  # one cell failing must not lose the others
                from aeroweaver_edge.runtime.redact import one_line

                outcome = f"FAILED: {one_line(f'{type(exc).__name__}: {exc}')[:300]}"
                failures.append(f"{cell}: {outcome}")
                unusable = isinstance(exc, CellUnusable)
                unusable_in_a_row = unusable_in_a_row + 1 if unusable else 0
            line = progress.line(cell, time.monotonic() - t0, outcome, queue)
            print(line, file=sys.stderr, flush=True)
            if unusable_in_a_row >= 2 and stop is None:
                stop = RunFailed(
                    f"the LLM failed most decisions of {unusable_in_a_row} cells in a row "
                    f"(last: {cell}); fix the endpoint, then rerun the same command to resume"
                )

    workers = [asyncio.create_task(worker(), name=f"bench-job-{i}") for i in range(jobs)]
    try:
        await asyncio.gather(*workers)
    finally:
        for w in workers:
            w.cancel()
        await asyncio.gather(*workers, return_exceptions=True)
    if stop is not None:
        raise stop


async def preflight(llm: LLMConfig) -> None:
    """The endpoint's start-up probe; a ``UserError`` naming the cause if it does not answer."""
    from aeroweaver_edge.orchestration.llm import probe

    verdict = await probe(llm)
    if not verdict.verdict:
        raise UserError(verdict.unanswered_line())
    print(f"bench: {verdict.line()}", file=sys.stderr, flush=True)


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="aeroweaver bench run",
        description="Tasks x conditions x seeds: per-episode JSON + traces, a CSV, a "
        "Markdown table and plots; resumable (finished cells are skipped).",
    )
    p.add_argument(
        "--tasks",
        nargs="+",
        type=canonical_task,
        choices=TASK_NAMES,
        default=None,
        metavar="TASK",
        help=f"default: all ({', '.join(TASK_NAMES)})",
    )
    p.add_argument(
        "--conditions",
        nargs="+",
        choices=list(CONDITIONS),
        default=None,
        metavar="COND",
        help=f"default: all ({', '.join(CONDITIONS)})",
    )
    p.add_argument(
        "--seeds",
        type=int_in(1, 1000),
        default=None,
        help="seeds 1..N (default 3; with --report-only: every finished seed unless given)",
    )
    p.add_argument(
        "--first-seed", type=int_in(0), default=None, help="seeds start here (default 1)"
    )
    p.add_argument(
        "--episodes",
        type=int_in(1, 1000),
        default=1,
        help="consecutive episodes per seed, memory kept (default 1)",
    )
    p.add_argument(
        "--rounds",
        type=int_in(1, 1000),
        default=None,
        help="episode horizon (default 24; 2 with --quick)",
    )
    p.add_argument(
        "--llm",
        metavar="URL",
        help="OpenAI-compatible base URL "
        "(default: the embedded SmolLM2-135M; --quick: the fake provider)",
    )
    p.add_argument("--model", help="model name at that endpoint")
    p.add_argument("--api-key-env", help="environment variable holding the API key")
    p.add_argument(
        "--llm-deadline",
        type=finite(),
        default=None,
        help=f"seconds per LLM call (default {DEFAULT_LLM_DEADLINE_S:g})",
    )
    p.add_argument(
        "--deadline",
        type=finite(),
        default=None,
        help="seconds per round (default: from the LLM deadline and the "
        "condition's sequential calls)",
    )
    p.add_argument(
        "--jobs",
        type=int_in(1, 256),
        default=None,
        help="cells run at once (default: the physical cores; with the embedded model each "
        "cell's server then gets one thread)",
    )
    p.add_argument("--out", default="bench-results", help="output directory")
    p.add_argument(
        "--quick",
        action="store_true",
        help="CI: every task and condition, 1 seed, 2 rounds, the fake LLM",
    )
    p.add_argument(
        "--report-only",
        action="store_true",
        help="only rebuild table, CSV and plots from the finished cells",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    args.argv = argv
    # A name given twice (or two spellings of one task) is one cell, one row, one column.
    args.tasks = list(dict.fromkeys(args.tasks or TASK_NAMES))
    args.conditions = list(dict.fromkeys(args.conditions or CONDITIONS))
    # --report-only reports the seeds a run names, or every finished seed if none is named
    report_seeds = None
    if args.seeds is not None or args.first_seed is not None:
        first = 1 if args.first_seed is None else args.first_seed
        report_seeds = range(first, first + (args.seeds or DEFAULT_SEEDS))
    if args.seeds is None:
        args.seeds = 1 if args.quick else DEFAULT_SEEDS
    if args.first_seed is None:
        args.first_seed = 1
    if args.quick:
        args.rounds = args.rounds or 2
    args.rounds = args.rounds or 24
    if args.llm:
        check_llm_url(args.llm)
    elif args.model or args.api_key_env:
        flag = "--model" if args.model else "--api-key-env"
        raise UserError(
            f"{flag} is for an endpoint given with --llm URL",
            "add --llm URL, or drop it to use the embedded SmolLM2-135M",
        )
    check_api_key_env(args.api_key_env)
    out = Path(args.out)
    if args.report_only:
        return _report_only(out, args, report_seeds)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out} is not a directory", "give --out a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(
            f"--out {out} cannot be created ({exc.strerror or exc})",
            "give --out a writable directory",
        ) from None
    if not os.access(out, os.W_OK):
        raise UserError(f"--out {out} is not writable", "give --out a writable directory")
    if args.jobs is None:
        args.jobs = physical_cores()
    if args.jobs > 1 and not args.llm and not args.quick:
        # one model server per job: one thread each beats two threads on one server under
        # load (docs/performance.md); an explicit AEROWEAVER_LLM_THREADS is kept
        os.environ.setdefault(THREADS_ENV, "1")
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    cells = plan_cells(args.tasks, args.conditions, seeds)
    return asyncio.run(_cancellable(run_all(args, cells)))


def _report_only(out: Path, args: argparse.Namespace, seeds: range | None) -> int:
    """Rebuild the report from finished cells; a directory without any is a mistyped
    ``--out``, not an empty benchmark, so it is refused rather than given an empty table.
    Named seeds restrict it, so a run still adding seeds can publish a table in which every
    condition has the same seeds."""
    from aeroweaver_lab.bench.report import load_cells, write_report

    if not out.is_dir():
        raise UserError(
            f"--out {out} is not a benchmark directory: nothing to report",
            "give --out the directory a bench run wrote",
        )
    cells = load_cells(out)
    if not cells:
        raise UserError(
            f"--out {out} holds no finished cell (runs/TASK/CONDITION/seedN.json)",
            "run the benchmark into it first (the same command without --report-only)",
        )
    if seeds is not None and not any(c["bench"]["seed"] in seeds for c in cells):
        raise UserError(
            f"--out {out} holds no finished cell of seeds {seeds.start}..{seeds.stop - 1}",
            "name seeds the run has finished, or drop --seeds/--first-seed for all of them",
        )
    if not os.access(out, os.W_OK):
        raise UserError(f"--out {out} is not writable", "give --out a writable directory")
    write_report(out, tasks=args.tasks, conditions=args.conditions, seeds=seeds)
    print(f"report written to {out / 'table.md'}", file=sys.stderr)
    return 0


async def _cancellable(coro: Any) -> int:
    """SIGTERM / SIGINT cancel the run, so every session and server is closed on the way
    out; finished cells are kept and the same command resumes."""
    import signal

    task = asyncio.ensure_future(coro)
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, task.cancel)
    try:
        return int(await task)
    finally:
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.remove_signal_handler(sig)


__all__ = ["Cell", "build_parser", "config_key", "load_done", "main", "plan_cells"]
