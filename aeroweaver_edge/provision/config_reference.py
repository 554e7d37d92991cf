"""The configuration reference, generated from the config schema itself.

Every section and key of ``uav.toml`` (``config.UavConfig``), with its type, its bounds, its
default and the comment ``keys init`` writes beside it (``daemon_toml.COMMENTS``), as the
Markdown tables of docs/configuration.md. The page holds the tables between two markers;
``tests/docs/test_configuration_reference.py`` fails when they differ from what this module
renders, so a key added, renamed or re-bounded in ``config.py`` cannot go undocumented.

    python -m aeroweaver_edge.provision.config_reference docs/configuration.md          # rewrite
    python -m aeroweaver_edge.provision.config_reference --check docs/configuration.md  # compare
"""

from __future__ import annotations

import argparse
import json
import sys
import types
from pathlib import Path
from typing import Any, Final, Literal, Union, get_args, get_origin

from annotated_types import Ge, Gt, Le, Lt, MaxLen, MinLen
from pydantic import BaseModel
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

from aeroweaver_edge.config import UavConfig
from aeroweaver_edge.provision.daemon_toml import COMMENTS, toml_value

BEGIN: Final = "<!-- reference: generated from config.UavConfig; do not edit by hand -->"
END: Final = "<!-- end of the generated reference -->"


def _type(annotation: Any) -> str:
    """A type as a reader of a TOML file thinks of it."""
    origin = get_origin(annotation)
    args = get_args(annotation)
    if origin is Literal:
        return " or ".join(f"`{json.dumps(a)}`" for a in args)
    if origin in (Union, types.UnionType):
        parts = [_type(a) for a in args if a is not type(None)]
        text = " or ".join(parts)
        return f"{text} (optional)" if type(None) in args else text
    if origin in (list, tuple):
        inner = [a for a in args if a is not Ellipsis]
        if origin is tuple and len(inner) > 1:
            return f"[{', '.join(_type(a) for a in inner)}]"
        return f"list of {_type(inner[0])}" if inner else "list"
    if origin is dict:
        return "table"
    if get_origin(annotation) is not None and hasattr(annotation, "__metadata__"):
        return _type(args[0])
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return f"table ({annotation.__name__})"
    name = getattr(annotation, "__name__", str(annotation))
    return {"float": "number", "int": "integer", "str": "string", "bool": "boolean"}.get(name, name)


def _bounds(info: FieldInfo) -> str:
    parts: list[str] = []
    for m in info.metadata:
        if isinstance(m, Gt):
            parts.append(f"> {m.gt:g}")
        elif isinstance(m, Ge):
            parts.append(f">= {m.ge:g}")
        elif isinstance(m, Lt):
            parts.append(f"< {m.lt:g}")
        elif isinstance(m, Le):
            parts.append(f"<= {m.le:g}")
        elif isinstance(m, MinLen):
            parts.append(f"at least {m.min_length} long")
        elif isinstance(m, MaxLen):
            parts.append(f"at most {m.max_length} long")
    return ", ".join(parts)


def _default(info: FieldInfo) -> str:
    if info.is_required():
        return "required"
    value = info.get_default(call_default_factory=True)
    if value is None:
        return "unset"
    if value is PydanticUndefined:
        return ""
    if isinstance(value, BaseModel):
        return "(section)"
    return f"`{toml_value(value)}`"


def _escape(text: str) -> str:
    """Text for a Markdown table cell: no pipe, no newline, no HTML tag."""
    return text.replace("|", "\\|").replace("\n", " ").replace("<", "&lt;").replace(">", "&gt;")


def _section(model: type[BaseModel], path: str, out: list[str]) -> None:
    """One table for ``model`` (``path``: ``mesh``, ``mesh.security``, ``""`` for the top),
    then one per nested section."""
    title = (f"[[{path[:-2]}]]" if path.endswith("[]") else f"[{path}]") if path else ""
    doc = (model.__doc__ or "").strip().split("\n\n")[0]
    out += [f"### `{title}`" if path else "### Top level", ""]
    if doc and path:
        out += [_escape(" ".join(doc.split()).replace("``", "`")), ""]
    out += ["| key | type | bounds | default | what |", "|---|---|---|---|---|"]
    nested: list[tuple[str, type[BaseModel]]] = []
    for name, info in model.model_fields.items():
        key = f"{path}.{name}" if path else name
        annotation = info.annotation
        sub = [a for a in (annotation, *get_args(annotation)) if isinstance(a, type)]
        section = next((a for a in sub if issubclass(a, BaseModel)), None)
        if section is not None and get_origin(annotation) is not list:
            nested.append((key, section))
            continue
        if section is not None:  # a list of tables: its own table, [[key]]
            nested.append((f"{key}[]", section))
        comment = COMMENTS.get(key, ("", ""))[0]
        out.append(
            f"| `{name}` | {_escape(_type(annotation))} | {_bounds(info)} | "
            f"{_escape(_default(info))} | {_escape(comment)} |"
        )
    out.append("")
    for key, section in nested:
        _section(section, key, out)


def render() -> str:
    """The generated block, markers included."""
    out = [BEGIN, ""]
    _section(UavConfig, "", out)
    return "\n".join([*out, END])


def replace_block(page: str, block: str) -> str:
    """``page`` with its generated block replaced (``ValueError``: no markers)."""
    start, end = page.find(BEGIN), page.find(END)
    if start < 0 or end < start:
        raise ValueError(f"no generated block: the page needs {BEGIN!r} ... {END!r}")
    return page[:start] + block + page[end + len(END) :]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m aeroweaver_edge.provision.config_reference")
    p.add_argument("page", type=Path, help="the Markdown page holding the generated block")
    p.add_argument("--check", action="store_true", help="compare only; exit 1 when stale")
    args = p.parse_args(argv)
    try:
        page = args.page.read_text(encoding="utf-8")
        new = replace_block(page, render())
    except (OSError, ValueError) as exc:
        print(f"config_reference: {args.page}: {exc}", file=sys.stderr)
        return 2
    if args.check:
        if new != page:
            print(f"{args.page}: the configuration reference is stale; rerun without --check")
            return 1
        return 0
    if new != page:
        args.page.write_text(new, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["BEGIN", "END", "main", "render", "replace_block"]
