"""One converter per public benchmark format.

| format | file | domain | gold |
|---|---|---|---|
| medqa | JSONL: question, options {A..}, answer_idx | medical_qa | option letter |
| medmcqa | JSON lines: id, question, opa..opd, cop (1-4 as released, 0-3 in the HF layout: detected per file, `cop_base` overrides) | medical_qa | option letter |
| mmlu | CSV without header: question, A, B, C, D, answer letter | medical_qa | option letter |
| pubmedqa | JSON {pmid: {QUESTION, CONTEXTS, final_decision, LONG_ANSWER}} | medical_qa | yes / no / maybe as A / B / C |
| medlfqa | JSONL: Question, Free_form_answer, Must_have [..], Nice_to_have [..] | medical_qa | free text + rubric |
| vqa-rad | JSON list: image_name, question, answer, answer_type (CLOSED/OPEN) + image folder | visual_diagnosis | yes/no choice or exact |
| slake | JSON list: img_name, question, answer, answer_type, q_lang + image folder | visual_diagnosis | same |
| pathvqa | JSON list: image, question, answer + image folder | visual_diagnosis | same |
| pmc-vqa | CSV: Figure_path, Question, Answer, Choice A..D ("A:text"), Answer_label + image folder | visual_diagnosis | option letter |
| vqa-med-2021 | text: image id, question, answer separated by pipes, one per line + image folder | visual_diagnosis | yes/no choice or exact |
| quilt-vqa | JSON list / lines: image, question, answer, answer_type (closed/open) + image folder | visual_diagnosis | same |
| mimic3 | folder: PATIENTS, ADMISSIONS, ICUSTAYS, LABEVENTS, D_LABITEMS, DIAGNOSES_ICD, D_ICD_DIAGNOSES (.csv/.csv.gz) | ehr_management | tool-computed |
| eicu | folder: patient, lab, diagnosis (.csv/.csv.gz) | ehr_management | tool-computed |
"""

from __future__ import annotations

import csv
import hashlib
import json
import re
import string
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from envs.converters.base import (
    ConversionResult,
    SourceFileError,
    iter_csv,
    iter_json_records,
    iter_jsonl,
    load_json,
    require,
)
from envs.core.task import Task

LETTERS = string.ascii_uppercase


def _task_id(fmt: str, key: str) -> str:
    return f"{fmt}_{hashlib.sha256(key.encode('utf-8')).hexdigest()[:12]}"


def _add(result: ConversionResult, path: Path, line: int, data: dict[str, Any]) -> None:
    try:
        result.tasks.append(Task.model_validate(data))
    except ValidationError as exc:
        problems = "; ".join(f"{'.'.join(map(str, e['loc'])) or 'task'}: {e['msg']}" for e in exc.errors())
        result.add_error(path, line, problems)


def _mcq(fmt: str, key: str, question: str, options: dict[str, str], answer: str, domain: str,
         extra: dict[str, Any] | None = None) -> dict[str, Any]:
    return {
        "id": _task_id(fmt, key), "domain": domain, "ticket": question.strip(), "options": options,
        "correct_answer": answer, "answer_type": "choice", "raw_question": question,
        "description": {"source": fmt, "task_type": "multiple_choice", "category": "benchmark"},
        "evaluation_criteria": {"reward_basis": ["ANSWER"]},
        "metadata": extra or {},
    }


def _options_key(options: dict[str, str]) -> str:
    """The options as part of an id: MedQA's 4- and 5-option test sets share question and answer letter."""
    return json.dumps(options, sort_keys=True, ensure_ascii=False)


def convert_medqa(path: Path, domain: str = "medical_qa", **_: Any) -> ConversionResult:
    result = ConversionResult()
    for line, row in iter_jsonl(path, result):
        missing = require(row, ["question", "options", "answer_idx"])
        if missing:
            result.add_error(path, line, f"missing field {missing!r}")
            continue
        options = row["options"]
        if not isinstance(options, dict) or not options:
            result.add_error(path, line, "field 'options' must be an object of letter -> text")
            continue
        answer = str(row["answer_idx"]).strip().upper()
        if answer not in options:
            result.add_error(path, line, f"answer_idx {answer!r} is not one of the options {sorted(options)}")
            continue
        options = {str(k): str(v) for k, v in options.items()}
        _add(result, path, line, _mcq("medqa", row["question"] + answer + _options_key(options), row["question"],
                                      options, answer, domain,
                                      {"meta_info": row.get("meta_info")}))
    return result


