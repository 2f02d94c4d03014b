"""Tools: a decorator, OpenAI schemas from signatures and Google-style docstrings, toolkits.

A tool is a toolkit method marked with :func:`is_tool`. Its signature (with type hints) and
docstring are the single source of truth: they give the OpenAI function schema the agent sees
and the pydantic model that validates the agent's arguments before the method runs.

Example:
    >>> class Demo(Toolkit):
    ...     @is_tool(ToolType.READ)
    ...     def add(self, a: int, b: int = 2) -> int:
    ...         '''Add two integers.
    ...
    ...         Args:
    ...             a: The first number.
    ...             b: The second number.
    ...         '''
    ...         return a + b
    >>> Demo().call("add", {"a": "3"}).result
    5
"""

from __future__ import annotations

import copy
import difflib
import inspect
import json
import re
import typing
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Callable, ClassVar

from pydantic import BaseModel, ConfigDict, ValidationError, create_model

from envs.core.trajectory import ErrorKind


class ToolType(StrEnum):
    """What a tool does to the world; WRITE tools may change the domain database."""

    READ = "read"
    WRITE = "write"
    THINK = "think"
    GENERIC = "generic"


class ToolError(Exception):
    """Raised by a tool for a clinical or lookup failure the agent should read (not a crash)."""


def is_tool(tool_type: ToolType = ToolType.READ, *, name: str | None = None, submit: bool = False):
    """Mark a toolkit method as an agent tool.

    Args:
        tool_type: READ, WRITE, THINK or GENERIC.
        name: Tool name shown to the agent; defaults to the method name.
        submit: True for the tool that ends the episode with the agent's answer.
    """

    def mark(fn: Callable) -> Callable:
        fn.__tool_type__ = ToolType(tool_type)
        fn.__tool_name__ = name or fn.__name__
        fn.__tool_submit__ = submit
        return fn

    return mark


_SECTION = re.compile(r"^\s*(Args|Arguments|Parameters|Returns|Return|Raises|Yields|Example|Examples|Note|Notes):\s*$")
_ARG_LINE = re.compile(r"^\s*(\*{0,2}[A-Za-z_][A-Za-z0-9_]*)\s*(?:\(([^)]*)\))?\s*:\s*(.*)$")


def parse_google_docstring(doc: str | None) -> tuple[str, dict[str, str]]:
    """Split a Google-style docstring into (description, {argument: description})."""
    if not doc:
        return "", {}
    lines = inspect.cleandoc(doc).splitlines()
    description: list[str] = []
    args: dict[str, str] = {}
    section: str | None = None
    current: str | None = None
    arg_indent: int | None = None
    for line in lines:
        header = _SECTION.match(line)
        if header:
            section = header.group(1)
            current, arg_indent = None, None
            continue
        if section is None:
            description.append(line)
        elif section in ("Args", "Arguments", "Parameters"):
            if not line.strip():
                continue
            indent = len(line) - len(line.lstrip())
            match = _ARG_LINE.match(line)
            if match and (arg_indent is None or indent <= arg_indent):
                arg_indent = indent
                current = match.group(1).lstrip("*")
                args[current] = match.group(3).strip()
            elif current is not None:
                args[current] = (args[current] + " " + line.strip()).strip()
    text = " ".join(part.strip() for part in "\n".join(description).strip().split("\n\n")[0].splitlines())
    return text.strip(), args


def _clean_schema(schema: dict, defs: dict) -> dict:
    """Inline $refs, drop pydantic titles, and turn Optional[X] into X (not required)."""
    if "$ref" in schema:
        schema = {**defs[schema["$ref"].split("/")[-1]], **{k: v for k, v in schema.items() if k != "$ref"}}
    out: dict[str, Any] = {}
    for key, value in schema.items():
        if key in ("title", "$defs"):
            continue
        if key == "anyOf":
            options = [_clean_schema(v, defs) for v in value if v.get("type") != "null"]
            if len(options) == 1:
                out.update(options[0])
            else:
                out["anyOf"] = options
            continue
        if isinstance(value, dict):
            out[key] = _clean_schema(value, defs) if key != "properties" else {
                name: _clean_schema(sub, defs) for name, sub in value.items()
            }
        elif isinstance(value, list) and key in ("items", "prefixItems", "allOf", "oneOf"):
            out[key] = [_clean_schema(v, defs) if isinstance(v, dict) else v for v in value]
        else:
            out[key] = value
    if "default" in out and out["default"] is None:
        del out["default"]
    return out


