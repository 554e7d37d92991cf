"""The embedded model's weight formats side by side: ``aeroweaver bench weights``.

Two measurements (docs/performance.md, "Weight format"):

- **speed**: prompt tokens/s (llama.cpp's ``timings.prompt_per_second``, prompt cache off)
  of each format for prompts of a few lengths and thread counts. One server per format
  stays up; within each repetition every format runs back to back (the order rotates), so
  a load change on a shared machine hits all formats alike. The load average is printed:
  only the ratios to Q4_1 are comparable across machines and loads.
- **agreement** (``--prompts FILE``): the first-token label log-probs of each format on
  recorded round prompts (``--record FILE`` writes them from simulated episodes), compared
  with the shipped Q4_1: top-1 agreement over each prompt's option labels, mean and max
  |delta log-prob| over the labels both returned, and the Q4_1 top-two margin where they
  disagree.

Also prints this CPU's peak (``llm.peak``) and each rate as a fraction of it.
"""

from __future__ import annotations

import json
import os
import re
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import httpx

from aeroweaver_edge.cli.checks import check_output_file, int_in
from aeroweaver_edge.cli.errors import ArgumentParser, report
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.llm import weights
from aeroweaver_edge.llm.embedded import EmbeddedServer, EmbeddedUnavailable, find_model
from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
from aeroweaver_edge.llm.peak import MODEL_PARAMS, cpu_peak
from aeroweaver_edge.runtime.redact import one_line
from aeroweaver_edge.tasks import TASK_NAMES

LENGTHS = (150, 600)
SLOTS = 8  # cache slots of the recording fake and the agreement servers (>= any task's team)
THREADS = (1, 2)
# Text to cut prompts from: a round prompt's kind of content, repeated past the longest length.
_FILLER = (
    "You are uav{i}, a searcher. Mission: cover every landmark with one drone each and hold "
    "there; avoid collisions. Position north {n} east {e}, velocity 0.0 0.0. Landmark L{j} at "
    "north {e} east {n}, 41 m away. Message from uav{j}: going to L{i}. Options: A. "
    "cover_landmark(target_id=L{j}) B. explore_local() C. hold_position() D. "
    "return_in_bounds(). Answer with one letter.\n"
)
_OPTION = re.compile(r"^([A-Z])\. ", re.MULTILINE)


def load_average() -> float:
    return os.getloadavg()[0]


def _filler() -> str:
    parts = (_FILLER.format(i=i % 7, j=i * 3 % 5, n=i * 7 % 60, e=i * 11 % 60) for i in range(60))
    return "".join(parts)


def _post(client: httpx.Client, url: str, body: dict[str, Any]) -> dict[str, Any]:
    response = client.post(url, json=body, timeout=600.0)
    response.raise_for_status()
    data = response.json()
    if not isinstance(data, dict):
        raise RuntimeError(f"{url} answered {type(data).__name__}")
    return data


def _root(server: EmbeddedServer) -> str:
    return server.base_url.removesuffix("/v1")


@contextmanager
def _servers(
    formats: Sequence[str],
    threads: int,
    n_batch: int | None = None,
    n_ubatch: int | None = None,
    n_parallel: int = 1,
) -> Iterator[dict[str, EmbeddedServer]]:
    with ExitStack() as stack:
        out = {}
        for fmt in formats:
            server = EmbeddedServer(
                threads=threads,
                weights=fmt,
                n_batch=n_batch,
                n_ubatch=n_ubatch,
                n_parallel=n_parallel,
            )
            out[fmt] = stack.enter_context(server)
        yield out


def speed(
    formats: Sequence[str],
    *,
    threads: Sequence[int] = THREADS,
    lengths: Sequence[int] = LENGTHS,
    reps: int = 3,
    n_batch: int | None = None,
    n_ubatch: int | None = None,
) -> list[dict[str, Any]]:
    """Rows ``{format, threads, tokens, rates, median}`` (prompt tokens/s per repetition)."""
    rates: dict[tuple[str, int, int], list[float]] = {}
    with httpx.Client() as client:
        for t in threads:
            with _servers(formats, t, n_batch, n_ubatch) as servers:
                first = _root(next(iter(servers.values())))
                ids = _post(client, f"{first}/tokenize", {"content": _filler()})["tokens"]
                if len(ids) < max(lengths):
                    raise RuntimeError(f"the filler text has only {len(ids)} tokens")
                for rep in range(reps):
                    k = rep % len(formats)  # rotate the order, so no format always goes first
                    order = [*formats[k:], *formats[:k]]
                    for fmt in order:
                        for n in lengths:
                            body = {
                                "prompt": ids[:n],
                                "max_tokens": 1,
                                "temperature": 0,
                                "cache_prompt": False,
                            }
                            data = _post(client, f"{_root(servers[fmt])}/v1/completions", body)
                            timings = data["timings"]
                            if int(timings["prompt_n"]) != n:
                                raise RuntimeError(f"{fmt}: {timings['prompt_n']} tokens, not {n}")
                            rates.setdefault((fmt, t, n), []).append(
                                float(timings["prompt_per_second"])
                            )
    return [
        {
            "format": fmt,
            "threads": t,
            "tokens": n,
            "rates": [round(r, 1) for r in values],
            "median": round(statistics.median(values), 1),
        }
        for (fmt, t, n), values in rates.items()
    ]