MEDMCQA_OPTION_FIELDS = ("opa", "opb", "opc", "opd")


def _medmcqa_base(cops: list[int], path: Path, cop_base: int | None, result: ConversionResult) -> int:
    """The file's `cop` numbering: the original release counts 1-4, the Hugging Face layout 0-3.

    Nothing in a row says which; the file does (a 0 only occurs 0-based, a 4 only 1-based). An explicit
    `cop_base` wins. A file with neither is ambiguous: we assume the original 1-4 and say so in the notes.
    """
    if cop_base is not None:
        if cop_base not in (0, 1):
            raise ValueError(f"--cop-base must be 0 or 1, got {cop_base!r}")
        result.notes.append(f"{path}: MedMCQA 'cop' read as {cop_base}-based (set by --cop-base)")
        return cop_base
    if 0 in cops:
        clash = " (it also has a 4: those rows are reported out of range)" if 4 in cops else ""
        result.notes.append(f"{path}: MedMCQA 'cop' read as 0-based (0-3, Hugging Face layout): the file has a cop of 0"
                            + clash)
        return 0
    if 4 in cops:
        result.notes.append(f"{path}: MedMCQA 'cop' read as 1-based (1-4, original release): the file has a cop of 4")
        return 1
    result.notes.append(f"{path}: MedMCQA 'cop' base cannot be told from the file (no 0 and no 4): ASSUMED 1-based "
                        "(1-4, original release); pass --cop-base 0 if it is the Hugging Face 0-3 layout")
    return 1


def convert_medmcqa(path: Path, domain: str = "medical_qa", cop_base: int | None = None, **_: Any) -> ConversionResult:
    result = ConversionResult()
    rows: list[tuple[int, dict[str, Any], int]] = []
    for line, row in iter_jsonl(path, result):
        missing = require(row, ["question", *MEDMCQA_OPTION_FIELDS, "cop"])
        if missing:
            result.add_error(path, line, f"missing field {missing!r}")
            continue
        cop = row["cop"]
        # strictly a JSON integer: 2.5, true or "2" mean the file is not what we think it is
        if isinstance(cop, bool) or not isinstance(cop, int):
            result.add_error(path, line, f"field 'cop' must be an integer, got {cop!r} ({type(cop).__name__})")
            continue
        rows.append((line, row, cop))
    base = _medmcqa_base([cop for _, _, cop in rows], path, cop_base, result)
    for line, row, cop in rows:
        index = cop - base
        if not 0 <= index <= 3:
            result.add_error(path, line, f"field 'cop' {cop!r} out of range {base}..{base + 3}")
            continue
        options = {LETTERS[i]: str(row[k]) for i, k in enumerate(MEDMCQA_OPTION_FIELDS)}
        key = str(row.get("id") or row["question"]) + _options_key(options)
        _add(result, path, line, _mcq("medmcqa", key, row["question"], options, LETTERS[index], domain,
                                      {"subject": row.get("subject_name"), "topic": row.get("topic_name"),
                                       "cop_base": base}))
    return result


def convert_mmlu(path: Path, domain: str = "medical_qa", subject: str | None = None, **_: Any) -> ConversionResult:
    result = ConversionResult()
    subject = subject or path.stem.removesuffix("_test").removesuffix("_dev").removesuffix("_val")
    for line, row in iter_csv(path, result, expected_columns=6):
        question, *choices, answer = row
        answer = answer.strip().upper()
        if answer not in "ABCD" or len(answer) != 1:
            result.add_error(path, line, f"answer column must be A-D, got {answer!r}")
            continue
        options = dict(zip("ABCD", choices))
        _add(result, path, line, _mcq("mmlu", subject + question + answer + _options_key(options), question, options, answer, domain,
                                      {"subject": subject}))
    return result


