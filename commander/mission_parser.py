"""Mission text + live roster -> validated ``TaskRecord`` (LLM first, deterministic fallback).

Policy: with a client, one LLM call asks for JSON matching ``TaskRecord.llm_schema()``
(``response_format: json_schema``; an endpoint that refuses it with 400/422 is asked again
in plain text). The first JSON object in the answer is validated against the roster. The
answer is rejected, and the rule-based parser used instead, when the call fails, the JSON is
missing or invalid, or it contradicts what the rules read unambiguously in the text (task
type, stated number of drones). Every fallback records why. Without a client the rules are
used directly. If neither understands the mission, ``MissionParseError`` says what is missing.

The rules are deliberately plain regular expressions over the nine tasks' usual wording (each
task's ``cues`` in its spec): they are a safety net that must behave the same way every time,
not a language model. When no cue names a task (or cues tie), the text is matched against the
tasks' own descriptions with BM25 and a task is taken only with a clear margin; otherwise the
parser refuses, naming what is missing.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import Any, Literal

from pydantic import ValidationError

from aeroweaver_edge.contracts.defaults import ARENA_HALF_M
from aeroweaver_edge.contracts.errors import UserError
from aeroweaver_edge.llm.client import CallTag, ChatClient, LLMError, LLMHTTPError
from aeroweaver_edge.tasks import get_spec, specs
from commander.mission_text import check_mission_text
from commander.retrieval import BM25Index
from commander.task_record import TASK_TYPES, TaskRecord, validation_summary

PARSE_MAX_TOKENS = 300  # a full record is ~60-150 tokens
ParseSource = Literal["llm", "fallback"]


class MissionParseError(UserError):
    """Neither the LLM nor the rules produced a valid task record; the message says why."""

    def explain(self) -> tuple[int, str]:
        return 2, f"cannot understand the mission: {self}"


# --------------------------------------------------------------------------- JSON over chat


@dataclass(frozen=True)
class JsonAnswer:
    """One JSON-returning LLM exchange. ``endpoint_failed``: the call itself failed (timeout,
    5xx, unreachable, breaker), so a second call to the same endpoint is not worth making."""

    data: dict[str, Any] | None
    tokens: int = 0
    error: str | None = None
    endpoint_failed: bool = False
    notes: tuple[str, ...] = ()


def _endpoint_failure(exc: LLMError) -> bool:
    return not isinstance(exc, LLMHTTPError) or exc.status == 429 or exc.status >= 500


def first_json_object(content: str) -> dict[str, Any] | None:
    """The first JSON object embedded in ``content`` (code fences and chatter tolerated)."""
    decoder = json.JSONDecoder()
    start = content.find("{")
    tries = 0
    while start != -1 and tries < 64:
        try:
            obj, _ = decoder.raw_decode(content, start)
        except ValueError:
            obj = None
        if isinstance(obj, dict):
            return obj
        start = content.find("{", start + 1)
        tries += 1
    return None


async def ask_json(
    client: ChatClient,
    messages: Sequence[Mapping[str, Any]],
    schema: Mapping[str, Any],
    *,
    name: str,
    purpose: str,
    max_tokens: int,
) -> JsonAnswer:
    """Ask for one JSON object; never raises for LLM failures (they come back as ``error``).

    The first request carries ``response_format`` (json_schema), ``temperature`` 0 and
    ``max_tokens``; some endpoints refuse one of those with 400/422, so the retry is bare.
    """
    tag = CallTag(agent="cmdr", role="commander", purpose=purpose)
    fmt = {"type": "json_schema", "json_schema": {"name": name, "schema": dict(schema)}}
    notes: list[str] = []
    try:
        try:
            result = await client.chat(
                messages, tag=tag, response_format=fmt, temperature=0, max_tokens=max_tokens
            )
        except LLMHTTPError as exc:
            if exc.status not in (400, 422):
                raise
            notes.append(
                f"{purpose}: endpoint refused the request with response_format/temperature/"
                f"max_tokens (HTTP {exc.status}); asked again in plain text without them"
            )
            result = await client.chat(messages, tag=tag)
    except LLMError as exc:
        return JsonAnswer(
            None,
            error=f"{type(exc).__name__}: {exc}",
            endpoint_failed=_endpoint_failure(exc),
            notes=tuple(notes),
        )
    tokens = result.usage.total_tokens
    choice = result.raw["choices"][0]
    message = choice.get("message") if isinstance(choice, dict) else None
    content = message.get("content") if isinstance(message, dict) else None
    if not isinstance(content, str) or not content.strip():
        return JsonAnswer(None, tokens, "the answer has no text content", notes=tuple(notes))
    data = first_json_object(content)
    if data is None:
        cut = " (cut off at max_tokens)" if choice.get("finish_reason") == "length" else ""
        excerpt = " ".join(content.split())[:120]
        return JsonAnswer(
            None, tokens, f"no JSON object in the answer{cut}: {excerpt!r}", notes=tuple(notes)
        )
    return JsonAnswer(data, tokens, notes=tuple(notes))


# --------------------------------------------------------------------------- rules

_NUM_WORDS = {
    "one": 1,
    "two": 2,
    "three": 3,
    "four": 4,
    "five": 5,
    "six": 6,
    "seven": 7,
    "eight": 8,
    "nine": 9,
    "ten": 10,
    "a single": 1,
    "a pair of": 2,
    "both": 2,
}
_NUM = r"(\d+|" + "|".join(sorted(_NUM_WORDS, key=len, reverse=True)) + r")"
_UAV_NOUN = (
    r"(?:drones?|uavs?|uas|aircraft|quadcopters?|quads?|copters?|multirotors?|"
    r"vehicles?|airframes?|agents?)\b"
)
# "<number> [of our|of the] [one adjective] <uav noun>"
_UAV_COUNT = re.compile(rf"\b{_NUM}\s+(?:of (?:our|the)\s+)?(?:[a-z-]+\s+)?{_UAV_NOUN}")
_NEGATED = re.compile(r"\b(?:no|not|never|nor)\s+(?:\w+\s+)?$|n't\s+(?:\w+\s+)?$")
_TOTAL_ONE = re.compile(rf"\b(?:with|using|use|only|just)\s+(?:one|a single|1)\s+{_UAV_NOUN}")


def _role_nouns(task: str) -> dict[str, str]:
    """Role nouns as operators say them (regex) -> the task role they count, from the specs."""
    return {r.nouns: r.name for r in get_spec(task).all_roles if r.nouns}


# (pattern, weight) per task, from each task's spec: 2 = names the task on its own, 1 = support
_CUES = {name: tuple((re.compile(p), w) for p, w in spec.cues) for name, spec in specs().items()}

_CONSTRAINT_CUE = re.compile(
    r"\b(?:avoid|keep|don't|do not|must not|never|no two|without|stay|at least|at most|"
    r"altitude|no closer|safe distance|collision)\b"
)
_DIR = r"(north|south)[- ]?(east|west)"
_QUADRANT = re.compile(rf"\b{_DIR}(?:ern)?\s+(?:quadrant|corner|sector|part|quarter|area)\b")
_HALF = re.compile(r"\b(north|south|east|west)(?:ern)?\s+half\b")
_FLOAT = r"(-?\d+(?:\.\d+)?)"
_CIRCLE = re.compile(
    rf"\b(?:within|inside)\s+(?:a\s+)?{_FLOAT}\s*(?:m|metres|meters)\b(?:\s+radius)?\s+"
    rf"(?:of|around|from)\s+(?:\(\s*{_FLOAT}\s*,\s*{_FLOAT}\s*\)|{_FLOAT}\s*,\s*{_FLOAT}|"
    r"the (centre|center|origin|middle)(?: of the arena)?)"
)
_RADIUS_AROUND = re.compile(
    rf"\b{_FLOAT}\s*(?:m|metres|meters)\s+radius\s+(?:around|of|about)\s+"
    rf"(?:\(\s*{_FLOAT}\s*,\s*{_FLOAT}\s*\)|the (centre|center|origin|middle))"
)
_BOX = re.compile(
    rf"\bnorth\s+{_FLOAT}\s*(?:m\s*)?(?:to|\.\.)\s*{_FLOAT}\s*(?:m\b)?\s*,?\s*(?:and\s+)?"
    rf"east\s+{_FLOAT}\s*(?:m\s*)?(?:to|\.\.)\s*{_FLOAT}"
)
_UAV_ID = re.compile(r"\b(?:uav|drone)[-_]?\d+\b")


@dataclass(frozen=True)
class TaskGuess:
    """What the rules read in a text: scores per task and the phrases that matched."""

    scores: dict[str, int]
    matched: dict[str, tuple[str, ...]]

    @property
    def ranked(self) -> list[tuple[str, int]]:
        return sorted(((t, s) for t, s in self.scores.items() if s > 0), key=lambda x: -x[1])

    @property
    def best(self) -> str | None:
        r = self.ranked
        if not r or (len(r) > 1 and r[1][1] == r[0][1]):
            return None
        return r[0][0]

    @property
    def confident(self) -> bool:
        """One task clearly ahead: strong cue (>= 2) and at least twice the runner-up."""
        r = self.ranked
        return bool(r) and r[0][1] >= 2 and (len(r) == 1 or r[1][1] * 2 <= r[0][1])


def guess_task(text: str) -> TaskGuess:
    low = text.lower()
    scores: dict[str, int] = {}
    matched: dict[str, tuple[str, ...]] = {}
    for task, cues in _CUES.items():
        hits = [(m.group(0), w) for rx, w in cues if (m := rx.search(low))]
        scores[task] = sum(w for _, w in hits)
        matched[task] = tuple(h for h, _ in hits)
    return TaskGuess(scores, matched)


BM25_MIN_SCORE = 1.5
"""The best task's BM25 score must reach this (about one distinctive word in common)..."""
BM25_MARGIN = 1.5
"""...and be this many times the runner-up's; otherwise the parser refuses."""


