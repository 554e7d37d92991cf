"""Skill packages: load, validate and look up ``skills/<name>/{skill.md,skill.py}``.

A package is refused at start-up rather than at the first decision that needs it, because a
broken skill discovered mid-flight can only become a hold. :func:`load_skills` therefore
checks *every* package (front matter, body, executor module, parameter model, function
signatures, generated JSON Schema) and, if anything is wrong, refuses the **whole** registry
with one :class:`SkillError` listing all problems, each naming the file and the field. A
partial registry would silently change which candidates the LLM sees.

Executors are imported by file path under a unique module name, so skill directories outside
the installed ``skills`` package work the same way as the shipped ones.
"""

from __future__ import annotations

import copy
import hashlib
import importlib.util
import inspect
import json
import os
import re
import sys
import traceback
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from types import ModuleType
from typing import Annotated, Any, Literal

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StringConstraints,
    ValidationError,
    field_validator,
)

from aeroweaver_edge.contracts.actions import Intent
from aeroweaver_edge.contracts.observation import Observation
from aeroweaver_edge.contracts.skill_api import SkillContext, SkillParams

DOC_FILE = "skill.md"
DEFAULT_EXECUTOR = "skill.py"
MAX_DESCRIPTION = 1024  # Agent Skills convention

Effect = Literal["actuates", "communicates", "records", "none"]
_Name = Annotated[str, StringConstraints(pattern=r"^[a-z0-9_-]+$", min_length=1, max_length=64)]
_Word = Annotated[str, StringConstraints(strip_whitespace=True, min_length=1, max_length=64)]
_Line = Annotated[str, StringConstraints(strip_whitespace=True, min_length=1, max_length=512)]


# --------------------------------------------------------------------------- errors


@dataclass(frozen=True)
class SkillProblem:
    """One defect in one file; ``field`` is the front-matter field or code object at fault."""

    path: Path
    message: str
    field: str | None = None
    line: int | None = None
    display: str = ""  # path as shown to people (relative to the skills root's parent)

    def __str__(self) -> str:
        where = self.display or str(self.path)
        if self.line is not None:
            where += f": line {self.line}"
        if self.field is not None:
            where += f": front matter field '{self.field}'"
        return f"{where}: {self.message}"


class SkillError(Exception):
    """A skill package is broken (or an executor broke its contract at run time)."""

    def __init__(self, problems: Sequence[SkillProblem], header: str = "") -> None:
        self.problems = tuple(problems)
        self.header = header
        super().__init__(str(self))

    def __str__(self) -> str:
        lines = [str(p) for p in self.problems]
        if not self.header and len(lines) == 1:
            return lines[0]
        return "\n  ".join([self.header or "skill problems:", *lines])

    def explain(self) -> tuple[int, str]:
        first = str(self.problems[0]) if self.problems else str(self)
        more = f" (and {len(self.problems) - 1} more problems)" if len(self.problems) > 1 else ""
        return 2, (
            f"broken skill package: {first}{more}; fix that file, or point "
            "AEROWEAVER_SKILLS_DIR at a valid skills directory"
        )


class SkillParamError(ValueError):
    """Parameters for a skill are invalid (unknown key, wrong type, non-finite, too long)."""

    def __init__(self, skill: str, errors: Sequence[str]) -> None:
        self.skill = skill
        self.errors = tuple(errors)
        super().__init__(f"{skill}: invalid parameters: " + "; ".join(errors))


# --------------------------------------------------------------------------- front matter