def option_labels(body: dict[str, Any]) -> list[str]:
    """The option letters (``"A. ..."`` lines) of a recorded request's last user message."""
    messages = body.get("messages") or []
    text = next(
        (str(m.get("content", "")) for m in reversed(messages) if m.get("role") == "user"), ""
    )
    return list(dict.fromkeys(_OPTION.findall(text)))


def label_logprobs(data: dict[str, Any], labels: Sequence[str]) -> dict[str, float]:
    """Log-prob of each label among the first token's top list (labels absent: left out)."""
    content = ((data.get("choices") or [{}])[0].get("logprobs") or {}).get("content") or []
    if not content:
        return {}
    out: dict[str, float] = {}
    for entry in content[0].get("top_logprobs") or []:
        token = str(entry.get("token", "")).strip()
        if token in labels and token not in out and float(entry["logprob"]) > -9000:
            out[token] = float(entry["logprob"])
    return out


def _top(scores: dict[str, float]) -> tuple[str | None, float]:
    """The best label and its margin over the second (inf when only one came back)."""
    ranked = sorted(scores.items(), key=lambda kv: -kv[1])
    if not ranked:
        return None, 0.0
    margin = ranked[0][1] - ranked[1][1] if len(ranked) > 1 else float("inf")
    return ranked[0][0], margin


def agreement(
    prompts: Sequence[dict[str, Any]],
    formats: Sequence[str],
    threads: int,
    *,
    cache: bool,
    scores_out: Path | None = None,
    first: int = 0,
) -> list[dict[str, Any]]:
    """Per format (Q4_1 first, the reference): first-token label log-probs on every recorded
    prompt, compared with Q4_1's (``summarize``). ``cache``: replay the prompts in their
    recorded order with their recorded cache slot (``id_slot``), as the run sent them, so
    each UAV's prefix is reused (cheap; llama.cpp's cache reuse shifts log-probs by ~0.03
    nats, docs/notes/llm.md); else every prompt is processed whole. ``scores_out``: one JSON line
    per prompt as it is done, numbered from ``first`` (``--from-scores`` summarises such
    files, also partial ones)."""
    formats = [weights.SHIPPED, *[f for f in formats if f != weights.SHIPPED]]
    per_prompt: list[dict[str, dict[str, float]]] = []
    slots = SLOTS if cache else 1
    with ExitStack() as stack:
        client = stack.enter_context(httpx.Client())
        pool = stack.enter_context(ThreadPoolExecutor(len(formats)))
        servers = stack.enter_context(_servers(formats, threads, n_parallel=slots))
        out = stack.enter_context(scores_out.open("w", encoding="utf-8")) if scores_out else None
        for i, body in enumerate(prompts):
            labs = option_labels(body)
            req = {k: v for k, v in body.items() if k != "stream"}
            if cache and isinstance(req.get("id_slot"), int):
                req["id_slot"] = req["id_slot"] % slots
            else:
                req.pop("id_slot", None)
            req.update(cache_prompt=cache, top_logprobs=max(20, int(req.get("top_logprobs", 20))))
            # The formats' servers work on the same prompt at once (one thread each).
            futures = {
                fmt: pool.submit(_post, client, f"{servers[fmt].base_url}/chat/completions", req)
                for fmt in formats
            }
            row = {fmt: label_logprobs(f.result(), labs) for fmt, f in futures.items()}
            per_prompt.append(row)
            if out is not None:
                line = {"prompt": first + i, "labels": labs, "scores": row}
                out.write(json.dumps(line) + "\n")
                out.flush()
            if (i + 1) % 50 == 0:
                print(f"agreement: {i + 1}/{len(prompts)} prompts", file=sys.stderr, flush=True)
    return summarize(per_prompt, formats)