@dataclass(frozen=True)
class DescriptionMatch:
    """BM25 over the task specs' wording: the task it settles on (or None) and the scores."""

    task: str | None
    scores: tuple[tuple[str, float], ...]


@cache
def _task_index() -> BM25Index:
    return BM25Index([spec.corpus_text() for spec in specs().values()])


def match_description(text: str, among: Sequence[str] = TASK_TYPES) -> DescriptionMatch:
    """When no keyword decides, read the mission against every task's description, summary,
    keywords and role goals (BM25). A task is chosen only with a clear margin: refusing is
    better than guessing wrong."""
    raw = _task_index().scores(text)
    names = list(specs())
    scores = sorted(
        ((names[i], float(raw[i])) for i in range(len(names)) if names[i] in among),
        key=lambda x: (-x[1], x[0]),
    )
    best = scores[0] if scores else None
    second = scores[1][1] if len(scores) > 1 else 0.0
    ok = best is not None and best[1] >= BM25_MIN_SCORE and best[1] >= BM25_MARGIN * second
    return DescriptionMatch(best[0] if ok and best else None, tuple(scores))


def _num(word: str) -> int:
    return int(word) if word.isdigit() else _NUM_WORDS[word]


def _natural(uav: str) -> tuple[Any, ...]:
    return tuple(int(p) if p.isdigit() else p for p in re.split(r"(\d+)", uav))