class SkillDoc(BaseModel):
    """The YAML front matter of ``skill.md``: Agent Skills fields plus the paper's."""

    model_config = ConfigDict(extra="forbid", frozen=True, str_strip_whitespace=True)

    name: _Name
    description: str = Field(min_length=1, max_length=MAX_DESCRIPTION)
    tags: tuple[_Word, ...] = ()
    aliases: tuple[_Word, ...] = ()
    inputs: dict[str, _Line] | tuple[_Line, ...] = Field(default_factory=dict)
    """Informational; when a mapping, its keys must be exactly the ``Params`` fields."""
    outputs: dict[str, _Line] | tuple[_Line, ...] = Field(default_factory=dict)
    conditions: tuple[_Line, ...] = ()
    executor: str = DEFAULT_EXECUTOR
    provenance: str = Field(default="", max_length=MAX_DESCRIPTION)
    dependencies: tuple[_Word, ...] = ()
    effects: tuple[Effect, ...] = Field(min_length=1)

    @field_validator("executor")
    @classmethod
    def _executor_inside_package(cls, v: str) -> str:
        p = PurePosixPath(v)
        if p.is_absolute() or ".." in p.parts or "\\" in v or p.suffix != ".py":
            raise ValueError("must be a relative path to a .py file inside the package")
        return v

    @field_validator("effects")
    @classmethod
    def _effects_consistent(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        if len(set(v)) != len(v):
            raise ValueError("duplicate effect")
        if "none" in v and len(v) > 1:
            raise ValueError("'none' cannot be combined with other effects")
        return v


# --------------------------------------------------------------------------- skills

OptionsFn = Callable[[Observation, SkillContext], Sequence[SkillParams]]
ExecuteFn = Callable[[Any, Observation, SkillContext], Intent]


@dataclass(frozen=True)
class SkillDocument:
    """What retrieval ranks a skill by (DESIGN §7: names, descriptions, tags, aliases)."""

    name: str
    description: str
    tags: tuple[str, ...]
    aliases: tuple[str, ...]
    body: str


@dataclass(frozen=True, eq=False)
class Skill:
    """A validated skill package: its document, its parameter model and its executor."""

    doc: SkillDoc
    body: str
    params: type[SkillParams]
    path: Path  # the package folder
    _options: OptionsFn
    _execute: ExecuteFn
    _schema: dict[str, Any]

    @property
    def name(self) -> str:
        return self.doc.name

    @property
    def description(self) -> str:
        return self.doc.description

    def json_schema(self) -> dict[str, Any]:
        """JSON Schema of the parameters, generated from ``Params`` (a fresh copy)."""
        return copy.deepcopy(self._schema)

    def parse_params(self, data: Mapping[str, object]) -> SkillParams:
        """Validate untrusted parameters as JSON would arrive: strict, no coercion."""
        if not isinstance(data, Mapping):
            raise SkillParamError(self.name, [f"expected an object, got {type(data).__name__}"])
        try:
            raw = json.dumps(dict(data))
        except (TypeError, ValueError) as e:
            raise SkillParamError(self.name, [f"not JSON-serialisable: {e}"]) from None
        try:
            return self.params.model_validate_json(raw, strict=True)
        except ValidationError as e:
            raise SkillParamError(self.name, _param_errors(e)) from None

    def options(self, obs: Observation, ctx: SkillContext) -> list[SkillParams]:
        """The callable parameterisations now; checks the executor kept its contract."""
        out = self._options(obs, ctx)
        if not isinstance(out, list | tuple) or not all(isinstance(p, self.params) for p in out):
            raise self._contract("options() must return a list of Params")
        return list(out)

    def execute(self, params: SkillParams, obs: Observation, ctx: SkillContext) -> Intent:
        """Run the executor; the result is an Intent for this UAV's own body only."""
        if not isinstance(params, self.params):
            raise SkillParamError(
                self.name, [f"expected {self.name} Params, got {type(params).__name__}"]
            )
        intent = self._execute(params, obs, ctx)
        if not isinstance(intent, Intent):
            raise self._contract(f"execute() returned {type(intent).__name__}, not Intent")
        return intent

    def invocation(self, params: SkillParams) -> str:
        return params.invocation(self.name)

    def prompt_text(self) -> str:
        """``name: description Parameters: ... Conditions: ...`` as the prompts render it."""
        params = "; ".join(_describe_params(self._schema)) or "none"
        conditions = "; ".join(c.rstrip(".") for c in self.doc.conditions) or "none"
        return (
            f"{self.name}: {_sentence(self.description)} "
            f"Parameters: {params}. Conditions: {conditions}."
        )

    def document(self) -> SkillDocument:
        d = self.doc
        return SkillDocument(d.name, d.description, d.tags, d.aliases, self.body)

    def _contract(self, message: str) -> SkillError:
        executor = self.path / self.doc.executor
        return SkillError([SkillProblem(executor, message, display=_display(executor))])


class SkillRegistry:
    """An immutable, ordered set of validated skills, looked up by name."""

    def __init__(self, skills: Iterable[Skill]) -> None:
        self._skills: dict[str, Skill] = {}
        for s in skills:
            if s.name in self._skills:
                raise ValueError(f"duplicate skill {s.name!r}")
            self._skills[s.name] = s

    def names(self) -> tuple[str, ...]:
        return tuple(self._skills)

    def get(self, name: str) -> Skill:
        try:
            return self._skills[name]
        except KeyError:
            raise KeyError(f"unknown skill {name!r}; known: {', '.join(self._skills)}") from None

    def subset(self, names: Iterable[str]) -> SkillRegistry:
        """The named skills, in the order given (duplicates dropped); unknown names refused."""
        wanted = list(dict.fromkeys(names))
        unknown = [n for n in wanted if n not in self._skills]
        if unknown:
            raise KeyError(f"unknown skills: {', '.join(unknown)}")
        return SkillRegistry(self._skills[n] for n in wanted)

    def documents(self) -> tuple[SkillDocument, ...]:
        return tuple(s.document() for s in self._skills.values())

    def __contains__(self, name: object) -> bool:
        return name in self._skills

    def __iter__(self) -> Iterator[Skill]:
        return iter(self._skills.values())

    def __len__(self) -> int:
        return len(self._skills)

    def __repr__(self) -> str:
        return f"SkillRegistry({list(self._skills)})"


# --------------------------------------------------------------------------- loader


SKILLS_DIR_ENV = "AEROWEAVER_SKILLS_DIR"


def default_root() -> Path:
    """``$AEROWEAVER_SKILLS_DIR`` if set, else the shipped ``skills`` package directory:
    the sibling of ``aeroweaver_edge``.

    Found by location, not by ``import skills``: that generic top-level name is easily
    shadowed (e.g. by ``tests/skills`` as a namespace package when ``tests/`` is on
    ``sys.path``, or by an unrelated distribution), and both packages ship in one wheel.
    """
    override = os.environ.get(SKILLS_DIR_ENV)
    if override:
        return Path(override)
    return Path(__file__).resolve().parent.parent / "skills"


def load_skills(root: Path | None = None) -> SkillRegistry:
    """Load and validate every package under ``root``; refuse all if any is broken.

    Every sub-directory not starting with ``_`` or ``.`` is a skill package. Raises
    :class:`SkillError` listing every problem found, each naming the file and the field.
    """
    root = (root or default_root()).resolve()
    if not root.is_dir():
        raise SkillError([SkillProblem(root, "skills directory not found", display=str(root))])
    loaded: list[Skill] = []
    problems: list[SkillProblem] = []
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        if folder.name.startswith(("_", ".")):
            continue
        skill, found = _load_package(folder, root)
        problems += found
        if skill is not None:
            loaded.append(skill)
    problems += _check_aliases(loaded, root)
    if problems:
        raise SkillError(problems, header=f"refusing skill packages under {root}:")
    return SkillRegistry(loaded)


def _load_package(folder: Path, root: Path) -> tuple[Skill | None, list[SkillProblem]]:
    doc_path = folder / DOC_FILE
    problems: list[SkillProblem] = []

    def problem(
        path: Path, message: str, field: str | None = None, line: int | None = None
    ) -> None:
        problems.append(SkillProblem(path, message, field, line, _display(path, root)))

    doc: SkillDoc | None = None
    body = ""
    raw: dict[str, Any] | None = None
    if not doc_path.is_file():
        problem(doc_path, "missing skill.md")
    else:
        raw, body, line, err = _split_front_matter(doc_path)
        if err is not None:
            problem(doc_path, err, line=line)
        if raw is not None:
            try:
                doc = SkillDoc.model_validate(raw)
            except ValidationError as e:
                for field, msg in _field_errors(e):
                    problem(doc_path, msg, field=field)
            name = raw.get("name")
            if isinstance(name, str) and name != folder.name:
                problem(doc_path, f"{name!r} must equal the folder name {folder.name!r}", "name")
        if err is None and not body:
            problem(doc_path, "empty body: the prose after the front matter is what the LLM reads")

    executor = folder / (doc.executor if doc is not None else DEFAULT_EXECUTOR)
    code = _load_executor(executor, folder.name, problem)
    if code is None or doc is None or problems:
        return None, problems
    params, options, execute, schema = code
    if isinstance(doc.inputs, dict) and set(doc.inputs) != set(params.model_fields):
        problem(
            doc_path,
            f"keys {sorted(doc.inputs)} must equal the Params fields {sorted(params.model_fields)}",
            "inputs",
        )
        return None, problems
    skill = Skill(doc, body, params, folder, options, execute, schema)
    return skill, problems


Problem = Callable[..., None]
_Code = tuple[type[SkillParams], OptionsFn, ExecuteFn, dict[str, Any]]


def _load_executor(path: Path, name: str, problem: Problem) -> _Code | None:
    """Import ``path`` under a unique module name and check the skill contract."""
    if not path.is_file():
        problem(path, "missing executor file")
        return None
    digest = hashlib.sha1(str(path).encode()).hexdigest()[:12]
    mod_name = f"aeroweaver_skill_{re.sub(r'[^a-z0-9_]', '_', name)}_{digest}"
    spec = importlib.util.spec_from_file_location(mod_name, path)
    if spec is None or spec.loader is None:
        problem(path, "cannot be imported")
        return None
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module  # pydantic and dataclasses resolve annotations through it
    try:
        spec.loader.exec_module(module)
    except (Exception, SystemExit) as e:
        sys.modules.pop(mod_name, None)
        detail = e.msg if isinstance(e, SyntaxError) else str(e)
        problem(path, f"import failed: {type(e).__name__}: {detail}", line=_error_line(e, path))
        return None

    params = _check_params(module, path, problem)
    funcs = [_check_function(module, fn, arity, path, problem) for fn, arity in _CONTRACT]
    if params is None or funcs[0] is None or funcs[1] is None:
        return None
    try:
        schema = params.model_json_schema()
    except Exception as e:
        problem(path, f"Params JSON Schema cannot be generated: {type(e).__name__}: {e}")
        return None
    schema["title"] = name
    return params, funcs[0], funcs[1], schema


def _check_params(module: ModuleType, path: Path, problem: Problem) -> type[SkillParams] | None:
    params = getattr(module, "Params", None)
    if params is None:
        problem(path, "missing class 'Params'")
        return None
    if not (isinstance(params, type) and issubclass(params, SkillParams)):
        problem(path, "Params must subclass SkillParams (aeroweaver_edge.contracts.skill_api)")
        return None
    cfg = params.model_config
    if cfg.get("extra") != "forbid" or cfg.get("allow_inf_nan") is not False:
        problem(path, "Params must keep SkillParams' extra='forbid' and allow_inf_nan=False")
        return None
    return params


_CONTRACT = (("options", ("obs", "ctx")), ("execute", ("params", "obs", "ctx")))


def _check_function(
    module: ModuleType, fn: str, args: tuple[str, ...], path: Path, problem: Problem
) -> Any:
    f = getattr(module, fn, None)
    if f is None:
        problem(path, f"missing function '{fn}'")
        return None
    if not callable(f):
        problem(path, f"'{fn}' must be a function")
        return None
    try:
        inspect.signature(f).bind(*args)
    except (TypeError, ValueError):
        problem(path, f"function '{fn}' must accept ({', '.join(args)})")
        return None
    return f


def _split_front_matter(
    path: Path,
) -> tuple[dict[str, Any] | None, str, int | None, str | None]:
    """Return (front matter, body, error line, error message)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        return None, "", None, f"cannot read: {e}"
    lines = text.splitlines()
    if not lines or lines[0].rstrip() != "---":
        return None, "", 1, "missing YAML front matter: the file must start with a '---' line"
    end = next((i for i in range(1, len(lines)) if lines[i].rstrip() == "---"), None)
    if end is None:
        return None, "", 1, "front matter is not closed by a '---' line"
    body = "\n".join(lines[end + 1 :]).strip()
    try:
        data = yaml.load("\n".join(lines[1:end]), Loader=_StrictLoader)
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        line = mark.line + 2 if mark is not None else None  # +1 for '---', +1 for 1-based
        return None, body, line, f"YAML syntax error: {e.problem or e}"
    except yaml.YAMLError as e:
        return None, body, None, f"YAML error: {e}"
    if not isinstance(data, dict):
        return None, body, 2, "front matter must be a YAML mapping"
    return data, body, None, None


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that refuses duplicate keys (PyYAML silently keeps the last one)."""


def _no_duplicates(loader: yaml.SafeLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    seen: set[Any] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r}", key_node.start_mark
            )
        seen.add(key)
    return loader.construct_mapping(node)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _no_duplicates)


