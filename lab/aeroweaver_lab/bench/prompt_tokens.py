"""Uncached prompt tokens per round decision, counted offline for every task.

A decision costs the prompt tokens its llama.cpp cache slot does not hold yet: those after
the longest common prefix with the same UAV's previous prompt (its first prompt against the
role's prefix that ``llm.slot_seed`` copies into the slot before round 0). The embedded model
needs minutes per episode on a small machine; this count needs seconds per task:

1. fly each task (``aeroweaver sim TASK``, its default team, seeded) against the loopback
   fake provider (``llm.fake_provider``: seeded label picks, answers in milliseconds) and keep
   every round-decision request the daemons sent -- the exact chat messages this code renders;
2. put each through the embedded server's ``/apply-template`` and ``/tokenize`` (SmolLM2's
   chat template and tokenizer) and count as the slot cache does.

The trajectories are the fake's picks, not SmolLM2's, so a task's figure is the prompt
layout's cost on a plausible flight; the README command's own figure comes from its run
summary (``tokens_per_decision.prompt_uncached``). Run it on two trees to compare layouts:

    python -m aeroweaver_lab.bench.prompt_tokens [--tasks coverage ...] [--rounds 24]
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
from collections.abc import Sequence
from typing import Any

import httpx

from aeroweaver_edge.cli.checks import int_in
from aeroweaver_edge.cli.errors import ArgumentParser, report
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.llm.embedded import EmbeddedServer, EmbeddedUnavailable
from aeroweaver_edge.llm.fake_provider import FakeProvider, Policy
from aeroweaver_edge.tasks import TASK_NAMES

SLOTS = 8  # cache slots of the fake (>= any task's default team)


def _round_decision(body: dict[str, Any]) -> bool:
    """A daemon's round decision: pinned to a cache slot and carrying lettered options (the
    endpoint probe and slot seeding carry neither)."""
    user = str(body.get("messages", [{}])[-1].get("content", ""))
    return isinstance(body.get("id_slot"), int) and "\nA. " in user and "\nB. " in user


def fly(task: str, seed: int, rounds: int) -> list[dict[str, Any]]:
    """The round-decision request bodies of one ``aeroweaver sim`` episode, in order."""
    policy = Policy(prefer="A", margin=0.5, seed=seed, usage="llama", llama_extras=True)
    with FakeProvider(policy, model="fake", n_slots=SLOTS).in_thread() as fp:
        cmd = [sys.executable, "-m", "aeroweaver_edge", "sim", task, "--quiet"]
        cmd += ["--seed", str(seed), "--rounds", str(rounds)]
        cmd += ["--llm", fp.base_url, "--model", fp.model, "--llm-slots"]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        bodies = [b for b in fp.chat_bodies() if _round_decision(b)]
    if done.returncode != 0:
        raise UserError(f"sim {task} seed {seed} failed (exit {done.returncode}): "
                        f"{done.stderr.strip().splitlines()[-1:] or ['no output']}")  # fmt: skip
    return bodies


def _common(a: Sequence[int], b: Sequence[int]) -> int:
    n = 0
    for x, y in zip(a, b, strict=False):
        if x != y:
            break
        n += 1
    return n


class Counter:
    """Tokens through the embedded server's chat template and tokenizer."""

    def __init__(self, server: EmbeddedServer) -> None:
        self._root = server.base_url.removesuffix("/v1")
        self._http = httpx.Client(timeout=60.0)

    def tokens(self, messages: Sequence[dict[str, Any]]) -> list[int]:
        text = self._post("/apply-template", {"messages": list(messages)})["prompt"]
        return [int(t) for t in self._post("/tokenize", {"content": text})["tokens"]]

    def _post(self, path: str, body: dict[str, Any]) -> dict[str, Any]:
        r = self._http.post(self._root + path, json=body)
        r.raise_for_status()
        data: dict[str, Any] = r.json()
        return data

    def uncached(self, bodies: Sequence[dict[str, Any]]) -> list[int]:
        """Per request: tokens after the longest common prefix with its slot's previous
        prompt; a slot's first against the seeded prefix (system + "You are UAV x.")."""
        last: dict[int, list[int]] = {}
        out = []
        for body in bodies:
            messages = body["messages"]
            toks = self.tokens(messages)
            prev = last.get(body["id_slot"])
            if prev is None:
                identity = str(messages[-1]["content"]).split("\n", 1)[0] + "\n"
                prev = self.tokens([*messages[:-1], {"role": "user", "content": identity}])
            out.append(len(toks) - _common(prev, toks))
            last[body["id_slot"]] = toks
        return out

    def close(self) -> None:
        self._http.close()


def summary(task: str, counts: Sequence[int], bodies: Sequence[dict[str, Any]]) -> dict[str, Any]:
    uavs = len({b["id_slot"] for b in bodies})
    return {
        "task": task,
        "uavs": uavs,
        "decisions": len(counts),
        "uncached_per_decision": round(statistics.mean(counts), 1) if counts else None,
        "median": statistics.median(counts) if counts else None,
        "first_rounds_mean": round(statistics.mean(counts[:uavs]), 1) if counts else None,
    }


def main(argv: Sequence[str] | None = None) -> int:
    p = ArgumentParser(
        prog="python -m aeroweaver_lab.bench.prompt_tokens", description=__doc__.splitlines()[0]
    )
    p.add_argument("--tasks", nargs="+", choices=TASK_NAMES, default=list(TASK_NAMES))
    p.add_argument("--seed", type=int_in(0), default=1)
    p.add_argument("--rounds", type=int_in(1, 1000), default=24)
    args = p.parse_args(argv)
    try:
        with EmbeddedServer(threads=1) as server:
            counter = Counter(server)
            try:
                for task in args.tasks:
                    bodies = fly(task, args.seed, args.rounds)
                    print(json.dumps(summary(task, counter.uncached(bodies), bodies)), flush=True)
            finally:
                counter.close()
    except (UserError, EmbeddedUnavailable) as exc:
        return report(exc, verbose=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