def stated_uav_count(text: str) -> int | None:
    """Total UAVs the text asks for: the largest '<n> drones', ignoring negated counts ('no
    two drones', "don't put two UAVs") and distributive 'one drone' ('one drone per
    landmark') unless phrased as a total ('with one drone')."""
    low = text.lower()
    counts = [
        _num(m.group(1))
        for m in _UAV_COUNT.finditer(low)
        if not _NEGATED.search(low[max(0, m.start() - 16) : m.start()])
    ]
    counts = [c for c in counts if c > 1]
    if counts:
        return max(counts)
    return 1 if _TOTAL_ONE.search(low) else None


def stated_role_counts(text: str, task: str) -> dict[str, int]:
    low = text.lower()
    out: dict[str, int] = {}
    for noun, role in _role_nouns(task).items():
        for m in re.finditer(rf"\b{_NUM}\s+(?:[a-z-]+\s+)?(?:{noun})\b", low):
            out[role] = max(out.get(role, 0), _num(m.group(1)))
    return out


def parse_region(text: str) -> dict[str, Any] | None:
    """A region dict (unvalidated) from the usual phrasings, or None."""
    low = text.lower()
    a = ARENA_HALF_M
    if m := _CIRCLE.search(low):
        r, n1, e1, n2, e2, centre = m.groups()
        n, e = (n1, e1) if n1 is not None else (n2, e2)
        north, east = (0.0, 0.0) if centre else (float(n), float(e))
        return {"kind": "circle", "north_m": north, "east_m": east, "radius_m": float(r)}
    if m := _RADIUS_AROUND.search(low):
        r, n, e, centre = m.groups()
        north, east = (0.0, 0.0) if centre else (float(n), float(e))
        return {"kind": "circle", "north_m": north, "east_m": east, "radius_m": float(r)}
    if m := _BOX.search(low):
        n0, n1, e0, e1 = (float(x) for x in m.groups())
        return {
            "kind": "box",
            "north_min_m": min(n0, n1),
            "north_max_m": max(n0, n1),
            "east_min_m": min(e0, e1),
            "east_max_m": max(e0, e1),
        }
    if m := _QUADRANT.search(low):
        ns, ew = m.groups()
        n_lo, n_hi = (0.0, a) if ns == "north" else (-a, 0.0)
        e_lo, e_hi = (0.0, a) if ew == "east" else (-a, 0.0)
        return {
            "kind": "box",
            "north_min_m": n_lo,
            "north_max_m": n_hi,
            "east_min_m": e_lo,
            "east_max_m": e_hi,
        }
    if m := _HALF.search(low):
        side = m.group(1)
        box = {"north_min_m": -a, "north_max_m": a, "east_min_m": -a, "east_max_m": a}
        key = {
            "north": "north_min_m",
            "south": "north_max_m",
            "east": "east_min_m",
            "west": "east_max_m",
        }[side]
        box[key] = 0.0
        return {"kind": "box", **box}
    return None


