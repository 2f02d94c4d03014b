"""Import task files written in the reference implementation's format.

Differences we absorb (facts about its files: ../shared/reference/reference_implementation.md):
* `assertions` (older files) vs `nl_assertions`; options as a dict {"A": text} or a list ("A. text"
  strings or plain texts); extra description keys (kept in `metadata["reference_description"]`).
* `correct_answer` as a letter in any case or wrapping ("b", "(B)", "B.", "Answer: (C)", "The answer is
  C"), or as the option's text.
* The EHR legacy schema: `expected_actions` ([{"tool", "args"}] or tool names), `expected_answer`,
  `rubric.must_mention` (and `rubric_keys`) become our expected actions, gold answer and must-mention
  assertions (NL assertions plus a rubric of required elements, so the task is graded on them).
* Tool names the reference renamed: `REFERENCE_TOOL_RENAMES` (below, and in envs/converters/README.md)
  maps them to ours, with their argument renames; a required `patient_id` missing from an action is
  taken from the task's own `patient_id`. An expected `submit_answer` action is dropped: the answer is
  graded as the answer (the reference expected `submit_answer(answer="")`, which no real answer matches).

Tasks whose expected actions still name tools the domain lacks are reported with the missing names and
left out of the result (never silently dropped), as are rows that fail the task schema. Whether the rest
can be graded (gold answer, argument fit) is checked by `hcgym tasks import` with
`envs.validate.static_problems`, for every imported task whatever its format.
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
# "Answer: (C)", "answer - C", "The answer is C.", "Correct answer: c)": the training prompt convention of
# the published runs ends answers with "Answer: X"
_ANSWER_PREFIX = re.compile(r"^\s*(?:the\s+)?(?:correct\s+|final\s+)?answer\s*(?:is|:|-|=)?\s*", re.IGNORECASE)

# reference tool name -> (our tool, {reference argument: our argument}); "*" applies to every domain.
# Every name here was read in the reference's task files (psychiatry and obstetrics tasks.json, the EHR
# benchmark files, the auto-generated evidence tasks); add a row only for a name seen there.
# Only tools that do the same job are mapped; the reference's tools with no counterpart here stay unknown
# and their tasks are reported (e.g. get_quality_indicators, administer_ymrs, get_glucose_log).
REFERENCE_TOOL_RENAMES: dict[str, dict[str, tuple[str, dict[str, str]]]] = {
    "*": {
        "search_wiki": ("search_medical_wiki", {}),
        "search_evidence": ("retrieve_evidence", {}),
        "review_treatment_guidelines": ("search_guidelines", {"condition": "query"}),
    },
    "ehr_management": {
        "get_patient_summary": ("summarize_admission", {}),
        "get_admission_info": ("summarize_admission", {}),
        "get_lab_results": ("get_lab_events", {}),
    },
    "obstetrics": {
        "get_patient_info": ("get_patient_summary", {}),
        "get_fetal_monitoring": ("get_ctg_tracing", {}),
        "get_labor_progress": ("get_cervical_exam", {}),
        "get_ultrasound_results": ("get_ultrasound_report", {}),
        "get_bishop_score": ("calculate_bishop_score", {}),
        "get_prenatal_labs": ("get_lab_results", {}),
        "order_medication": ("order_medication", {"medication": "drug"}),
    },
    "psychiatry": {
        "perform_mental_status_exam": ("mental_status_exam", {}),
        "get_patient_presentation": ("get_patient_summary", {}),
        "order_laboratory_tests": ("order_lab", {"tests": "test"}),
    },
}


GRADED_BASES = ("ACTION", "NL_ASSERTION", "ANSWER", "DB", "RUBRIC")


def rename_for(domain: str, name: str) -> tuple[str, dict[str, str]] | None:
    return REFERENCE_TOOL_RENAMES.get(domain, {}).get(name) or REFERENCE_TOOL_RENAMES["*"].get(name)


@dataclass
class ImportResult:
    tasks: list[Task] = field(default_factory=list)
    issues: list[str] = field(default_factory=list)
    rows_read: int = 0
    # reason -> count of rows left out here (schema, unknown tools); the CLI adds the validation reasons
    rejected: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def reject(self, reason: str, message: str) -> None:
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        self.issues.append(message)


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
    for candidate in (text, _ANSWER_PREFIX.sub("", text, count=1).strip()):
        match = _LETTER.match(candidate)
        if match and options and match.group(1).upper() in options:
            return match.group(1).upper()
        if options:
            for letter, option in options.items():
                if option.strip().lower() == candidate.lower():
                    return letter
    return text


def _legacy_actions(raw: Any) -> list[dict[str, Any]]:
    """The EHR legacy `expected_actions`: [{"tool"|"name", "args"|"arguments"}] or bare tool names."""
    if not isinstance(raw, list):
        raise ValueError(f"expected_actions must be a list, got {type(raw).__name__}")  # noqa: TRY004 (a row error reported with the task)
    out = []
    for index, item in enumerate(raw):
        if isinstance(item, str):
            out.append({"action_id": f"a{index}", "name": item, "arguments": {}})
            continue
        if not isinstance(item, dict) or not (item.get("tool") or item.get("name")):
            raise ValueError(f"expected_actions[{index}] must be a tool name or an object with 'tool' and 'args'")
        args = item.get("args", item.get("arguments")) or {}
        if not isinstance(args, dict):
            raise ValueError(f"expected_actions[{index}].args must be an object")  # noqa: TRY004 (a row error)
        out.append({"action_id": f"a{index}", "name": item.get("tool") or item.get("name"), "arguments": dict(args),
                    "compare_args": list(args)})
    return out


def _mentions(raw: dict[str, Any], crit: dict[str, Any]) -> list[str]:
    rubric = raw.get("rubric")
    items: list[str] = []
    if isinstance(rubric, dict):
        items += [str(x) for x in rubric.get("must_mention") or []]
    items += [str(x) for x in crit.pop("rubric_keys", None) or raw.get("rubric_keys") or []]
    return [x for x in dict.fromkeys(items) if x.strip()]


def convert_reference_task(raw: dict[str, Any], domain: str, *, renamed: dict[str, int] | None = None) -> dict[str, Any]:
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
    for key in ("category", "difficulty", "source"):  # the EHR legacy schema keeps these at the top level
        if raw.get(key) is not None and isinstance(raw[key], str):
            desc = {key: raw[key], **desc}
    known = set(TaskDescription.model_fields)
    out["description"] = {k: v for k, v in desc.items() if k in known}
    extra_desc = {k: v for k, v in desc.items() if k not in known}
    crit = dict(raw.get("evaluation_criteria") or {})
    if "assertions" in crit and "nl_assertions" not in crit:
        crit["nl_assertions"] = crit.pop("assertions")
    crit.pop("assertions", None)
    mentions = _mentions(raw, crit)
    raw_actions = crit.get("actions") or (_legacy_actions(raw["expected_actions"]) if raw.get("expected_actions")
                                           else [])
    actions = []
    for index, action in enumerate(raw_actions):
        action = dict(action)
        if action.get("name") == "submit_answer":
            continue  # graded as the answer, not as an expected call
        action.setdefault("action_id", f"a{index}")
        arguments = dict(action.get("arguments") or {})
        mapped = rename_for(domain, str(action.get("name")))
        if mapped:
            new_name, arg_map = mapped
            if renamed is not None and new_name != action["name"]:
                key = f"{action['name']} -> {new_name}"
                renamed[key] = renamed.get(key, 0) + 1
            action["name"] = new_name
            arguments = {arg_map.get(k, k): v for k, v in arguments.items()}
            if action.get("compare_args"):
                action["compare_args"] = [arg_map.get(k, k) for k in action["compare_args"]]
        if out.get("patient_id") and "patient_id" not in arguments and _needs_patient(domain, action["name"]):
            arguments["patient_id"] = out["patient_id"]
        action["arguments"] = arguments
        actions.append({k: action[k] for k in ("action_id", "name", "arguments", "compare_args", "info") if k in action})
    crit["actions"] = actions
    crit = {k: v for k, v in crit.items() if k in ("actions", "nl_assertions", "reward_basis", "rubric")}
    if "reward_basis" in crit:
        given = crit["reward_basis"] if isinstance(crit["reward_basis"], list) else [crit["reward_basis"]]
        # the reference's "MCQA" basis is its multiple-choice answer check: our ANSWER
        basis = [{"MCQA": "ANSWER"}.get(str(b), str(b)) for b in given]
        crit["reward_basis"] = list(dict.fromkeys(b for b in basis if b in GRADED_BASES))
        if given and not crit["reward_basis"]:
            raise ValueError(f"reward_basis {given} names nothing we grade ({', '.join(GRADED_BASES)}, or MCQA)")
    if mentions:
        crit["nl_assertions"] = list(crit.get("nl_assertions") or []) + [f"The response mentions {m}" for m in mentions]
        crit["rubric"] = list(crit.get("rubric") or []) + [
            {"criterion": f"Mentions {m}", "points": 1.0, "kind": "required_element", "tags": ["must_mention"]}
            for m in mentions]
        basis = crit.get("reward_basis") or ["ACTION"] * bool(actions)
        crit["reward_basis"] = list(dict.fromkeys([*basis, "NL_ASSERTION", "RUBRIC"]))
    out["evaluation_criteria"] = crit
    options = _options(raw.get("options"))
    if options is not None and not options and raw.get("correct_answer") is not None:
        raise ValueError(f"options are empty but correct_answer is {raw['correct_answer']!r}")
    if options:
        out["options"] = options
    gold = raw.get("correct_answer")
    if gold is None and raw.get("expected_answer") is not None:
        gold = raw["expected_answer"]
    answer = _answer_letter(gold, options)
    if answer is not None and str(answer).strip():
        out["correct_answer"] = answer
        # a legacy expected answer in prose is graded as free text, a short one as an exact answer
        out["answer_type"] = "choice" if options else ("free_text" if len(str(answer).split()) > 8 else "exact")
        if "reward_basis" in crit and "ANSWER" not in crit["reward_basis"]:
            crit["reward_basis"].append("ANSWER")
    if extra_desc:
        out["metadata"] = {"reference_description": extra_desc}
    return out


_PATIENT_TOOLS: dict[str, set[str]] = {}


def _needs_patient(domain: str, tool: str) -> bool:
    """Whether our `tool` in `domain` requires a `patient_id` argument (the reference's EHR tools took only
    `hadm_id`; ours also name the patient, which the legacy task gives at its top level)."""
    if domain not in _PATIENT_TOOLS:
        try:
            from envs import registry

            definitions = registry.get_environment(domain).toolkit.definitions
        except Exception:  # noqa: BLE001 (an unknown or broken domain: the caller reports the domain itself)
            definitions = {}
        _PATIENT_TOOLS[domain] = {name for name, d in definitions.items()
                                  if "patient_id" in d.parameters.get("required", [])}
    return tool in _PATIENT_TOOLS[domain]


def read_reference_file(path: Path) -> list[Any]:
    from envs.converters.base import SourceFileError, read_text

    try:
        raw = json.loads(read_text(path))
    except SourceFileError as exc:
        raise DataFileError(str(exc)) from None
    except json.JSONDecodeError as exc:
        raise DataFileError(f"{path}:{exc.lineno}: not valid JSON at line {exc.lineno} column {exc.colno}: "
                            f"{exc.msg}") from None
    if isinstance(raw, dict) and "tasks" in raw:
        raw = raw["tasks"]
    if not isinstance(raw, list):
        raise DataFileError(f"{path}: expected a JSON list of tasks, got {type(raw).__name__}")
    return raw


def import_reference_tasks(path: str | Path, domain: str, *, tool_names: set[str] | None = None) -> ImportResult:
    """Read a reference-format tasks JSON file and convert it; see the module docstring."""
    path = Path(path)
    per_task = None
    if tool_names is None:
        from envs import registry

        tool_names = set(registry.get_environment(domain).toolkit.tool_names)
        # domains whose tools depend on the task (cross_domain: a pathway's phases, or an imported task's
        # knowledge tools) say which tools each task may use
        per_task = getattr(registry.domain_module(domain), "task_tool_definitions", None)
    raw = read_reference_file(path)
    result = ImportResult()
    renamed: dict[str, int] = {}
    for index, item in enumerate(raw):
        result.rows_read += 1
        label = f"task {item.get('id')!r}" if isinstance(item, dict) and item.get("id") else f"task #{index}"
        if not isinstance(item, dict):
            result.reject("not a task object", f"{path} [{label}]: expected an object, got {type(item).__name__}")
            continue
        try:
            task = Task.model_validate(convert_reference_task(item, domain, renamed=renamed))
        except ValidationError as exc:
            result.reject("schema", format_validation_error(exc, source=str(path), item=label))
            continue
        except ValueError as exc:
            result.reject("schema", f"{path} [{label}]: {exc}")
            continue
        available = tool_names
        if per_task is not None:
            try:
                available = set(per_task(task))
            except (KeyError, ValueError):
                available = tool_names
        missing = sorted({a.name for a in task.evaluation_criteria.actions} - available)
        if missing:
            result.reject("unknown tool", f"{path} [{label}]: names tools the {domain!r} domain lacks: "
                                          f"{', '.join(missing)}")
            continue
        result.tasks.append(task)
    for key, count in sorted(renamed.items()):
        result.notes.append(f"{path}: reference tool renamed {key} in {count} expected action(s)")
    return result