def summarize(
    per_prompt: Sequence[dict[str, dict[str, float]]], formats: Sequence[str]
) -> list[dict[str, Any]]:
    """Top-1 agreement with Q4_1 over each prompt's option labels, |delta log-prob| over the
    labels both returned, and Q4_1's top-two margin where the picks differ."""
    rows = []
    for fmt in formats:
        same, deltas, margins, n = 0, [], [], 0
        for row in per_prompt:
            a, b = row.get(weights.SHIPPED, {}), row.get(fmt, {})
            top_a, margin = _top(a)
            top_b, _ = _top(b)
            if top_a is None or top_b is None:
                continue
            n += 1
            if top_a == top_b:
                same += 1
            else:
                margins.append(margin)
            deltas += [abs(a[k] - b[k]) for k in a.keys() & b.keys()]
        rows.append(
            {
                "format": fmt,
                "prompts": n,
                "top1_agree": round(same / n, 4) if n else None,
                "mean_abs_delta": round(statistics.fmean(deltas), 4) if deltas else None,
                "max_abs_delta": round(max(deltas), 4) if deltas else None,
                "disagree_margin_max": round(max(margins), 4) if margins else None,
                "disagree_margin_median": round(statistics.median(margins), 4) if margins else None,
            }
        )
    return rows


def _round_prompt(body: dict[str, Any]) -> bool:
    """A daemon's round decision: pinned to its cache slot (``--llm-slots``) and lettered
    options. The endpoint probe and the Commander's calls carry no slot."""
    return isinstance(body.get("id_slot"), int) and len(option_labels(body)) >= 2


def record(out: Path, tasks: Sequence[str], seeds: Sequence[int], rounds: int) -> int:
    """Run ``aeroweaver sim`` episodes against the fake provider (``llm.fake_provider``: a
    real loopback OpenAI-compatible server with seeded label preferences) and write every
    round-decision request body it received as JSON Lines.

    The fake answers in milliseconds, so hundreds of round prompts of all nine tasks take
    minutes on a loaded machine, where the embedded model needs hours; the prompts are the
    exact bodies the daemons send (rules, mission, skills, history, observation, options),
    and only the picks that shaped the histories are the fake's, not SmolLM2's."""
    kept: list[dict[str, Any]] = []
    for task in tasks:
        for seed in seeds:
            policy = Policy(prefer="ABCD"[seed % 4], seed=seed, margin=1.0, llama_extras=True)
            fake = FakeProvider(policy, model="smollm2-135m-instruct", n_slots=SLOTS)
            with fake.in_thread() as fp:
                cmd = [sys.executable, "-m", "aeroweaver_edge", "sim", task, "--quiet"]
                cmd += ["--seed", str(seed), "--rounds", str(rounds)]  # the task's own team
                cmd += ["--llm", fp.base_url, "--model", fp.model, "--llm-slots"]
                done = subprocess.run(cmd, capture_output=True, text=True, check=False)
                bodies = [b for b in fp.chat_bodies() if _round_prompt(b)]
            print(f"recorded {task} seed {seed}: exit {done.returncode}, {len(bodies)} prompts",
                  file=sys.stderr)  # fmt: skip
            if done.returncode != 0:
                print(done.stderr[-2000:], file=sys.stderr)
            kept += bodies
    with out.open("w", encoding="utf-8") as f:
        for body in kept:
            f.write(json.dumps(body) + "\n")
    return len(kept)


