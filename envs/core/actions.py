"""Turning an agent's raw text into tool calls.

Accepted, in this order of precedence:
  * Hermes/Qwen blocks: ``<tool_call>{"name": ..., "arguments": {...}}</tool_call>`` (several allowed)
  * fenced JSON: a ```json (or bare ```) block holding a call object or a list of them
  * a bare JSON value: a call object ``{"name", "arguments"}``, an OpenAI tool call
    ``{"type": "function", "function": {"name", "arguments": "<json string>"}}``, a message with
    ``tool_calls: [...]``, or a list of any of these
  * function-call syntax ``tool(a=1, b="x")`` for a known tool name, one per line; the values are
    Python/JSON literals, typed later by the tool's signature (so ``dose_mg="5"`` becomes 5.0)
Anything else is a plain message. Several calls in one action are executed in order.

Parsing never raises: a structure that looks like a call but cannot be read is reported in
`ParsedAction.errors`, which the environment shows to the agent.
"""

from __future__ import annotations

import ast
import json
import re
from dataclasses import dataclass, field
from typing import Any, Container

_HERMES = re.compile(r"<tool_call>\s*(.*?)\s*(?:</tool_call>|$)", re.DOTALL)
_FENCE = re.compile(r"```[ \t]*(json|JSON|tool_call|)[ \t]*\n?(.*?)```", re.DOTALL)
_FUNC_START = re.compile(r"(?<![\w.])([A-Za-z_][A-Za-z0-9_]*)\s*\(")


@dataclass
class ParsedCall:
    name: str
    arguments: Any  # dict when well formed; validated against the tool signature later
    format: str


@dataclass
class ParsedAction:
    calls: list[ParsedCall] = field(default_factory=list)
    message: str = ""
    format: str = "text"  # json | openai | hermes | fenced | function | text | empty
    errors: list[str] = field(default_factory=list)


def _loads(text: str) -> Any:
    return json.loads(text)


def _call_from_obj(obj: Any, fmt: str, errors: list[str]) -> list[ParsedCall]:
    """Read one JSON value as zero or more calls (object, OpenAI shape, tool_calls list, list)."""
    if isinstance(obj, list):
        calls: list[ParsedCall] = []
        for item in obj:
            calls.extend(_call_from_obj(item, fmt, errors))
        return calls
    if not isinstance(obj, dict):
        return []
    if isinstance(obj.get("tool_calls"), list):
        return _call_from_obj(obj["tool_calls"], "openai" if fmt == "json" else fmt, errors)
    if isinstance(obj.get("function"), dict):
        inner = obj["function"]
        fmt = "openai" if fmt == "json" else fmt
    else:
        inner = obj
    name = inner.get("name")
    if name is None:
        if "arguments" in inner or "parameters" in inner:
            errors.append("tool call object has no 'name'")
        return []
    if not isinstance(name, str):
        errors.append(f"tool name must be a string, got {type(name).__name__}")
        return []
    args = inner.get("arguments", inner.get("parameters", {}))
    if isinstance(args, str):
        stripped = args.strip()
        if not stripped:
            args = {}
        else:
            try:
                args = json.loads(stripped)
            except json.JSONDecodeError as exc:
                errors.append(f"arguments of {name!r} are not valid JSON: {exc.msg} at position {exc.pos}")
                return []
    if args is None:
        args = {}
    return [ParsedCall(name=name, arguments=args, format=fmt)]


_PY_LITERALS = {"true": True, "false": False, "null": None, "none": None}


def _literal(node: ast.AST) -> Any:
    if isinstance(node, ast.Name):  # JSON-style true/false/null, or a bare word as a string
        return _PY_LITERALS.get(node.id.lower(), node.id)
    return ast.literal_eval(node)


def _split_call(text: str, start: int) -> int | None:
    """Index just past the parenthesis that closes the one opened at `start`, quotes respected."""
    depth, i, quote = 0, start, None
    while i < len(text):
        ch = text[i]
        if quote:
            if ch == "\\":
                i += 2
                continue
            if ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
            if depth == 0:
                return i + 1
        i += 1
    return None