def parse_constraints(text: str) -> tuple[str, ...]:
    """Sentences or clauses carrying a constraint cue (avoid, keep, never, at least ...)."""
    out: list[str] = []
    for sentence in re.split(r"(?<=[.!?;])\s+", text.strip()):
        s = sentence.strip().rstrip(".;!")
        if s and _CONSTRAINT_CUE.search(s.lower()):
            out.append(s[:300])
    return tuple(dict.fromkeys(out))


def _pick_uavs(text: str, task: str, roster: Sequence[str], roles: Mapping[str, int]) -> list[str]:
    """Participating UAVs: named ids, else a stated count, else as many as the task uses."""
    spec = get_spec(task)
    live = sorted(roster, key=_natural)
    low = text.lower()
    named = [u for u in live if re.search(rf"\b{re.escape(u.lower())}\b", low)]
    down = sorted({m.group(0) for m in _UAV_ID.finditer(low)} - {u.lower() for u in live})
    if down:
        raise MissionParseError(
            f"the mission names {', '.join(down)} but only these are up: "
            f"{', '.join(live) or 'none'}"
        )
    if named:
        return named
    count = stated_uav_count(text)
    if count is None:
        ours = {r: n for r, n in roles.items() if r in spec.role_names}
        rest = [r for r in spec.roles if r.name not in ours]
        if ours and all(r.max_count is not None and r.max_count == r.min_count for r in rest):
            count = sum(ours.values()) + sum(r.min_count for r in rest)
        elif ours:  # the default team, but at least what the stated roles need
            need = sum(ours.values()) + sum(r.min_count for r in rest)
            if need > len(live):
                raise MissionParseError(
                    f"the stated roles {ours} need at least {need} drones but only {len(live)} "
                    f"{'is' if len(live) == 1 else 'are'} up: {', '.join(live)}"
                )
            return live[: max(need, min(spec.team_size, len(live)))]
    if count is not None:
        if count > len(live):
            n = "drone" if count == 1 else "drones"
            raise MissionParseError(
                f"asked for {count} {n} but only {len(live)} {'is' if len(live) == 1 else 'are'}"
                f" up: {', '.join(live) or 'none'}"
            )
        return live[:count]
    if len(live) < spec.min_uavs:
        raise MissionParseError(
            f"{task} needs {spec.describe_size()} but only {len(live)} "
            f"{'is' if len(live) == 1 else 'are'} up: {', '.join(live) or 'none'}"
        )
    return live[: spec.team_size]  # no number stated: the task's default team, if up