def _read_prompts(path: Path, start: int, limit: int | None) -> list[dict[str, Any]]:
    """The recorded chat bodies in ``path`` (JSON Lines)."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
        rows = [json.loads(line) for line in lines if line.strip()]
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise UserError(
            f"--prompts {path}: {one_line(str(exc))}",
            "give a file written by 'aeroweaver bench weights --record FILE'",
        ) from None
    if not all(isinstance(r, dict) and isinstance(r.get("messages"), list) for r in rows):
        raise UserError(
            f"--prompts {path}: a line is not a recorded chat request",
            "give a file written by 'aeroweaver bench weights --record FILE'",
        )
    return rows[start : None if limit is None else start + limit]


def main(argv: Sequence[str] | None = None) -> int:
    p = ArgumentParser(prog="aeroweaver bench weights", description=__doc__.splitlines()[0])
    p.add_argument("--formats", nargs="+", choices=weights.FORMATS, default=list(weights.FORMATS))
    p.add_argument("--threads", type=int_in(1, 256), nargs="+", default=list(THREADS))
    p.add_argument("--lengths", type=int_in(1, 4000), nargs="+", default=list(LENGTHS))
    p.add_argument("--reps", type=int_in(1), default=3, help="interleaved repetitions")
    p.add_argument("--n-batch", type=int_in(1), default=None, help="llama.cpp n_batch")
    p.add_argument("--n-ubatch", type=int_in(1), default=None, help="llama.cpp n_ubatch")
    p.add_argument("--prompts", type=Path, help="agreement on these recorded prompts (JSONL)")
    p.add_argument("--start", type=int_in(0), default=0, help="skip the first N recorded prompts")
    p.add_argument("--limit", type=int_in(1), default=None, help="use N recorded prompts")
    p.add_argument("--record", type=Path, help="record round prompts to this JSONL and stop")
    p.add_argument("--tasks", nargs="+", choices=TASK_NAMES, default=list(TASK_NAMES))
    p.add_argument("--seeds", type=int, nargs="+", default=[1])
    p.add_argument("--rounds", type=int_in(1), default=24)
    p.add_argument("--skip-speed", action="store_true", help="only the agreement")
    p.add_argument("--no-cache", action="store_true", help="agreement: every prompt whole")
    p.add_argument("--scores", type=Path, help="agreement: per-prompt label log-probs (JSONL)")
    p.add_argument("--from-scores", type=Path, nargs="+", help="summarise --scores files, stop")
    args = p.parse_args(argv)
    try:
        return _run(args)
    except (UserError, EmbeddedUnavailable, weights.WeightsUnavailable) as exc:
        return report(exc, verbose=False)


def _run(args: Any) -> int:
    if args.from_scores:
        per_prompt = []
        for path in args.from_scores:
            try:
                lines = path.read_text(encoding="utf-8").splitlines()
                per_prompt += [json.loads(line)["scores"] for line in lines if line.strip()]
            except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
                raise UserError(f"--from-scores {path}: {one_line(str(exc))}") from None
        formats = list(dict.fromkeys(f for row in per_prompt for f in row))
        for row in summarize(per_prompt, formats):
            print(json.dumps(row))
        return 0
    if args.scores:
        check_output_file(args.scores, "--scores")
    if args.record:
        check_output_file(args.record, "--record")
        n = record(args.record, args.tasks, args.seeds, args.rounds)
        print(json.dumps({"recorded": n, "file": str(args.record)}))
        return 0
    prompts = _read_prompts(args.prompts, args.start, args.limit) if args.prompts else []
    if args.prompts and not prompts:
        raise UserError(f"--prompts {args.prompts} holds no prompt")
    source = find_model()
    for fmt in args.formats:  # convert (or verify) up front, so the timings exclude it
        t0 = time.perf_counter()
        path = weights.prepare(source, fmt)
        print(json.dumps({"format": fmt, "file": str(path), "bytes": path.stat().st_size,
                          "prepare_s": round(time.perf_counter() - t0, 2)}))  # fmt: skip
    peak = cpu_peak()
    print(json.dumps({"peak": peak.as_dict()}))
    if not args.skip_speed:
        load0 = load_average()
        rows = speed(args.formats, threads=args.threads, lengths=args.lengths, reps=args.reps,
                     n_batch=args.n_batch, n_ubatch=args.n_ubatch)  # fmt: skip
        load1 = load_average()
        base = {(r["threads"], r["tokens"]): r["median"] for r in rows if r["format"] == "q4_1"}
        for r in rows:
            ref = base.get((r["threads"], r["tokens"]))
            r["x_q4_1"] = round(r["median"] / ref, 2) if ref else None
            gflops = r["median"] * 2 * MODEL_PARAMS / 1e9
            r["gflops"] = round(gflops, 1)
            r["of_fp32_peak"] = round(gflops / peak.fp32_gflops(r["threads"]), 4)
            r["n_batch"], r["n_ubatch"] = args.n_batch, args.n_ubatch
            r["load"] = [round(load0, 2), round(load1, 2)]
            print(json.dumps(r))
    if prompts:
        load0 = load_average()
        rows = agreement(
            prompts,
            args.formats,
            min(args.threads),
            cache=not args.no_cache,
            scores_out=args.scores,
            first=args.start,
        )
        for row in rows:
            row["load"] = [round(load0, 2), round(load_average(), 2)]
            print(json.dumps(row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
