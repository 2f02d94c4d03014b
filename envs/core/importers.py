"""Import task files written in the reference implementation's format.

Differences we absorb: `assertions` (older files) vs `nl_assertions`; options as a dict
{"A": text} or a list ("A. text" strings or plain texts); `correct_answer` as a letter in any
case or wrapping ("b", "(B)", "B."), or as the option's text; extra description keys. Tasks whose
expected actions name tools the domain lacks are reported with the missing names and left out of
the result (never silently dropped), as are rows that fail validation.
"""

from __future__ import annotations

import json
import re
import string
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from envs.core.db import DataFileError, format_validation_error
from envs.core.task import Task, TaskDescription

_LETTER = re.compile(r"^\(?\s*([A-Za-z])\s*[).:]?\s*$")
_LISTED = re.compile(r"^\s*\(?([A-Za-z])[).:]\s+(.*)$", re.DOTALL)


@dataclass
class ImportResult:
    tasks: list[Task] = field(default_factory=list)
    issues: list[str] = field(default_factory=list)


def _options(raw: Any) -> dict[str, str] | None:
    if raw is None:
        return None
    if isinstance(raw, dict):
        return {str(k).strip().upper(): str(v) for k, v in raw.items()}
    if isinstance(raw, list):
        out: dict[str, str] = {}
        for index, item in enumerate(raw):
            match = _LISTED.match(str(item))
            if match:
                out[match.group(1).upper()] = match.group(2).strip()
            else:
                out[string.ascii_uppercase[index]] = str(item)
        return out
    raise ValueError(f"options must be an object or a list, got {type(raw).__name__}")


def _answer_letter(answer: Any, options: dict[str, str] | None) -> str | None:
    if answer is None:
        return None
    text = str(answer).strip()
    match = _LETTER.match(text)
    if match and options and match.group(1).upper() in options:
        return match.group(1).upper()
    if options:
        for letter, option in options.items():
            if option.strip().lower() == text.lower():
                return letter
    return text


def convert_reference_task(raw: dict[str, Any], domain: str) -> dict[str, Any]:
    """Map one reference-format task dict onto our schema (a dict ready for `Task`)."""
    out: dict[str, Any] = {"domain": domain}
    for key in ("id", "ticket", "user_scenario", "raw_question", "raw_answer", "patient_id", "image_path"):
        if raw.get(key) is not None:
            out[key] = raw[key]
    if "ticket" not in out and raw.get("question"):
        out["ticket"] = raw["question"]
    desc = raw.get("description") or {}
    if isinstance(desc, str):
        desc = {"purpose": desc}
    known = set(TaskDescription.model_fields)
    out["description"] = {k: v for k, v in desc.items() if k in known}
    extra_desc = {k: v for k, v in desc.items() if k not in known}
    crit = dict(raw.get("evaluation_criteria") or {})
    if "assertions" in crit and "nl_assertions" not in crit:
        crit["nl_assertions"] = crit.pop("assertions")
    crit.pop("assertions", None)
    actions = []
    for index, action in enumerate(crit.get("actions") or []):
        action = dict(action)
        action.setdefault("action_id", f"a{index}")
        action.setdefault("arguments", {})
        actions.append({k: action[k] for k in ("action_id", "name", "arguments", "compare_args", "info") if k in action})
    crit["actions"] = actions
    crit = {k: v for k, v in crit.items() if k in ("actions", "nl_assertions", "reward_basis", "rubric")}
    if "reward_basis" in crit:
        crit["reward_basis"] = [b for b in crit["reward_basis"] if b in ("ACTION", "NL_ASSERTION", "ANSWER", "DB", "RUBRIC")]
    out["evaluation_criteria"] = crit
    options = _options(raw.get("options"))
    if options:
        out["options"] = options
    answer = _answer_letter(raw.get("correct_answer"), options)
    if answer is not None:
        out["correct_answer"] = answer
        out["answer_type"] = "choice" if options else "exact"
    if extra_desc:
        out["metadata"] = {"reference_description": extra_desc}
    return out


def import_reference_tasks(path: str | Path, domain: str, *, tool_names: set[str] | None = None) -> ImportResult:
    """Read a reference-format tasks JSON file and convert it; see the module docstring."""
    path = Path(path)
    if tool_names is None:
        from envs import registry

        tool_names = set(registry.get_environment(domain).toolkit.tool_names)
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataFileError(f"{path}: file not found") from None
    except json.JSONDecodeError as exc:
        raise DataFileError(f"{path}: not valid JSON at line {exc.lineno} column {exc.colno}: {exc.msg}") from None
    if isinstance(raw, dict) and "tasks" in raw:
        raw = raw["tasks"]
    if not isinstance(raw, list):
        raise DataFileError(f"{path}: expected a JSON list of tasks, got {type(raw).__name__}")
    result = ImportResult()
    for index, item in enumerate(raw):
        label = f"task {item.get('id')!r}" if isinstance(item, dict) and item.get("id") else f"task #{index}"
        if not isinstance(item, dict):
            result.issues.append(f"{path} [{label}]: expected an object, got {type(item).__name__}")
            continue
        try:
            task = Task.model_validate(convert_reference_task(item, domain))
        except ValidationError as exc:
            result.issues.append(format_validation_error(exc, source=str(path), item=label))
            continue
        except ValueError as exc:
            result.issues.append(f"{path} [{label}]: {exc}")
            continue
        missing = sorted({a.name for a in task.evaluation_criteria.actions} - tool_names)
        if missing:
            result.issues.append(f"{path} [{label}]: names tools the {domain!r} domain lacks: {', '.join(missing)}")
            continue
        result.tasks.append(task)
    return result
