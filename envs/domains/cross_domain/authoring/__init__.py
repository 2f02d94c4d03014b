"""The authored pathways of the cross-domain domain, read from the case files, and the fixed split.

The cases are data (`envs/domains/cross_domain/cases/<family>.yaml`, one file per pathway family,
schema in `schema.py`), so a clinician reviews them without reading Python; `rendering.py` turns a
case into the pathway the engine runs. `python -m envs.domains.cross_domain.authoring` writes
`pathways.json` and `split_tasks.json` next to the environment; the test suite checks that the
committed files equal what the case files build, so the JSON is never edited by hand.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from envs.core.db import DataFileError

from .rendering import pathway
from .schema import Case, CaseFile

HERE = Path(__file__).resolve().parent.parent
CASES_DIR = HERE / "cases"
# The families in the order pathways.json lists them (file stem -> cases/<stem>.yaml).
FAMILIES: tuple[str, ...] = ("chest_pain", "diabetic", "stroke", "sepsis", "postop", "paediatric")


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML keeps the last of two equal keys silently; a case file with a repeated key is refused."""


def _mapping_without_repeats(loader: _UniqueKeyLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen: set[Any] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(None, None, f"repeated key {key!r}", key_node.start_mark)
        seen.add(key)
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping_without_repeats)


def _location(loc: tuple[Any, ...]) -> str:
    return ".".join(str(part) for part in loc) or "(top level)"


def _errors(exc: ValidationError) -> str:
    return "; ".join(f"field {_location(e['loc'])}: {e['msg']}" for e in exc.errors())


def load_case_file(path: Path) -> tuple[str, list[Case]]:
    """(family title, validated cases) of one case file; a bad file raises `DataFileError` naming the
    file, the line (YAML syntax), the case (index and id) and the field."""
    try:
        raw = yaml.load(path.read_text(encoding="utf-8"), Loader=_UniqueKeyLoader)  # noqa: S506 (a SafeLoader)
    except FileNotFoundError:
        raise DataFileError(f"{path}: case file not found") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        raise DataFileError(f"{path}:{where} not valid YAML: {getattr(exc, 'problem', None) or exc}") from None
    if not isinstance(raw, dict):
        raise DataFileError(f"{path}: expected a mapping with title, summary and cases, got {type(raw).__name__}")
    try:
        family = CaseFile.model_validate(raw)
    except ValidationError as exc:
        raise DataFileError(f"{path}: {_errors(exc)}") from None
    cases = []
    for index, item in enumerate(family.cases):
        case_id = item.get("id") if isinstance(item, dict) else None
        try:
            cases.append(Case.model_validate(item))
        except ValidationError as exc:
            raise DataFileError(f"{path}: case #{index + 1} {case_id!r}: {_errors(exc)}") from None
    return family.title, cases


def load_cases(folder: Path = CASES_DIR) -> list[tuple[str, Case]]:
    """(title, case) for every case of every family, in the families' order. A case file that no
    family names, or a repeated case or patient id, is an error rather than a silently missing task."""
    unlisted = sorted(p.name for p in folder.glob("*.yaml") if p.stem not in FAMILIES)
    if unlisted:
        raise DataFileError(f"{folder}: case files {unlisted} are not in authoring.FAMILIES {list(FAMILIES)}")
    out: list[tuple[str, Case]] = []
    for stem in FAMILIES:
        title, cases = load_case_file(folder / f"{stem}.yaml")
        out += [(title, case) for case in cases]
    for key in ("id", "patient_id"):
        values = [c.id if key == "id" else c.patient.patient_id for _, c in out]
        repeated = sorted({v for v in values if values.count(v) > 1})
        if repeated:
            raise DataFileError(f"{folder}: repeated case {key}s {repeated}")
    return out


def all_pathways(folder: Path = CASES_DIR) -> list[dict[str, Any]]:
    return [pathway(case, title) for title, case in load_cases(folder)]


def splits(folder: Path = CASES_DIR) -> dict[str, list[str]]:
    """Each case's `split`: one variant of every pathway is held out for test, the others train."""
    cases = [case for _, case in load_cases(folder)]
    return {name: [f"pathway_{c.id}" for c in cases if c.split == name] for name in ("train", "test")}


def render(folder: Path = CASES_DIR) -> dict[str, str]:
    """File name -> content of the two generated files."""
    return {
        "pathways.json": json.dumps(all_pathways(folder), indent=1, ensure_ascii=False) + "\n",
        "split_tasks.json": json.dumps(splits(folder), indent=1) + "\n",
    }


def write(folder: Path = HERE) -> list[Path]:
    written = []
    for name, text in render().items():
        path = folder / name
        path.write_text(text, encoding="utf-8")
        written.append(path)
    return written