PUBMEDQA_OPTIONS = {"A": "yes", "B": "no", "C": "maybe"}


def convert_pubmedqa(path: Path, domain: str = "medical_qa", **_: Any) -> ConversionResult:
    result = ConversionResult()
    data = load_json(path)
    if not isinstance(data, dict):
        raise SourceFileError(f"{path}: expected an object of pmid -> record, got {type(data).__name__}")
    for index, (pmid, row) in enumerate(data.items(), start=1):
        if not isinstance(row, dict):
            result.add_error(path, index, f"record {pmid}: expected an object")
            continue
        missing = require(row, ["QUESTION", "final_decision"])
        if missing:
            result.add_error(path, index, f"record {pmid}: missing field {missing!r}")
            continue
        decision = str(row["final_decision"]).strip().lower()
        letter = {v: k for k, v in PUBMEDQA_OPTIONS.items()}.get(decision)
        if letter is None:
            result.add_error(path, index, f"record {pmid}: final_decision must be yes/no/maybe, got {decision!r}")
            continue
        contexts = row.get("CONTEXTS") or []
        ticket = "Context:\n" + "\n".join(str(c) for c in contexts) + f"\n\nQuestion: {row['QUESTION']}"
        task = _mcq("pubmedqa", str(pmid), ticket, dict(PUBMEDQA_OPTIONS), letter, domain,
                    {"pmid": str(pmid), "long_answer": row.get("LONG_ANSWER")})
        task["raw_question"] = row["QUESTION"]
        _add(result, path, index, task)
    return result


def convert_medlfqa(path: Path, domain: str = "medical_qa", **_: Any) -> ConversionResult:
    result = ConversionResult()
    for line, row in iter_jsonl(path, result):
        missing = require(row, ["Question", "Free_form_answer"])
        if missing:
            result.add_error(path, line, f"missing field {missing!r}")
            continue
        must = [str(s) for s in row.get("Must_have") or []]
        nice = [str(s) for s in row.get("Nice_to_have") or []]
        rubric = [{"criterion": s, "points": 2.0, "tags": ["must_have"]} for s in must]
        rubric += [{"criterion": s, "points": 1.0, "tags": ["nice_to_have"]} for s in nice]
        _add(result, path, line, {
            "id": _task_id("medlfqa", row["Question"]), "domain": domain, "ticket": row["Question"],
            "answer_type": "free_text", "correct_answer": row["Free_form_answer"],
            "description": {"source": "medlfqa", "task_type": "long_form"},
            "evaluation_criteria": {"nl_assertions": must, "rubric": rubric,
                                    "reward_basis": ["ANSWER", "NL_ASSERTION", "RUBRIC"]},
            # MedLFQA ships one file per benchmark (live_qa, medication_qa, healthsearch_qa, kqa_golden,
            # kqa_silver_wogold) in one format: the file name is what tells them apart for eval suites
            "metadata": {"subset": path.stem},
        })
    return result


def _vqa(fmt: str, image_key: str, *, lang_key: str | None = None) -> Callable[..., ConversionResult]:
    def convert(path: Path, domain: str = "visual_diagnosis", image_dir: str | Path | None = None,
                **_: Any) -> ConversionResult:
        if image_dir is None:
            raise SourceFileError(f"{fmt}: pass the image folder (--image-dir) that the JSON's {image_key!r} names refer to")
        images = Path(image_dir)
        if not images.is_dir():
            raise SourceFileError(f"{images}: image folder not found")
        result = ConversionResult()
        for line, row in iter_json_records(path, result):
            if lang_key and row.get(lang_key, "en") != "en":
                continue  # SLAKE is bilingual; we keep the English questions
            missing = require(row, [image_key, "question", "answer"])
            if missing:
                result.add_error(path, line, f"missing field {missing!r}")
                continue
            name = str(row[image_key])
            candidates = [images / name] + [images / f"{name}{ext}" for ext in (".jpg", ".png", ".jpeg")]
            image = next((c for c in candidates if c.is_file()), None)
            if image is None:
                result.add_error(path, line, f"image {name!r} not found in {images}")
                continue
            metadata = {k: row[k] for k in ("qid", "question_type", "modality", "location", "content_type") if k in row}
            _add(result, path, line, _vqa_task(fmt, domain, name, image, str(row["question"]), str(row["answer"]),
                                               str(row.get("answer_type", "")), metadata))
        return result

    return convert