def safe_repr(value: Any, limit: int = 60) -> str:
    """repr for error messages that cannot itself fail: repr of an int over 4,300 digits raises
    ValueError, and a deeply nested value RecursionError."""
    try:
        text = repr(value)
    except (ValueError, RecursionError):
        text = f"<{type(value).__name__} too large to show>"
    return text if len(text) <= limit else text[:limit] + "..."


def _type_label(annotation: Any) -> str:
    """A short human label for an annotation, used in argument error messages."""
    origin = typing.get_origin(annotation)
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in typing.get_args(annotation))
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        return " or ".join(_type_label(a) for a in typing.get_args(annotation) if a is not type(None))
    if origin in (list, tuple, set):
        inner = typing.get_args(annotation)
        return f"list of {_type_label(inner[0])}" if inner else "list"
    if origin is dict:
        return "object"
    return {str: "string", int: "integer", float: "number", bool: "boolean", dict: "object", list: "list"}.get(
        annotation, getattr(annotation, "__name__", str(annotation))
    )


@dataclass(frozen=True)
class ToolDefinition:
    """One tool: its name, type, description, argument model and OpenAI schema."""

    name: str
    tool_type: ToolType
    description: str
    args_model: type[BaseModel]
    parameters: dict
    attribute: str
    submit: bool = False
    arg_types: dict[str, str] = field(default_factory=dict)

    @classmethod
    def from_function(cls, fn: Callable, *, name: str | None = None, tool_type: ToolType | None = None) -> "ToolDefinition":
        """Build the definition from a function's signature and Google-style docstring."""
        tool_name = name or getattr(fn, "__tool_name__", fn.__name__)
        description, arg_docs = parse_google_docstring(fn.__doc__)
        if not description:
            raise TypeError(f"tool {tool_name!r}: the docstring's first line (its description) is missing")
        hints = typing.get_type_hints(fn, include_extras=True)
        fields: dict[str, Any] = {}
        arg_types: dict[str, str] = {}
        for pname, param in inspect.signature(fn).parameters.items():
            if pname == "self" or param.kind in (param.VAR_POSITIONAL, param.VAR_KEYWORD):
                continue
            if pname not in hints:
                raise TypeError(f"tool {tool_name!r}: argument {pname!r} has no type annotation")
            annotation = hints[pname]
            default = ... if param.default is inspect.Parameter.empty else param.default
            from pydantic import Field

            fields[pname] = (annotation, Field(default, description=arg_docs.get(pname) or None))
            arg_types[pname] = _type_label(annotation)
        model = create_model(  # type: ignore[call-overload]
            f"{tool_name}_arguments", __config__=ConfigDict(extra="forbid"), **fields
        )
        raw = model.model_json_schema()
        params = _clean_schema(raw, raw.get("$defs", {}))
        params.setdefault("properties", {})
        params.setdefault("required", [])
        params["type"] = "object"
        params.pop("additionalProperties", None)
        return cls(
            name=tool_name,
            tool_type=ToolType(tool_type or getattr(fn, "__tool_type__", ToolType.READ)),
            description=description,
            args_model=model,
            parameters=params,
            attribute=fn.__name__,
            submit=bool(getattr(fn, "__tool_submit__", False)),
            arg_types=arg_types,
        )

    def openai_schema(self) -> dict:
        """The OpenAI function-calling schema (`{"type": "function", "function": {...}}`)."""
        return {
            "type": "function",
            "function": {"name": self.name, "description": self.description, "parameters": self.parameters},
        }

    def validate(self, arguments: Any) -> dict:
        """Validate arguments; raise ToolArgumentError naming each bad argument and its type."""
        if not isinstance(arguments, dict):
            raise ToolArgumentError(
                f"tool {self.name!r}: arguments must be a JSON object of name -> value, got {type(arguments).__name__}"
            )
        try:
            validated = self.args_model.model_validate(arguments)
        except ValidationError as exc:
            raise ToolArgumentError(self._explain(exc)) from None
        return {k: getattr(validated, k) for k in self.args_model.model_fields}

    def _explain(self, exc: ValidationError) -> str:
        problems = []
        for err in exc.errors():
            arg = str(err["loc"][0]) if err["loc"] else "?"
            where = ".".join(str(p) for p in err["loc"])
            if err["type"] == "missing":
                problems.append(f"missing required argument {arg!r} ({self.arg_types.get(arg, '?')})")
            elif err["type"] == "extra_forbidden":
                near = difflib.get_close_matches(arg, list(self.arg_types), n=1)
                hint = f"; did you mean {near[0]!r}?" if near else ""
                problems.append(f"unknown argument {arg!r}{hint} (accepted: {', '.join(self.arg_types) or 'none'})")
            else:
                got = err.get("input")
                got_repr = safe_repr(got)
                expected = self.arg_types.get(arg, "?")
                problems.append(f"argument {where!r} expects {expected}, got {got_repr}: {err['msg']}")
        return f"tool {self.name!r}: " + "; ".join(problems)