def parse_fallback(text: str, roster: Sequence[str]) -> TaskRecord:
    """The deterministic parser; raises ``MissionParseError`` naming what is missing."""
    if not text.strip():
        raise MissionParseError("the mission text is empty")
    if not roster:
        raise MissionParseError("no UAVs are up: the roster is empty")
    guess = guess_task(text)
    task = guess.best
    if task is None:
        ranked = guess.ranked
        tied = [t for t, s in ranked if s == ranked[0][1]] if ranked else list(TASK_TYPES)
        task = match_description(text, tied).task
    if task is None:
        quoted = " ".join(text.split())
        quoted = quoted if len(quoted) <= 80 else quoted[:79] + "…"
        if ranked:
            raise MissionParseError(
                f"task type is ambiguous in {quoted!r}: it reads as {' and '.join(tied)} "
                f"equally; say which task is meant"
            )
        raise MissionParseError(
            f"no task type recognised in {quoted!r}; known tasks: {', '.join(TASK_TYPES)}"
        )
    roles = stated_role_counts(text, task)
    uavs = _pick_uavs(text, task, roster, roles)
    data = {
        "task": task,
        "uavs": uavs,
        "role_counts": roles,
        "region": parse_region(text),
        "constraints": parse_constraints(text),
        "text": text,
    }
    try:
        return TaskRecord.model_validate(data, context={"roster": list(roster)})
    except ValidationError as e:
        why = validation_summary(e)
        raise MissionParseError(f"{task} mission is not feasible: {why}") from None


# --------------------------------------------------------------------------- LLM


def _task_lines() -> str:
    lines = []
    for spec in specs().values():
        roles = ", ".join(
            f"{r.name} ({r.min_count}..{'n' if r.max_count is None else r.max_count})"
            for r in spec.roles
        )
        scripted = (
            f"; played by the environment: {', '.join(spec.scripted_names)}"
            if spec.scripted
            else ""
        )
        lines.append(f"- {spec.name}: {spec.summary}. Our roles: {roles}{scripted}.")
    return "\n".join(lines)


def _team_sizes() -> str:
    return ", ".join(f"{s.name} {s.team_size}" for s in specs().values())


def parse_messages(text: str, roster: Sequence[str]) -> list[dict[str, str]]:
    schema = json.dumps(TaskRecord.llm_schema(roster), separators=(",", ":"))
    system = (
        "You are the mission parser of a UAV swarm Commander. Read the operator's mission and "
        "answer with exactly one JSON object that matches the JSON Schema below, and nothing "
        "else.\n\nTask types:\n"
        f"{_task_lines()}\n\n"
        f"Live UAVs: {', '.join(sorted(roster, key=_natural)) or 'none'}.\n"
        "Rules: choose 'uavs' from the live UAVs only; if the mission names no number, use the "
        f"task's default team size ({_team_sizes()}) or all live UAVs if fewer. Fill "
        "'role_counts' only with counts the mission states. 'region' is optional: a circle "
        "{kind: circle, north_m, east_m, radius_m} or a box {kind: box, north_min_m, "
        "north_max_m, east_min_m, east_max_m} in metres, arena "
        f"north/east within ±{ARENA_HALF_M:g} m of the centre (0, 0). 'constraints' are short "
        "phrases copied from the mission (safety, spacing, limits); ignore unrelated chatter.\n\n"
        f"JSON Schema: {schema}"
    )
    return [{"role": "system", "content": system}, {"role": "user", "content": text}]