def _find_image(images: Path, name: str) -> Path | None:
    candidates = [images / name] + [images / f"{name}{ext}" for ext in (".jpg", ".png", ".jpeg")]
    return next((c for c in candidates if c.is_file()), None)


def _image_folder(fmt: str, image_dir: str | Path | None, what: str) -> Path:
    if image_dir is None:
        raise SourceFileError(f"{fmt}: pass the image folder (--image-dir) that the file's {what} refer to")
    images = Path(image_dir)
    if not images.is_dir():
        raise SourceFileError(f"{images}: image folder not found")
    return images


def _vqa_task(fmt: str, domain: str, name: str, image: Path, question: str, answer: str, answer_type: str,
              metadata: dict[str, Any]) -> dict[str, Any]:
    """A yes/no answer (or a CLOSED one) becomes a two-option choice; anything else an exact-match answer."""
    answer = answer.strip()
    closed = answer.lower() in ("yes", "no") or answer_type.upper() == "CLOSED"
    base = {
        "id": _task_id(fmt, f"{name}|{question}|{answer}"), "domain": domain,
        "ticket": question, "image_path": str(image.resolve()),
        "description": {"source": fmt, "task_type": "vqa_closed" if closed else "vqa_open"},
        "evaluation_criteria": {"reward_basis": ["ANSWER"]},
        "metadata": metadata,
    }
    if closed and answer.lower() in ("yes", "no"):
        base.update(options={"A": "yes", "B": "no"}, correct_answer="A" if answer.lower() == "yes" else "B",
                    answer_type="choice")
    else:
        base.update(correct_answer=answer, answer_type="exact")
    return base


# PMC-VQA (Zhang et al. 2023), as distributed at huggingface.co/datasets/xmcmic/PMC-VQA (README "Sample"):
# `train.csv` / `test.csv` / `test_clean.csv` (and the v2 `train2.csv` / `test2.csv`) with the header
# Figure_path,Question,Answer,Choice A,Choice B,Choice C,Choice D,Answer_label; each choice carries its
# letter as a prefix ("B:Focal uptake pattern"); Figure_path names a file of images.zip.
PMC_VQA_COLUMNS = ("Figure_path", "Question", "Choice A", "Choice B", "Choice C", "Choice D", "Answer_label")
_CHOICE_PREFIX = re.compile(r"^\s*([A-D])\s*[:.)]\s*")


def convert_pmc_vqa(path: Path, domain: str = "visual_diagnosis", image_dir: str | Path | None = None,
                    **_: Any) -> ConversionResult:
    images = _image_folder("pmc-vqa", image_dir, "'Figure_path' names")
    if not path.exists():
        raise SourceFileError(f"{path}: file not found")
    result = ConversionResult()
    # utf-8-sig: a file saved by a spreadsheet tool starts with a BOM that would rename the first column
    with path.open(encoding="utf-8-sig", newline="") as handle:
        reader = csv.DictReader(handle)
        header = reader.fieldnames or []
        absent = [c for c in PMC_VQA_COLUMNS if c not in header]
        if absent:
            raise SourceFileError(f"{path}: not a PMC-VQA CSV: header lacks column(s) {absent} (found {header})")
        for row in reader:
            line = reader.line_num
            missing = require(row, ["Figure_path", "Question", "Answer_label"])
            if missing:
                result.add_error(path, line, f"missing field {missing!r}")
                continue
            options = {}
            for letter in "ABCD":
                text = (row.get(f"Choice {letter}") or "").strip()
                if text:
                    options[letter] = _CHOICE_PREFIX.sub("", text, count=1).strip()
            label = row["Answer_label"].strip().upper()
            if label not in options:
                result.add_error(path, line, f"Answer_label {label!r} is not one of the choices {sorted(options)}")
                continue
            image = _find_image(images, row["Figure_path"].strip())
            if image is None:
                result.add_error(path, line, f"image {row['Figure_path']!r} not found in {images}")
                continue
            _add(result, path, line, {
                "id": _task_id("pmc-vqa", f"{row['Figure_path']}|{row['Question']}|{label}"), "domain": domain,
                "ticket": row["Question"].strip(), "image_path": str(image.resolve()), "options": options,
                "correct_answer": label, "answer_type": "choice",
                "description": {"source": "pmc-vqa", "task_type": "vqa_choice"},
                "evaluation_criteria": {"reward_basis": ["ANSWER"]},
                "metadata": {"figure": row["Figure_path"].strip(), "answer_text": (row.get("Answer") or "").strip()},
            })
    return result