class ToolArgumentError(ValueError):
    """The agent's arguments do not fit the tool's signature."""


class UnknownToolError(LookupError):
    """The agent named a tool that does not exist."""


@dataclass
class ToolOutcome:
    """The result of one tool call as the environment records it."""

    name: str
    arguments: dict
    result: Any = None
    error: str | None = None
    tool_type: ToolType | None = None
    submit: bool = False
    error_kind: ErrorKind | None = None  # what kind of failure `error` is (see envs.core.trajectory)

    @property
    def ok(self) -> bool:
        return self.error is None

    def as_text(self) -> str:
        """The observation text the agent receives for this call."""
        if self.error is not None:
            return json.dumps({"error": self.error}, ensure_ascii=False)
        if isinstance(self.result, str):
            return self.result
        return json.dumps(self.result, ensure_ascii=False, default=_json_default)


def _json_default(value: Any) -> Any:
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json")
    if isinstance(value, set):
        return sorted(value)
    return str(value)


@dataclass(frozen=True)
class _JsonSnapshot:
    cls: type
    data: str


def snapshot_db(db: Any) -> Any:
    """What a WRITE call saves before it runs, to restore the database if the call fails.

    Plain pydantic databases are saved as their JSON text: cheap to make, and dropping it after a
    successful call frees one string instead of a whole copied object tree (which cost tens of
    milliseconds for large charts). Databases with their own copy semantics (`__deepcopy__`, e.g.
    forks that share read-only tables) use those.
    """
    if db is None:
        return None
    from envs.core.db import DB

    if isinstance(db, DB) and type(db).__deepcopy__ is DB.__deepcopy__:
        return _JsonSnapshot(type(db), db.model_dump_json())
    return copy.deepcopy(db)


def restore_db(snapshot: Any, current: Any = None) -> Any:
    """The database to keep after a failed WRITE call: the saved state, or the current object
    when the call failed before changing anything (most tools validate first), which avoids
    rebuilding and freeing a whole database."""
    if isinstance(snapshot, _JsonSnapshot):
        if current is not None and current.model_dump_json() == snapshot.data:
            return current
        return snapshot.cls.model_validate_json(snapshot.data)
    return snapshot


