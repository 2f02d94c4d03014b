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
`ParsedAction.errors`, which the environment shows to the agent. Hostile input is bounded here, so
nothing downstream (argument validation, turn records, the reward) sees values Python cannot
print or recurse through: JSON and call arguments may nest at most `MAX_NESTING_DEPTH` levels,
integers may have at most `MAX_INTEGER_DIGITS` digits, and function syntax accepts only JSON-typed
literals (strings, numbers, true/false/null, lists, objects with string keys).
"""

from __future__ import annotations

import ast
import json
import re
from dataclasses import dataclass, field
from typing import Any, Container

from envs.core.tools import safe_repr

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


MAX_NESTING_DEPTH = 64  # far beyond any tool's arguments; stops RecursionError in json/pydantic/rewards
MAX_INTEGER_DIGITS = 100  # int() refuses >4,300 digits and float() overflows past ~308; 100 is ample


class ActionSyntaxError(ValueError):
    """A call-shaped structure that cannot be read; its message is shown to the agent."""


_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)
_BRACKETS = re.compile(r"[\[\]{}]")


def _nesting_depth(text: str) -> int:
    """Deepest bracket nesting of a JSON text, string contents ignored (cheap: one regex pass)."""
    depth = deepest = 0
    for match in _BRACKETS.finditer(_JSON_STRING.sub('""', text)):
        if match.group() in "[{":
            depth += 1
            deepest = max(deepest, depth)
        else:
            depth -= 1
    return deepest


def _bounded_int(digits: str) -> int:
    if len(digits.lstrip("-")) > MAX_INTEGER_DIGITS:
        raise ActionSyntaxError(f"integer of {len(digits.lstrip('-'))} digits exceeds the limit of {MAX_INTEGER_DIGITS} digits")
    return int(digits)


def _loads(text: str) -> Any:
    """json.loads with bounded nesting and integer size; every failure is an ActionSyntaxError."""
    depth = _nesting_depth(text)
    if depth > MAX_NESTING_DEPTH:
        raise ActionSyntaxError(f"JSON nested {depth} levels deep exceeds the limit of {MAX_NESTING_DEPTH}")
    try:
        return json.loads(text, parse_int=_bounded_int)
    except json.JSONDecodeError as exc:
        raise ActionSyntaxError(f"{exc.msg} at position {exc.pos}") from None
    except RecursionError:  # the depth check counts brackets; this is the backstop
        raise ActionSyntaxError(f"JSON nested deeper than {MAX_NESTING_DEPTH} levels") from None
    except ValueError as exc:  # _bounded_int, or a number Python refuses to convert
        raise ActionSyntaxError(str(exc)) from None


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
                args = _loads(stripped)
            except ActionSyntaxError as exc:
                errors.append(f"arguments of {name[:80]!r} are not valid JSON: {exc}")
                return []
    if args is None:
        args = {}
    return [ParsedCall(name=name, arguments=args, format=fmt)]


_PY_LITERALS = {"true": True, "false": False, "null": None, "none": None}


def _literal(node: ast.AST, depth: int = 0) -> Any:
    """A function-syntax argument as a JSON value. Only JSON types are accepted: a complex, bytes,
    set or Ellipsis literal would pass ast.literal_eval but break json.dumps in the turn record."""
    if depth > MAX_NESTING_DEPTH:
        raise ActionSyntaxError(f"argument nested deeper than {MAX_NESTING_DEPTH} levels")
    if isinstance(node, ast.Name):  # JSON-style true/false/null, or a bare word as a string
        return _PY_LITERALS.get(node.id.lower(), node.id)
    if isinstance(node, ast.Constant):
        value = node.value
        if isinstance(value, bool) or value is None or isinstance(value, str):
            return value
        if isinstance(value, int):
            # hex/octal/binary literals are parsed without the decimal digit limit; bound by size
            if value.bit_length() > MAX_INTEGER_DIGITS * 3.33:
                raise ActionSyntaxError(f"integer literal exceeds the limit of {MAX_INTEGER_DIGITS} digits")
            return value
        if isinstance(value, float):
            return value
        kind = "Ellipsis (...)" if value is Ellipsis else type(value).__name__
        raise ActionSyntaxError(f"{kind} literal is not a JSON value (use a string, number, true/false/null, list or object)")
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        operand = _literal(node.operand, depth + 1)
        if isinstance(operand, bool) or not isinstance(operand, (int, float)):
            raise ActionSyntaxError("a sign (+/-) applies only to a number")
        return -operand if isinstance(node.op, ast.USub) else operand
    if isinstance(node, (ast.List, ast.Tuple)):
        return [_literal(item, depth + 1) for item in node.elts]
    if isinstance(node, ast.Dict):
        out: dict[str, Any] = {}
        for key, value in zip(node.keys, node.values):
            if key is None:
                raise ActionSyntaxError("** unpacking is not allowed in an argument")
            key_value = _literal(key, depth + 1)
            if not isinstance(key_value, str):
                raise ActionSyntaxError(f"object keys must be strings, got {type(key_value).__name__}")
            out[key_value] = _literal(value, depth + 1)
        return out
    if isinstance(node, ast.Set):
        raise ActionSyntaxError("set literal is not a JSON value (use a list [..])")
    raise ActionSyntaxError(f"{type(node).__name__} expression is not a literal value")


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
        except (SyntaxError, ValueError, TypeError, RecursionError, MemoryError, OverflowError) as exc:
            # ValueError includes Python's own integer-digit limit when parsing a huge decimal literal
            kind = f"{type(exc).__name__}: " if isinstance(exc, (RecursionError, MemoryError)) else ""
            errors.append(f"could not read call to {name!r}: {kind}{str(exc)[:300]}")
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
    try:
        return _parse_action(text, tool_names)
    except Exception as exc:  # a parser bug must become a parse error the agent sees, never a crash
        message = text if isinstance(text, str) else f"<{type(text).__name__}>"
        return ParsedAction(message=message, format="text",
                            errors=[f"action could not be parsed ({type(exc).__name__}: {str(exc)[:200]})"])


def _parse_action(text: Any, tool_names: Container[str]) -> ParsedAction:
    if not isinstance(text, str):
        return ParsedAction(format="text", message=safe_repr(text, 2000),
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
            except ActionSyntaxError as exc:
                errors.append(f"<tool_call> block is not valid JSON: {exc}")
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
            except ActionSyntaxError as exc:
                errors.append(f"fenced JSON block is not valid JSON: {exc}")
                continue
            calls.extend(_call_from_obj(obj, "fenced", errors))
        if fenced_any:
            message = _FENCE.sub("", stripped).strip()
            return ParsedAction(calls=calls, message=message, format="fenced", errors=errors)

    if stripped[0] in "{[":
        try:
            obj = _loads(stripped)
        except ActionSyntaxError as exc:
            if '"name"' in stripped or "'name'" in stripped or "nested" in str(exc) or "digits" in str(exc):
                errors.append(f"action looks like a JSON tool call but is not valid JSON: {exc}")
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
