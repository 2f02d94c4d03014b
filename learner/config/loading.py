"""Loading a run config: YAML files (`extends`), `--set` overrides, validation with one line per problem.

A config may start from another with `extends: other.yaml` (path relative to the file); mappings
merge key by key, everything else is replaced. `--set key.path=value` overrides apply last.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from learner.config.checks import _number_problems, _reference_problems
from learner.config.schema import RunConfig


class ConfigError(ValueError):
    """A config file is unreadable or invalid; the message names the file and each key path."""


class _ConfigLoader(yaml.SafeLoader):
    """PyYAML's safe loader with YAML 1.2 floats: `lr: 3e-4` is the number 0.0003, not the string
    '3e-4' (YAML 1.1, which PyYAML follows, needs a dot and a signed exponent: `3.0e-4`)."""


_ConfigLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                  |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                  |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                  |[-+]?\.(?:inf|Inf|INF)
                  |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."),
)


def _yaml_load(text: str) -> Any:
    return yaml.load(text, Loader=_ConfigLoader)  # noqa: S506 (a SafeLoader subclass)


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for key, value in over.items():
        out[key] = _merge(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def _read_yaml(path: Path, seen: tuple[Path, ...] = ()) -> dict:
    path = path.resolve()
    if path in seen:
        raise ConfigError(f"{path}: 'extends' cycle: {' -> '.join(str(p) for p in (*seen, path))}")
    if not path.exists():
        raise ConfigError(f"{path}: config file not found")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the config file ({exc.strerror or exc})") from None
    try:
        text = data.decode("utf-8-sig")  # a BOM from a Windows editor is not part of the YAML
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ConfigError(f"{path}: config file is not UTF-8 text (byte 0x{data[exc.start]:02x} at line {line}); "
                          f"re-save it as UTF-8") from None
    try:
        raw = _yaml_load(text)
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        at = f" at line {where.line + 1}, column {where.column + 1}" if where else ""
        raise ConfigError(f"{path}: not valid YAML{at}: {getattr(exc, 'problem', exc)}") from None
    except RecursionError:
        raise ConfigError(f"{path}: config file is nested too deeply to parse") from None
    raw = raw or {}
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: the top level must be a mapping of sections, got {type(raw).__name__}")
    parent = raw.pop("extends", None)
    if parent is None:
        return raw
    if not isinstance(parent, str):
        raise ConfigError(f"{path}: extends: expected a file path, got {type(parent).__name__}")
    return _merge(_read_yaml(path.parent / parent, (*seen, path)), raw)


def _set_path(data: dict, dotted: str, value: Any) -> None:
    keys = dotted.split(".")
    node = data
    for key in keys[:-1]:
        child = node.setdefault(key, {})
        if not isinstance(child, dict):
            raise ConfigError(f"override {dotted!r}: {key!r} is not a section")
        node = child
    node[keys[-1]] = value


def format_errors(exc: ValidationError) -> list[str]:
    """One line per error: `dotted.key.path: message (got value)`."""
    lines = []
    for err in exc.errors():
        path = ".".join(str(p) for p in err["loc"]) or "(top level)"
        if err["type"] == "extra_forbidden":
            lines.append(f"{path}: unknown key")
            continue
        got = err.get("input")
        shown = "" if isinstance(got, (dict, list)) or got is None else f" (got {got!r})"
        message = err["msg"]
        if err["type"] == "value_error":
            # A section's own validator says which key it means ("teacher.hints.reward_threshold: ...");
            # report it at that key instead of at the section ("(top level): Value error, ...").
            named = _NAMED_KEY.match(message.removeprefix("Value error, "))
            prefix = "" if path == "(top level)" else path + "."
            if named and named["key"].startswith(prefix):
                path, message, shown = named["key"], named["rest"], ""
        lines.append(f"{path}: {message}{shown}")
    return lines


_NAMED_KEY = re.compile(r"(?P<key>[a-z_]+(?:\.[a-z_0-9]+)+)(?::| (?=[a-z(]))\s*(?P<rest>.*)", re.S)


def validate_config(data: dict, source: str = "<config>", *, check_references: bool = True) -> RunConfig:
    """Validate a config mapping into a `RunConfig`.

    Beyond the models' own rules: booleans or strings where numbers belong and non-finite numbers
    are refused; with `check_references`, so are unknown domains, splits a domain does not declare
    and (for a run on this machine) local paths that do not exist.

    Raises:
        ConfigError: naming `source` and the key path of every problem.
    """
    problems = _number_problems(RunConfig, data, "") if isinstance(data, dict) else []
    # One line per key: pydantic's own message for a key flagged above adds nothing (its paths
    # write list indices as `.1` where ours write `[1]`).
    flagged = {re.sub(r"\[(\d+)\]", r".\1", line.split(": ", 1)[0]) for line in problems}
    config = None
    try:
        config = RunConfig.model_validate(data)
    except ValidationError as exc:
        problems += [line for line in format_errors(exc) if line.split(": ", 1)[0] not in flagged]
    if config is not None and not problems and check_references:
        problems = _reference_problems(config)
    if problems:
        raise ConfigError(f"{source}: invalid config\n  " + "\n  ".join(problems))
    return config


def load_config(path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> RunConfig:
    """Load a YAML run config, apply `key.path=value` overrides (values parsed as YAML), validate.

    Raises:
        ConfigError: naming the file and the key path of every problem.
    """
    path = Path(path)
    data = _read_yaml(path)
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"override {item!r}: expected key.path=value")
        key, _, text = item.partition("=")
        try:
            value = _yaml_load(text)
        except yaml.YAMLError:
            value = text
        _set_path(data, key.strip(), value)
    return validate_config(data, str(path))


def dump_config(config: RunConfig, path: str | Path) -> None:
    """Write the resolved config (what actually ran) next to the run's outputs."""
    Path(path).write_text(yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False), encoding="utf-8")