def _check_aliases(skills: Sequence[Skill], root: Path) -> list[SkillProblem]:
    """Aliases feed retrieval; one that shadows another skill's name or alias is ambiguous."""
    owner: dict[str, str] = {s.name: s.name for s in skills}
    out: list[SkillProblem] = []
    for s in skills:
        for alias in s.doc.aliases:
            other = owner.setdefault(alias, s.name)
            if other != s.name:
                path = s.path / DOC_FILE
                msg = f"alias {alias!r} is already used by skill {other!r}"
                out.append(SkillProblem(path, msg, "aliases", display=_display(path, root)))
    return out


# --------------------------------------------------------------------------- helpers


def _display(path: Path, root: Path | None = None) -> str:
    """``<root name>/<package>/<file>``: short, and still says which file."""
    base = (root or path.parent.parent).parent
    try:
        return path.relative_to(base).as_posix()
    except ValueError:
        return str(path)


def _field_errors(e: ValidationError) -> list[tuple[str, str]]:
    """(field, message) pairs; item indices kept, union-branch names dropped."""
    out: dict[tuple[str, str], None] = {}
    errors = e.errors()
    item_errors = {str(err["loc"][0]) for err in errors if len(err["loc"]) > 1}
    for err in errors:
        loc = err["loc"]
        field = str(loc[0]) if loc else "<root>"
        if err["type"] == "too_short" and field in item_errors:
            continue  # a bad item also empties the tuple; the item error says why
        index = "".join(f"[{x}]" for x in loc[1:] if isinstance(x, int))
        msg = "unknown field" if err["type"] == "extra_forbidden" else err["msg"]
        out[(field, f"{index + ' ' if index else ''}{msg}")] = None
    return list(out)


