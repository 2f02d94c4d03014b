"""The run config's reference page, docs/config.md, generated from the pydantic models.

Every leaf setting of `RunConfig` (a field that is not itself a section) carries a
`Field(description=...)`; this module walks the models and writes one section per top-level
section, with a table per model: dotted key, type (with its bounds), default, description. The
output depends only on the models, so a test compares the committed page with it.

Regenerate the page after changing a setting:

    $ hcgym config reference --output docs/config.md

Example:
    >>> "| `trainer.max_steps` |" in render_reference()
    True
"""

from __future__ import annotations

import inspect
import json
import types
import typing
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal, NamedTuple, Union

import annotated_types
from pydantic import BaseModel
from pydantic.fields import FieldInfo

#: Where the page lives, relative to the repository root.
REFERENCE_PAGE = Path("docs/config.md")
REGENERATE = "hcgym config reference --output docs/config.md"


class Setting(NamedTuple):
    """One leaf setting: its dotted key, the model that declares it and its field."""

    key: str
    model: type[BaseModel]
    field: FieldInfo


def _section_model(annotation: Any) -> type[BaseModel] | None:
    """The pydantic model a field holds (`Model` or `Model | None`), else None (a leaf)."""
    union = typing.get_origin(annotation) in (Union, types.UnionType)
    for candidate in typing.get_args(annotation) if union else (annotation,):
        if isinstance(candidate, type) and issubclass(candidate, BaseModel):
            return candidate
    return None


def sections(model: type[BaseModel], prefix: str = "") -> Iterator[tuple[str, type[BaseModel]]]:
    """(dotted prefix, model) of `model` and of every section below it, depth first in field order."""
    yield prefix, model
    for name, field in model.model_fields.items():
        sub = _section_model(field.annotation)
        if sub is not None:
            yield from sections(sub, f"{prefix}{name}.")


def leaf_settings(model: type[BaseModel] | None = None) -> list[Setting]:
    """Every leaf setting of `model` (default: `RunConfig`), in page order."""
    if model is None:
        from learner.config import RunConfig

        model = RunConfig
    return [Setting(prefix + name, owner, field)
            for prefix, owner in sections(model)
            for name, field in owner.model_fields.items() if _section_model(field.annotation) is None]


def undocumented(model: type[BaseModel] | None = None) -> list[str]:
    """`dotted.key (ModelName in module)` of every leaf setting without a description."""
    return [f"{s.key} ({s.model.__name__} in {_public_module(s.model)})"
            for s in leaf_settings(model) if not (s.field.description or "").strip()]


def format_type(annotation: Any) -> str:
    """A field annotation as the page writes it: `int | null`, `"tiny" | "pretrained"`, `dict[str, float]`."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if annotation is type(None):
        return "null"
    if annotation is Any:
        return "any"
    if origin in (Union, types.UnionType):
        return " | ".join(format_type(a) for a in args)
    if origin is Literal:
        return " | ".join(json.dumps(v) for v in args)
    if origin is typing.Annotated:
        return format_type(args[0]) + _bounds(args[1:])
    if origin is not None:
        name = getattr(origin, "__name__", str(origin))
        return f"{name}[{', '.join(format_type(a) for a in args)}]"
    return getattr(annotation, "__name__", str(annotation))


def _bounds(metadata: Any) -> str:
    """` >= 1, <= 2`-style bounds of a field's or an Annotated type's metadata ('' when none)."""
    marks = []
    for item in metadata:
        for attr, sign in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<"), ("min_length", "length >=")):
            value = getattr(item, attr, None)
            if value is not None and isinstance(item, (annotated_types.BaseMetadata, annotated_types.GroupedMetadata)):
                marks.append(f"{sign} {value}")
    return f" ({', '.join(marks)})" if marks else ""


def format_default(field: FieldInfo) -> str:
    """The field's default as YAML would write it (null, true, 0.001, "text", [..], {})."""
    if field.is_required():
        return "(required)"
    value = field.get_default(call_default_factory=True)
    if isinstance(value, BaseModel):
        value = value.model_dump(mode="json")
    return json.dumps(value, default=list, ensure_ascii=False)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _code(text: str) -> str:
    return f"`{_cell(text)}`"


def _summary(model: type[BaseModel]) -> str:
    """The first paragraph of the model's own docstring, on one line ('' when it has none)."""
    doc = model.__dict__.get("__doc__")
    if not doc:
        return ""
    return " ".join(inspect.cleandoc(doc).split("\n\n")[0].split())


def _public_module(model: type[BaseModel]) -> str:
    """Where to import the model from: `learner.config` for the sections its package defines."""
    return "learner.config" if model.__module__.startswith("learner.config.") else model.__module__


def _table(prefix: str, model: type[BaseModel]) -> list[str]:
    rows = [(name, field) for name, field in model.model_fields.items() if _section_model(field.annotation) is None]
    if not rows:
        return []
    lines = ["| key | type | default | description |", "|---|---|---|---|"]
    for name, field in rows:
        kind = format_type(field.annotation) + _bounds(field.metadata)
        lines.append(f"| {_code(prefix + name)} | {_code(kind)} | {_code(format_default(field))} | "
                     f"{_cell(field.description or '')} |")
    return lines


def render_reference() -> str:
    """The text of docs/config.md: one section per top-level section of `RunConfig`, a table per model."""
    from learner.config import RunConfig

    out = ["# Run config reference", "",
           "<!-- Generated from the config models by learner/config_reference.py; do not edit. "
           f"Regenerate: `{REGENERATE}` -->", "",
           "Every setting of a run config (`hcgym train --config FILE.yaml`), generated from the pydantic models "
           "that validate it when it loads. Keys are dotted paths into the YAML; `--set key.path=value` overrides "
           "one. Unknown keys are errors. Types use YAML's words (`null`, `true`); a bound such as `(>= 1)` is "
           "checked at load. How configs are written and composed (`extends:`): [training.md](training.md).", ""]
    top = [(name, field) for name, field in RunConfig.model_fields.items()]
    out += ["## Top level", ""] + _table("", RunConfig) + [""]
    for name, field in top:
        section = _section_model(field.annotation)
        if section is None:
            continue
        out += [f"## `{name}`", ""]
        for prefix, model in sections(section, f"{name}."):
            key = prefix.rstrip(".")
            if prefix != f"{name}.":
                out += [f"### `{key}`", ""]
            summary = _summary(model)
            out += [f"{summary + ' ' if summary else ''}Model: `{_public_module(model)}.{model.__qualname__}`.", ""]
            table = _table(prefix, model)
            out += table + ([""] if table else [])
    return "\n".join(out).rstrip("\n") + "\n"


def write_reference(path: str | Path = REFERENCE_PAGE) -> Path:
    """Write the page to `path` (default docs/config.md relative to the working directory)."""
    path = Path(path)
    path.write_text(render_reference(), encoding="utf-8")
    return path


def check_reference(path: str | Path = REFERENCE_PAGE) -> list[str]:
    """Problems with the committed page: settings without a description, a missing or stale page."""
    problems = [f"{item}: no description (give the field Field(description=...))" for item in undocumented()]
    path = Path(path)
    if not path.is_file():
        problems.append(f"{path}: missing; write it with `{REGENERATE}`")
    elif path.read_text(encoding="utf-8") != render_reference():
        problems.append(f"{path}: differs from the config models; regenerate it with `{REGENERATE}`")
    return problems