async def parse_with_llm(
    text: str, roster: Sequence[str], client: ChatClient
) -> tuple[TaskRecord | None, JsonAnswer, str | None]:
    """(record or None, the exchange, why it was rejected)."""
    answer = await ask_json(
        client,
        parse_messages(text, roster),
        TaskRecord.llm_schema(roster),
        name="task_record",
        purpose="mission_parse",
        max_tokens=PARSE_MAX_TOKENS,
    )
    if answer.data is None:
        return None, answer, answer.error
    try:
        record = TaskRecord.model_validate(
            {**answer.data, "text": text}, context={"roster": list(roster)}
        )
    except ValidationError as e:
        return None, answer, f"invalid task record: {validation_summary(e)}"
    return record, answer, None


def _contradiction(record: TaskRecord, text: str) -> str | None:
    """Where the LLM's record disagrees with what the rules read unambiguously."""
    guess = guess_task(text)
    if guess.confident and guess.best is not None and guess.best != record.task:
        said = ", ".join(repr(p) for p in guess.matched[guess.best][:2])
        return f"LLM said task {record.task!r} but the text clearly names {guess.best} ({said})"
    stated = stated_uav_count(text)
    if stated is not None and stated != len(record.uavs):
        return f"LLM chose {len(record.uavs)} UAVs but the text asks for {stated}"
    return None


@dataclass(frozen=True)
class ParseOutcome:
    record: TaskRecord
    source: ParseSource
    tokens: int = 0
    notes: tuple[str, ...] = ()
    endpoint_failed: bool = False  # the LLM endpoint itself failed during parsing
    llm_error: str | None = field(default=None)


async def parse_mission(
    text: str, roster: Sequence[str], client: ChatClient | None = None
) -> ParseOutcome:
    """LLM when a client is given, else (or on any LLM problem) the rules. The text is
    checked first (``mission_text``: UTF-8, no control characters, at most 8 KiB)."""
    text = check_mission_text(text)
    if client is None:
        return ParseOutcome(
            parse_fallback(text, roster),
            "fallback",
            notes=("mission parse: no LLM client; used the rule-based parser",),
        )
    if not roster:
        raise MissionParseError("no UAVs are up: the roster is empty")
    record, answer, why = await parse_with_llm(text, roster, client)
    if record is not None:
        why = _contradiction(record, text)
        if why is None:
            return ParseOutcome(record, "llm", answer.tokens, answer.notes)
    note = f"mission parse: LLM answer rejected ({why}); used the rule-based parser"
    try:
        fallback = parse_fallback(text, roster)
    except MissionParseError as e:
        raise MissionParseError(f"{e} (the LLM did not help either: {why})") from None
    return ParseOutcome(
        fallback,
        "fallback",
        answer.tokens,
        (*answer.notes, note),
        endpoint_failed=answer.endpoint_failed,
        llm_error=why,
    )


__all__ = [
    "DescriptionMatch",
    "JsonAnswer",
    "MissionParseError",
    "ParseOutcome",
    "TaskGuess",
    "ask_json",
    "first_json_object",
    "guess_task",
    "match_description",
    "parse_constraints",
    "parse_fallback",
    "parse_messages",
    "parse_mission",
    "parse_region",
    "parse_with_llm",
    "stated_role_counts",
    "stated_uav_count",
]