# VQA-Med 2021 (ImageCLEF, github.com/abachaa/VQA-Med-2021): the QA files are plain text, one
# pipe-separated line per question, `<image id>|<question>|<answer>` (the 2020 training set and the
# 2021 validation set, e.g. VQA-Med-2021-VQAnswering-Task1-New-ValidationSet.txt, and the test set
# with ground truth); the image id names `<image id>.jpg` in the images folder.
def convert_vqa_med_2021(path: Path, domain: str = "visual_diagnosis", image_dir: str | Path | None = None,
                         **_: Any) -> ConversionResult:
    images = _image_folder("vqa-med-2021", image_dir, "image ids")
    if not path.exists():
        raise SourceFileError(f"{path}: file not found")
    result = ConversionResult()
    with path.open(encoding="utf-8-sig") as handle:
        for line, text in enumerate(handle, start=1):
            if not text.strip():
                continue
            fields = [f.strip() for f in text.rstrip("\r\n").split("|")]
            if len(fields) != 3:
                result.add_error(path, line, f"expected 3 '|'-separated fields (image id|question|answer), got {len(fields)}")
                continue
            image_id, question, answer = fields
            if not image_id or not question or not answer:
                result.add_error(path, line, "empty image id, question or answer")
                continue
            image = _find_image(images, image_id)
            if image is None:
                result.add_error(path, line, f"image {image_id!r} not found in {images}")
                continue
            _add(result, path, line, _vqa_task("vqa-med-2021", domain, image_id, image, question, answer, "",
                                               {"image_id": image_id}))
    return result


def _ehr(name: str) -> Callable[..., ConversionResult]:
    def convert(path: Path, **options: Any) -> ConversionResult:
        from envs.converters import ehr  # imported on use: it pulls in the EHR domain

        return getattr(ehr, name)(path, **options)

    return convert


CONVERTERS: dict[str, Callable[..., ConversionResult]] = {
    "medqa": convert_medqa,
    "medmcqa": convert_medmcqa,
    "mmlu": convert_mmlu,
    "pubmedqa": convert_pubmedqa,
    "medlfqa": convert_medlfqa,
    "vqa-rad": _vqa("vqa-rad", "image_name"),
    "slake": _vqa("slake", "img_name", lang_key="q_lang"),
    "pathvqa": _vqa("pathvqa", "image"),
    "pmc-vqa": convert_pmc_vqa,
    "vqa-med-2021": convert_vqa_med_2021,
    # Quilt-VQA (Seyfioglu et al. 2024, huggingface.co/datasets/wisdomik/Quilt_VQA, 985 test rows): records
    # `image`, `question`, `answer`, `answer_type` ("closed" / "open"), `context`, as a JSON list or lines
    "quilt-vqa": _vqa("quilt-vqa", "image"),
    "mimic3": _ehr("convert_mimic3"),
    "eicu": _ehr("convert_eicu"),
}


def convert(fmt: str, path: str | Path, **options: Any) -> ConversionResult:
    """Convert a benchmark file; raises SourceFileError when the whole file cannot be read."""
    if fmt not in CONVERTERS:
        raise ValueError(f"unknown format {fmt!r}; supported: {', '.join(sorted(CONVERTERS))} (and 'reference')")
    return CONVERTERS[fmt](Path(path), **{k: v for k, v in options.items() if v is not None})