class Toolkit:
    """Base class for a domain's tools: collects every method decorated with :func:`is_tool`.

    Subclasses hold the domain database in `self.db`. WRITE tools change it; a failed call
    (bad arguments, ToolError, or any exception) leaves it exactly as it was.
    """

    _definitions: ClassVar[dict[str, ToolDefinition]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        definitions: dict[str, ToolDefinition] = {}
        for klass in reversed(cls.__mro__):
            for attr, member in vars(klass).items():
                fn = getattr(member, "__func__", member)
                if callable(fn) and hasattr(fn, "__tool_type__"):
                    definition = ToolDefinition.from_function(fn)
                    definitions[definition.name] = definition
        cls._definitions = definitions

    def __init__(self, db: Any = None) -> None:
        self.db = db

    # -- introspection -------------------------------------------------------------------------
    @property
    def definitions(self) -> dict[str, ToolDefinition]:
        return self._definitions

    @property
    def tool_names(self) -> list[str]:
        return list(self.definitions)

    def has_tool(self, name: str) -> bool:
        return name in self.definitions

    def get_definition(self, name: str) -> ToolDefinition:
        try:
            return self.definitions[name]
        except KeyError:
            raise UnknownToolError(self.unknown_tool_message(name)) from None

    def unknown_tool_message(self, name: str) -> str:
        shown = name[:80] if isinstance(name, str) else safe_repr(name, 80)
        near = difflib.get_close_matches(shown, self.tool_names, n=3, cutoff=0.5)
        hint = f" Did you mean: {', '.join(near)}?" if near else f" Available tools: {', '.join(self.tool_names)}."
        return f"unknown tool {shown!r}.{hint}"

    def schemas(self) -> list[dict]:
        """OpenAI function schemas for every tool."""
        return [d.openai_schema() for d in self.definitions.values()]

    def bound(self, name: str) -> tuple[ToolDefinition, Callable]:
        definition = self.get_definition(name)
        return definition, getattr(self, definition.attribute)

    # -- execution -----------------------------------------------------------------------------
    def use_tool(self, name: str, **kwargs: Any) -> Any:
        """Call a tool directly (validated); raises on any error. For code, not agents."""
        definition, method = self.bound(name)
        return method(**definition.validate(kwargs))

    def call(self, name: str, arguments: Any) -> ToolOutcome:
        """Call a tool for the agent: never raises; errors become the outcome's `error`."""
        if not isinstance(name, str) or not self.has_tool(name):
            return ToolOutcome(name=name if isinstance(name, str) else safe_repr(name, 80),
                               arguments=arguments if isinstance(arguments, dict) else {},
                               error=self.unknown_tool_message(name), error_kind="unknown_tool")
        definition, method = self.bound(name)
        outcome = ToolOutcome(name=name, arguments=arguments if isinstance(arguments, dict) else {},
                              tool_type=definition.tool_type, submit=definition.submit)
        try:
            kwargs = definition.validate(arguments)
        except ToolArgumentError as exc:
            outcome.error, outcome.error_kind = str(exc), "invalid_arguments"
            return outcome
        snapshot = self._snapshot() if definition.tool_type is ToolType.WRITE else None
        try:
            outcome.result = method(**kwargs)
        except ToolError as exc:
            outcome.error, outcome.error_kind = f"{name}: {exc}", "tool_error"
        except (ValueError, TypeError, KeyError, LookupError, ArithmeticError) as exc:
            # A validation error from a clinical calculator names the argument and its range.
            outcome.error, outcome.error_kind = f"{name}: {type(exc).__name__}: {exc}", "input_error"
        except Exception as exc:  # a tool bug must not crash the episode or lose state
            outcome.error, outcome.error_kind = f"{name}: internal error {type(exc).__name__}: {exc}", "internal_error"
        if outcome.error is not None and snapshot is not None:
            self._restore(snapshot)
        return outcome

    def _snapshot(self) -> Any:
        return snapshot_db(self.db)

    def _restore(self, snapshot: Any) -> None:
        self.db = restore_db(snapshot, self.db)


class CompositeToolkit(Toolkit):
    """Several toolkits behind one interface.

    Name clashes: the first toolkit given wins (domain tools are listed before shared tools, so
    a domain may specialise a shared tool by defining one of the same name). Shadowed tools are
    listed in `shadowed` as (name, losing toolkit class) so the clash is visible, not silent.
    """

    def __init__(self, *toolkits: Toolkit) -> None:
        if not toolkits:
            raise ValueError("CompositeToolkit needs at least one toolkit")
        self.toolkits = list(toolkits)
        self._owner: dict[str, Toolkit] = {}
        self.shadowed: list[tuple[str, str]] = []
        merged: dict[str, ToolDefinition] = {}
        for kit in self.toolkits:
            for name, definition in kit.definitions.items():
                if name in merged:
                    self.shadowed.append((name, type(kit).__name__))
                    continue
                merged[name] = definition
                self._owner[name] = kit
        self._merged = merged

    @property
    def definitions(self) -> dict[str, ToolDefinition]:  # type: ignore[override]
        return self._merged

    @property
    def db(self) -> Any:  # the primary (domain) toolkit's database
        return self.toolkits[0].db

    @db.setter
    def db(self, value: Any) -> None:
        self.toolkits[0].db = value

    def bound(self, name: str) -> tuple[ToolDefinition, Callable]:
        definition = self.get_definition(name)
        return definition, getattr(self._owner[name], definition.attribute)

    def _snapshot(self) -> Any:
        return [snapshot_db(kit.db) for kit in self.toolkits]

    def _restore(self, snapshot: Any) -> None:
        for kit, saved in zip(self.toolkits, snapshot):
            kit.db = restore_db(saved, kit.db)
