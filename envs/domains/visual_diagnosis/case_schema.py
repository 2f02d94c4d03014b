"""The authored visual-diagnosis cases: the schema of a case file (`cases/<family>.json`) and its loader.

A case is one authored workflow: the study to render (the patient, the indication, the finding with
its side and zone, or the CT nodules with their prior sizes), the ticket, the gold answer, the gold
tool calls, the NL assertions, the category (whose guideline the file names) and the reasoning a
complete gold submission gives. Every model is strict: an unknown or misspelt key, a wrong type or a
missing field is a `DataFileError` naming the file, the case (`case #2 'vis_a_pneumonia'`) and the
field (`image.side`).

Values only the rendered image fixes are written as template fields, `{name}` or `{name:format}` (e.g.
`"{cardiothoracic_ratio:.2f}"`), in the answer, the aliases and the tool-call arguments; a string
that is exactly one `{name}` stands for the value itself (a number stays a number). `VALUES` lists
the names each modality offers; `generate.authored` fills them in.
"""

from __future__ import annotations

import string
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, ValidationError, model_validator

from envs.core.db import DataFileError, format_validation_error, read_json_file
from envs.core.models import StrictModel

CASES_DIR = Path(__file__).resolve().parent / "cases"
Number = int | float  # keeps the form written (0 stays 0, 1.0 stays 1.0), so the task reads as the case does

# The template fields ({name} in a case's strings) each image fills, with the measured value each stands for.
VALUES: dict[str, dict[str, str]] = {
    "radiograph": {
        "cardiothoracic_ratio": "the rendered cardiothoracic ratio",
        "lesion_diameter_mm": "the rendered nodule or mass diameter (mm)",
        "lesion_x": "the lesion centroid's image column (pixels)",
        "lesion_y": "the lesion centroid's image row (pixels)",
    },
    "ct": {
        "first_nodule_side": "the side the first nodule of the plan was placed on",
        "mean_diameter_change_mm": "the first nodule's mean diameter now minus on the prior (mm, 1 decimal)",
        "fleischner_recommendation": "envs.calculators' Fleischner 2017 category for the first nodule, the nodule "
                                     "count and the patient's risk",
    },
    "any": {
        "known_malignancy_management": "envs.domains.imaging_guidelines.KNOWN_MALIGNANCY_MANAGEMENT",
        "known_malignancy_aliases": "envs.domains.imaging_guidelines.KNOWN_MALIGNANCY_ALIASES (a list)",
    },
}
_FORMATTER = string.Formatter()


def placeholders(value: Any) -> set[str]:
    """The template field names ({name}) in a string, or in the strings of a list or mapping."""
    if isinstance(value, str):
        try:
            return {name for _, name, _, _ in _FORMATTER.parse(value) if name is not None}
        except ValueError as exc:  # an unmatched brace
            raise ValueError(f"{value!r}: {exc}") from None
    if isinstance(value, dict):
        return set().union(*(placeholders(v) for v in value.values()))
    if isinstance(value, list):
        return set().union(*(placeholders(v) for v in value))
    return set()


def fill(value: Any, values: dict[str, Any]) -> Any:
    """`value` with its template fields filled from `values`; a string that is exactly one `{name}` becomes
    the value itself."""
    if isinstance(value, dict):
        return {k: fill(v, values) for k, v in value.items()}
    if isinstance(value, list):
        return [fill(v, values) for v in value]
    if not isinstance(value, str) or not placeholders(value):
        return value
    parts = list(_FORMATTER.parse(value))
    if len(parts) == 1 and parts[0][0] == "" and not parts[0][2] and parts[0][3] is None:
        return values[parts[0][1]]
    return value.format(**values)


class Patient(StrictModel):
    age: int = Field(ge=0, le=120)
    sex: Literal["female", "male"]
    history: str
    pack_years: float = Field(default=0.0, ge=0)  # >= 10 is a high lung-cancer risk (Fleischner 2017)
    symptoms: list[str] = Field(default_factory=list)
    known_malignancy: str | None = None


class Radiograph(StrictModel):
    """A PA chest radiograph with one finding (side and zone drawn at random where not given)."""

    modality: Literal["radiograph"]
    finding: Literal["normal", "nodule", "mass", "consolidation", "pleural effusion", "pneumothorax", "cardiomegaly"]
    side: Literal["right", "left"] | None = None
    zone: Literal["upper", "middle", "lower"] | None = None
    # The finding and cardiomegaly on one film (CTR 0.57-0.62).
    with_cardiomegaly: bool = False

    @model_validator(mode="after")
    def _second_finding(self) -> Radiograph:
        if self.with_cardiomegaly and self.finding in ("normal", "cardiomegaly"):
            raise ValueError(f"with_cardiomegaly needs a second finding, not {self.finding!r}")
        return self