def _function_calls(text: str, tool_names: Container[str], errors: list[str]) -> tuple[list[ParsedCall], str]:
    calls: list[ParsedCall] = []
    rest: list[str] = []
    pos = 0
    for match in _FUNC_START.finditer(text):
        if match.start() < pos or match.group(1) not in tool_names:
            continue
        end = _split_call(text, match.end() - 1)
        if end is None:
            errors.append(f"call to {match.group(1)!r} has no closing parenthesis")
            continue
        source = text[match.start():end]
        name = match.group(1)
        try:
            node = ast.parse(source, mode="eval").body
            if not isinstance(node, ast.Call):
                raise ValueError("not a call")
            if node.args:
                raise ValueError("use keyword arguments, e.g. tool(name=value)")
            args = {kw.arg: _literal(kw.value) for kw in node.keywords if kw.arg is not None}
        except (SyntaxError, ValueError, TypeError) as exc:
            errors.append(f"could not read call to {name!r}: {exc}")
            rest.append(text[pos:end])
            pos = end
            continue
        rest.append(text[pos:match.start()])
        calls.append(ParsedCall(name=name, arguments=args, format="function"))
        pos = end
    rest.append(text[pos:])
    return calls, "".join(rest)


def parse_action(text: Any, tool_names: Container[str] = ()) -> ParsedAction:
    """Parse an agent action. Never raises.

    Args:
        text: The agent's raw output for this turn.
        tool_names: Known tool names; function-call syntax is recognised only for these.
    """
    if not isinstance(text, str):
        return ParsedAction(format="text", message=repr(text)[:2000],
                            errors=[f"action must be a string, got {type(text).__name__}"])
    stripped = text.strip()
    if not stripped:
        return ParsedAction(format="empty")
    errors: list[str] = []

    if "<tool_call>" in stripped:
        calls: list[ParsedCall] = []
        for body in _HERMES.findall(stripped):
            body = body.strip()
            if body.startswith("```"):
                body = body.strip("`").removeprefix("json").strip()
            try:
                obj = _loads(body)
            except json.JSONDecodeError as exc:
                errors.append(f"<tool_call> block is not valid JSON: {exc.msg} at position {exc.pos}")
                continue
            found = _call_from_obj(obj, "hermes", errors)
            if not found and not errors:
                errors.append("<tool_call> block holds no tool call object with a 'name'")
            calls.extend(found)
        message = _HERMES.sub("", stripped).strip()
        return ParsedAction(calls=calls, message=message, format="hermes", errors=errors)

    if "```" in stripped:
        calls = []
        fenced_any = False
        for lang, body in _FENCE.findall(stripped):
            body = body.strip()
            if not body.startswith(("{", "[")):
                continue
            fenced_any = True
            try:
                obj = _loads(body)
            except json.JSONDecodeError as exc:
                errors.append(f"fenced JSON block is not valid JSON: {exc.msg} at position {exc.pos}")
                continue
            calls.extend(_call_from_obj(obj, "fenced", errors))
        if fenced_any:
            message = _FENCE.sub("", stripped).strip()
            return ParsedAction(calls=calls, message=message, format="fenced", errors=errors)

    if stripped[0] in "{[":
        try:
            obj = _loads(stripped)
        except json.JSONDecodeError as exc:
            if '"name"' in stripped or "'name'" in stripped:
                errors.append(f"action looks like a JSON tool call but is not valid JSON: {exc.msg} at position {exc.pos}")
            return ParsedAction(message=stripped, format="text", errors=errors)
        calls = _call_from_obj(obj, "json", errors)
        fmt = calls[0].format if calls else "json"
        message = obj.get("content") or "" if isinstance(obj, dict) and isinstance(obj.get("content"), str) else ""
        if not calls and not errors:
            return ParsedAction(message=stripped, format="text")
        return ParsedAction(calls=calls, message=message, format=fmt, errors=errors)

    if "(" in stripped and tool_names:
        calls, rest = _function_calls(stripped, tool_names, errors)
        if calls or errors:
            return ParsedAction(calls=calls, message=rest.strip(), format="function", errors=errors)

    return ParsedAction(message=stripped, format="text")