def _param_errors(e: ValidationError) -> list[str]:
    out = []
    for err in e.errors():
        loc = ".".join(str(x) for x in err["loc"]) or "<params>"
        msg = "unknown parameter" if err["type"] == "extra_forbidden" else err["msg"]
        out.append(f"parameter '{loc}': {msg}")
    return out


def _error_line(e: BaseException, path: Path) -> int | None:
    """Line in ``path`` where an import-time exception was raised (deepest frame there)."""
    if isinstance(e, SyntaxError) and e.filename and Path(e.filename) == path:
        return e.lineno
    frames = [f for f in traceback.extract_tb(e.__traceback__) if Path(f.filename) == path]
    return frames[-1].lineno if frames else None


def _describe_params(schema: Mapping[str, Any]) -> list[str]:
    required = set(schema.get("required", ()))
    out = []
    for name, prop in schema.get("properties", {}).items():
        kind = prop.get("type", "value")
        extra = [] if name in required else ["optional"]
        if "enum" in prop:
            extra.append("one of " + ", ".join(map(str, prop["enum"])))
        if "minimum" in prop or "maximum" in prop:
            extra.append(f"{prop.get('minimum', '')}..{prop.get('maximum', '')}")
        head = f"{name} ({', '.join([kind, *extra])})"
        out.append(f"{head}: {prop['description']}" if "description" in prop else head)
    return out


def _sentence(text: str) -> str:
    text = " ".join(text.split())
    return text if text.endswith((".", "!", "?")) else text + "."


__all__ = [
    "Effect",
    "Skill",
    "SkillDoc",
    "SkillDocument",
    "SkillError",
    "SkillParamError",
    "SkillProblem",
    "SkillRegistry",
    "default_root",
    "load_skills",
]