class Nodule(StrictModel):
    type: Literal["solid", "part_solid", "ground_glass"]
    mean_mm: float = Field(gt=0, le=30)


class ChestCT(StrictModel):
    """An axial chest CT slice with its nodules; `prior_mean_mm` (one entry per nodule, null: absent
    on the prior) adds a prior study 12 months earlier."""

    modality: Literal["ct"]
    nodules: list[Nodule] = Field(min_length=1)
    prior_mean_mm: list[float | None] | None = None

    @model_validator(mode="after")
    def _prior_per_nodule(self) -> ChestCT:
        if self.prior_mean_mm is not None and len(self.prior_mean_mm) != len(self.nodules):
            raise ValueError(f"prior_mean_mm has {len(self.prior_mean_mm)} entries for {len(self.nodules)} nodules")
        return self


class Action(StrictModel):
    name: str
    arguments: dict[str, Any]
    compare_args: list[str] | None = None  # omitted: every argument is compared


class Case(StrictModel):
    id: str = Field(pattern=r"^vis_a_[a-z0-9_]+$")
    study_id: str = Field(pattern=r"^VIS-\d{3}$")
    patient: Patient
    indication: str
    image: Radiograph | ChestCT = Field(discriminator="modality")
    ticket: str
    answer: str
    answer_type: Literal["exact", "numeric", "choice"]
    options: dict[str, str] | None = None
    answer_unit: str | None = None
    answer_tolerance: Number | None = None
    answer_aliases: list[str] | str | None = None  # a string: one template field that fills in a list
    emergency: str | None = None
    actions: list[Action] = Field(min_length=1)
    assertions: list[str] = Field(min_length=1)
    category: str
    gold_reasoning: str | None = None

    @model_validator(mode="after")
    def _known_placeholders(self) -> Case:
        offered = {**VALUES[self.image.modality], **VALUES["any"]}
        fields = {"answer": self.answer, "answer_aliases": self.answer_aliases,
                  **{f"actions.{i}.arguments": a.arguments for i, a in enumerate(self.actions)}}
        for field, value in fields.items():
            unknown = sorted(placeholders(value) - set(offered))
            if unknown:
                raise ValueError(f"{field}: placeholder(s) {unknown} are not values a {self.image.modality} offers "
                                 f"({', '.join(sorted(offered))})")
        if isinstance(self.answer_aliases, str) and placeholders(self.answer_aliases) != {"known_malignancy_aliases"}:
            raise ValueError("answer_aliases: a list of strings, or the template field '{known_malignancy_aliases}'")
        return self


class CaseFile(StrictModel):
    title: str
    # category -> the guideline or reference its cases follow (the tasks' provenance)
    guidelines: dict[str, str] = Field(min_length=1)
    cases: list[dict[str, Any]] = Field(min_length=1)  # each validated as a `Case`, so an error names the case


def load_case_file(path: Path) -> list[tuple[Case, str]]:
    """(case, the guideline its category follows) for each case of one case file; a bad file raises
    `DataFileError` naming the file, the case (index and id) and the field."""
    family = _validated(CaseFile, read_json_file(path, "case file", refuse_repeated_keys=True), str(path))
    cases = []
    for index, item in enumerate(family.cases, 1):
        where = f"case #{index} {item.get('id') if isinstance(item, dict) else None!r}"
        case = _validated(Case, item, str(path), where)
        if case.category not in family.guidelines:
            raise DataFileError(f"{path} [{where}] field 'category': {case.category!r} is not among the file's "
                                f"guidelines ({', '.join(family.guidelines)})")
        cases.append((case, family.guidelines[case.category]))
    return cases


def load_cases(folder: Path = CASES_DIR) -> list[tuple[Case, str]]:
    """(case, guideline) for every case file, in study-id order: the images are drawn from one seeded
    stream in that order, so a new case takes the next study id and leaves the others' images unchanged.
    A repeated case or study id is an error naming both files."""
    out: list[tuple[Case, str, Path]] = []
    for path in sorted(folder.glob("*.json")):
        out += [(case, guideline, path) for case, guideline in load_case_file(path)]
    if not out:
        raise DataFileError(f"{folder}: no case files (*.json)")
    for key in ("id", "study_id"):
        first: dict[str, Path] = {}
        for case, _, path in out:
            value = getattr(case, key)
            if value in first:
                raise DataFileError(f"{path}: case {key} {value!r} is already in {first[value]}")
            first[value] = path
    return [(case, guideline) for case, guideline, _ in sorted(out, key=lambda item: item[0].study_id)]


def _validated(model: type[StrictModel], raw: Any, source: str, item: str | None = None) -> Any:
    try:
        return model.model_validate(raw)
    except ValidationError as exc:
        raise DataFileError(format_validation_error(exc, source=source, item=item)) from None
