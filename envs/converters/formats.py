"""One converter per public benchmark format.

| format | file | domain | gold |
|---|---|---|---|
| medqa | JSONL: question, answer (text), options {A..} (4 or 5; BigBIO: [{key, value}]), answer_idx, meta_info [, metamap_phrases, realidx] | medical_qa | option letter |
| medmcqa | JSON lines (or the HF parquet): id, question, opa..opd, cop (1-4 as released, 0-3 in the HF layout: detected per file, `cop_base` overrides) | medical_qa | option letter |
| mmlu | original CSV without header (question, A, B, C, D, answer letter); Hugging Face parquet or its CSV export (question, subject, choices [4], answer 0-3) | medical_qa | option letter |
| pubmedqa | JSON {pmid: {QUESTION, CONTEXTS (list, or one string), final_decision, LONG_ANSWER}} | medical_qa | yes / no / maybe as A / B / C |
| medlfqa | JSONL: Question, Free_form_answer, Must_have [..], Nice_to_have [..] | medical_qa | free text + rubric |
| vqa-rad | JSON list: image_name, question, answer, answer_type (CLOSED/OPEN) + image folder | visual_diagnosis | closed: choice between the question's alternatives; open: exact |
| slake | JSON list: img_name, question, answer, answer_type, q_lang + image folder | visual_diagnosis | same |
| pathvqa | official pickled split (`*_vqa.pkl`, read by a restricted reader) or JSON: {image, question, answer} or LXMERT-style {img_id, sent, label {answer: score}} + image folder | visual_diagnosis | same |
| pmc-vqa | CSV: Figure_path, Question, Answer, Choice A..D ("A:text"), Answer_label + image folder | visual_diagnosis | option letter |
| vqa-med-2021 | text: image id, question, answer separated by pipes, one per line + image folder | visual_diagnosis | yes/no choice or exact |
| quilt-vqa | JSON list / lines: image, question, answer, answer_type (closed/open) + image folder | visual_diagnosis | same |
| mimic3 | folder: PATIENTS, ADMISSIONS, ICUSTAYS, LABEVENTS, D_LABITEMS, DIAGNOSES_ICD, D_ICD_DIAGNOSES (.csv/.csv.gz) | ehr_management | tool-computed |
| eicu | folder: patient, lab, diagnosis (.csv/.csv.gz) | ehr_management | tool-computed |

Every file may be UTF-8 with or without a BOM, with LF or CRLF line ends, and gzip-compressed (`.gz`);
record formats (JSON lines / arrays) also read a `.parquet` export of the same records;
other encodings and damaged gzip stop with the file and line (`envs/converters/base.py`). Ids are
`<format>_<hash of everything that makes the task distinct>` (question, options, answer, and the image or
subject where there is one), so they are namespaced by source and two layouts of one question differ.
Image names are resolved inside the image folder (`--image-dir`, default: the dataset file's folder);
a name that escapes it is reported with its row.
"""

from __future__ import annotations

import csv
import gc
import hashlib
import json
import re
import string
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from envs.converters.base import (
    ConversionResult,
    SourceFileError,
    confined_image,
    csv_rows,
    iter_csv,
    iter_json_records,
    iter_jsonl,
    iter_lines,
    read_text,
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
        "raw_answer": options.get(answer),
        "description": {"source": fmt, "task_type": "multiple_choice", "category": "benchmark"},
        "evaluation_criteria": {"reward_basis": ["ANSWER"]},
        "metadata": extra or {},
    }


def _options_key(options: dict[str, str]) -> str:
    """The options as part of an id: MedQA's 4- and 5-option test sets share question and answer letter."""
    return json.dumps(options, sort_keys=True, ensure_ascii=False)


def _empty_options(options: dict[str, str]) -> list[str]:
    return [letter for letter, text in options.items() if not str(text).strip()]


def convert_medqa(path: Path, domain: str = "medical_qa", **_: Any) -> ConversionResult:
    """MedQA (Jin et al. 2021) US files as released: `question`, `answer` (the option text), `options`
    (4 or 5 letters), `answer_idx`, `meta_info`; the 4-option files add `metamap_phrases`, some
    redistributions `realidx`. `answer`, when present, must be the text of option `answer_idx`."""
    result = ConversionResult()
    for line, row in iter_jsonl(path, result):
        missing = require(row, ["question", "options", "answer_idx"])
        if missing:
            result.add_error(path, line, f"missing field {missing!r}")
            continue
        options = row["options"]
        # the BigBIO redistribution writes the options as [{"key": "A", "value": text}, ...]
        if isinstance(options, list) and options and all(isinstance(o, dict) and {"key", "value"} <= o.keys()
                                                         for o in options):
            options = {o["key"]: o["value"] for o in options}
        if not isinstance(options, dict) or not options:
            result.add_error(path, line, "field 'options' must be an object of letter -> text")
            continue
        options = {str(k).strip().upper(): str(v) for k, v in options.items()}
        answer = str(row["answer_idx"]).strip().upper()
        if answer not in options:
            result.add_error(path, line, f"answer_idx {answer!r} is not one of the options {sorted(options)}")
            continue
        if _empty_options(options):
            result.add_error(path, line, f"option(s) {_empty_options(options)} are empty")
            continue
        text = row.get("answer")
        if isinstance(text, str) and text.strip() and text.strip() != options[answer].strip():
            result.add_error(path, line, f"answer {text!r} is not the text of option {answer} "
                                         f"({options[answer]!r}): answer_idx and answer disagree")
            continue
        extra = {"meta_info": row.get("meta_info")}
        if row.get("realidx") is not None:
            extra["realidx"] = row["realidx"]
        _add(result, path, line, _mcq("medqa", row["question"] + answer + _options_key(options), row["question"],
                                      options, answer, domain, extra))
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
    for line, row in iter_json_records(path, result):
        missing = require(row, ["question", *MEDMCQA_OPTION_FIELDS, "cop"])
        if missing:
            result.add_error(path, line, f"missing field {missing!r}")
            continue
        cop = row["cop"]
        # strictly a JSON integer: 2.5, true or "2" mean the file is not what we think it is
        if isinstance(cop, bool) or not isinstance(cop, int):
            result.add_error(path, line, f"field 'cop' must be an integer, got {cop!r} ({type(cop).__name__})")
            continue
        # keep only what the task needs until the base is known: `exp` (explanations) is most of a row
        rows.append((line, {k: row.get(k) for k in ("id", "question", *MEDMCQA_OPTION_FIELDS, "subject_name",
                                                      "topic_name")}, cop))
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


# -- MMLU --------------------------------------------------------------------------------------------
# Original release (Hendrycks et al. 2021, data.tar): one header-less CSV per subject and split,
# `question,A,B,C,D,answer_letter`, fields quoted where they hold commas or newlines.
# Hugging Face `cais/mmlu`: parquet per subject/split with `question`, `subject`, `choices` (list of 4),
# `answer` (int 0-3); its CSV export has the header `question,subject,choices,answer`, `choices` written
# as a Python / JSON list or, from a pandas frame of numpy arrays, as `['a' 'b' 'c' 'd']`.
MMLU_HF_COLUMNS = ("question", "choices", "answer")
_PY_STRING = re.compile(r"""'(?:[^'\\]|\\.)*'|"(?:[^"\\]|\\.)*\"""", re.DOTALL)


def parse_choices(text: str) -> list[str]:
    """A `choices` cell of an MMLU CSV export -> the list of option texts (ValueError if it is not one).

    Accepted: a JSON list, a Python list of string literals (`['a', "b's"]`), and numpy's repr of a string
    array (`['a' 'b']`, no commas: Python would silently concatenate those, so they are split here)."""
    import ast

    cell = text.strip()
    if cell.startswith("[") and cell.endswith("]"):
        try:
            value = json.loads(cell)
            if isinstance(value, list) and all(isinstance(v, str) for v in value):
                return value
        except ValueError:
            pass
        inner = cell[1:-1]
        parts = _PY_STRING.findall(inner)
        separators = [sep.strip() for sep in _PY_STRING.sub("\0", inner).split("\0")]
        between = separators[1:-1]
        if parts and not separators[0] and not separators[-1] and (
                all(sep == "," for sep in between) or all(sep == "" for sep in between)):
            return [ast.literal_eval(part) for part in parts]  # string literals only: never evaluates code
    raise ValueError(f"'choices' is not a list of option texts: {text[:80]!r}")


def _mmlu_row(result: ConversionResult, path: Path, line: int, domain: str, subject: str, question: str,
              choices: list[str], answer: str) -> None:
    if not question.strip():
        result.add_error(path, line, "empty question")
        return
    if len(choices) != 4:
        result.add_error(path, line, f"expected 4 choices, got {len(choices)}")
        return
    options = dict(zip("ABCD", (str(c) for c in choices)))
    if _empty_options(options):
        result.add_error(path, line, f"option(s) {_empty_options(options)} are empty")
        return
    _add(result, path, line, _mcq("mmlu", subject + question + answer + _options_key(options), question, options,
                                  answer, domain, {"subject": subject}))


def _mmlu_hf_answer(value: Any) -> str:
    if isinstance(value, bool):  # JSON true is not an index
        raise ValueError(f"answer must be an integer 0-3, got {value!r}")  # noqa: TRY004 (a row error, not a type bug)
    if isinstance(value, str):
        value = value.strip()
        if value in ("0", "1", "2", "3"):
            return "ABCD"[int(value)]
        if value.upper() in ("A", "B", "C", "D"):
            return value.upper()
        raise ValueError(f"answer must be an integer 0-3, got {value!r}")
    if isinstance(value, int) and 0 <= value <= 3:
        return "ABCD"[value]
    raise ValueError(f"answer must be an integer 0-3, got {value!r}")


def _mmlu_parquet(path: Path, result: ConversionResult, domain: str, subject: str | None) -> None:
    try:
        import pyarrow.parquet as pq
    except ImportError:  # pragma: no cover - pyarrow is a dependency
        raise SourceFileError(f"{path}: reading parquet needs pyarrow (pip install pyarrow)") from None
    try:
        table = pq.read_table(path)
    except (OSError, ValueError) as exc:  # pyarrow's ArrowInvalid / ArrowIOError derive from these
        raise SourceFileError(f"{path}: not a readable parquet file ({type(exc).__name__}: {exc})") from None
    absent = [c for c in MMLU_HF_COLUMNS if c not in table.column_names]
    if absent:
        raise SourceFileError(f"{path}: not an MMLU parquet: columns {absent} missing (found {table.column_names})")
    fallback = subject or _mmlu_subject(path)
    for number, row in enumerate(table.to_pylist(), start=1):
        result.rows_read += 1
        where = f"row {number}"
        try:
            answer = _mmlu_hf_answer(row["answer"])
        except ValueError as exc:
            result.add_error(path, number, f"{where}: {exc}")
            continue
        choices = row["choices"]
        if not isinstance(choices, list):
            result.add_error(path, number, f"{where}: 'choices' is not a list")
            continue
        _mmlu_row(result, path, number, domain, str(row.get("subject") or fallback), str(row["question"] or ""),
                  [str(c) for c in choices], answer)


def _mmlu_subject(path: Path) -> str:
    stem = path.name.removesuffix(".gz").removesuffix(".csv").removesuffix(".parquet")
    for suffix in ("_test", "_dev", "_val", "_validation", "_train", "_auxiliary_train"):
        stem = stem.removesuffix(suffix)
    return stem.removeprefix("test-").removeprefix("validation-").removeprefix("dev-")


def convert_mmlu(path: Path, domain: str = "medical_qa", subject: str | None = None, **_: Any) -> ConversionResult:
    result = ConversionResult()
    if path.name.endswith(".parquet"):
        _mmlu_parquet(path, result, domain, subject)
        return result
    lines = iter_lines(path)
    first = next(lines, None)
    if first is None:
        return result
    header = next(csv.reader([first[1]]), [])
    if [h.strip().lower() for h in header[:1]] == ["question"] and "choices" in [h.strip().lower() for h in header]:
        # the Hugging Face CSV export: a header row, `choices` as a list, `answer` 0-3
        columns = [h.strip().lower() for h in header]
        absent = [c for c in MMLU_HF_COLUMNS if c not in columns]
        if absent:
            raise SourceFileError(f"{path}: MMLU CSV header lacks column(s) {absent} (found {header})")
        fallback = subject or _mmlu_subject(path)
        for line, row, problem in csv_rows(path, lines):
            if row is None:
                result.rows_read += 1
                result.add_error(path, line, problem)
                continue
            if not row or all(not c.strip() for c in row):
                continue
            result.rows_read += 1
            if len(row) != len(columns):
                result.add_error(path, line, f"expected {len(columns)} columns, got {len(row)}")
                continue
            record = dict(zip(columns, row))
            try:
                answer = _mmlu_hf_answer(record["answer"])
                choices = parse_choices(record["choices"])
            except ValueError as exc:
                result.add_error(path, line, str(exc))
                continue
            _mmlu_row(result, path, line, domain, record.get("subject") or fallback, record["question"], choices,
                      answer)
        return result
    subject = subject or _mmlu_subject(path)
    rows = iter_csv(path, result, expected_columns=6, lines=_chain(first, lines))
    for line, row in rows:
        question, *choices, answer = row
        answer = answer.strip().upper()
        if answer not in "ABCD" or len(answer) != 1:
            result.add_error(path, line, f"answer column must be A-D, got {answer!r}")
            continue
        _mmlu_row(result, path, line, domain, subject, question, choices, answer)
    return result


def _chain(first: tuple[int, str], rest: Any) -> Any:
    yield first
    yield from rest


PUBMEDQA_OPTIONS = {"A": "yes", "B": "no", "C": "maybe"}


def convert_pubmedqa(path: Path, domain: str = "medical_qa", **_: Any) -> ConversionResult:
    """PubMedQA `ori_pqal.json` (and the unlabeled/artificial files, which share the layout):
    {pmid: {QUESTION, CONTEXTS [..], LABELS, MESHES, YEAR, reasoning_*_pred, final_decision, LONG_ANSWER}}."""
    result = ConversionResult()
    text = read_text(path)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SourceFileError(f"{path}:{exc.lineno}: not valid JSON at line {exc.lineno} column {exc.colno}: "
                              f"{exc.msg}") from None
    if not isinstance(data, dict):
        raise SourceFileError(f"{path}: expected an object of pmid -> record, got {type(data).__name__}")
    searched = [0, 1]  # (position, line) of the last key found: records are found in file order

    def line_of(pmid: str) -> int:
        at = text.find(json.dumps(pmid), searched[0])
        if at < 0:
            return 0
        searched[1] += text.count("\n", searched[0], at)
        searched[0] = at
        return searched[1]

    for pmid, row in data.items():
        index = line_of(str(pmid))
        result.rows_read += 1
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
        # a redistribution that joined the abstract into one string must not become one line per character
        if isinstance(contexts, str):
            contexts = [contexts]
        if not isinstance(contexts, list):
            result.add_error(path, index, f"record {pmid}: CONTEXTS must be a list of strings or a string")
            continue
        ticket = "Context:\n" + "\n".join(str(c) for c in contexts) + f"\n\nQuestion: {row['QUESTION']}"
        task = _mcq("pubmedqa", str(pmid), ticket, dict(PUBMEDQA_OPTIONS), letter, domain,
                    {"pmid": str(pmid), "long_answer": row.get("LONG_ANSWER")})
        task["raw_question"] = row["QUESTION"]
        _add(result, path, index, task)
    return result


def convert_medlfqa(path: Path, domain: str = "medical_qa", **_: Any) -> ConversionResult:
    """MedLFQA (Jeong et al. 2024, OLAPH): JSON lines `Question`, `Free_form_answer`, `Must_have`, `Nice_to_have`."""
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


# -- VQA -----------------------------------------------------------------------------------------------
def _image_folder(fmt: str, image_dir: str | Path | None, path: Path) -> Path:
    """The folder image names are resolved in: the one given, else the dataset file's own folder."""
    images = Path(image_dir) if image_dir is not None else path.resolve().parent
    if not images.is_dir():
        raise SourceFileError(f"{images}: image folder not found (--image-dir for {fmt})")
    return images


def _item(row: dict[str, Any]) -> str:
    return f"item {row['__item__']}: " if "__item__" in row else ""


_ARTICLES = {"a", "an", "the"}


def _tokens(text: str) -> list[str]:
    """Words as written (case kept), articles left out."""
    return [w for w in re.findall(r"[\w\-+/.]+", text) if w.lower() not in _ARTICLES]


def _words(text: str) -> list[str]:
    return [w.lower() for w in _tokens(text)]


def closed_alternatives(question: str, answer: str) -> list[str] | None:
    """The two alternatives of a closed question "Is this a CT or an MRI?", as the question writes them, when
    the answer is one of them (compared without case and articles).

    The question must hold one " or "; the answer must be the words just before it or just after it; the
    other alternative is as many words on the other side. None otherwise."""
    text = question.strip().rstrip("?.! ")
    parts = re.split(r"\s+or\s+", text, flags=re.IGNORECASE)
    if len(parts) != 2:
        return None
    left, right = _tokens(parts[0]), _tokens(re.split(r"[,;:]", parts[1])[0])
    want = _words(answer)
    n = len(want)
    if not n or n > len(left) or n > len(right):
        return None
    if [w.lower() for w in left[-n:]] == want:
        return [" ".join(left[-n:]), " ".join(right[:n])]
    if [w.lower() for w in right[:n]] == want:
        return [" ".join(left[-n:]), " ".join(right[:n])]
    return None


def _vqa_task(fmt: str, domain: str, name: str, image: Path, question: str, answer: str, answer_type: str,
              metadata: dict[str, Any]) -> dict[str, Any]:
    """A closed question becomes a choice: yes/no, or the two alternatives it names ("left or right?");
    a closed answer that is neither stays a closed question graded on the exact answer; open ones are exact."""
    answer = answer.strip()
    closed = answer.lower() in ("yes", "no") or answer_type.strip().upper() == "CLOSED"
    base = {
        "id": _task_id(fmt, f"{name}|{question}|{answer}"), "domain": domain,
        "ticket": question, "image_path": str(image),
        "description": {"source": fmt, "task_type": "vqa_closed" if closed else "vqa_open"},
        "evaluation_criteria": {"reward_basis": ["ANSWER"]},
        "raw_question": question, "raw_answer": answer,
        "metadata": metadata,
    }
    alternatives = closed_alternatives(question, answer) if closed and answer.lower() not in ("yes", "no") else None
    if closed and answer.lower() in ("yes", "no"):
        base.update(options={"A": "yes", "B": "no"}, correct_answer="A" if answer.lower() == "yes" else "B",
                    answer_type="choice")
    elif alternatives and _words(alternatives[0]) != _words(alternatives[1]):
        letter = "A" if _words(alternatives[0]) == _words(answer) else "B"
        # the gold option is the source's answer text as written; the other as the question writes it
        options = {"A": alternatives[0], "B": alternatives[1], letter: answer}
        base.update(options=options, correct_answer=letter, answer_type="choice")
        base["metadata"] = {**metadata, "closed_alternatives": "from the question"}
    else:
        base.update(correct_answer=answer, answer_type="exact")
    return base


# PathVQA (He et al. 2020, github.com/UCSD-AI4H/PathVQA): the released split files are pickles
# (`qas/train_vqa.pkl`, `val_vqa.pkl`, `test_vqa.pkl`), each a list of dicts; rows are either
# {image, question, answer} or LXMERT-style {img_id, sent, label {answer: score}, question_id, answer_type}.
# They are read by envs/data/safe_pickle.load_plain_pickle, which refuses anything but plain data.
def _pathvqa_fields(row: dict[str, Any]) -> tuple[str | None, str | None, str | None, str]:
    image = row.get("image") if row.get("image") is not None else row.get("img_id")
    question = row.get("question") if row.get("question") is not None else row.get("sent")
    answer = row.get("answer")
    if answer is None and isinstance(row.get("label"), dict) and row["label"]:
        label = row["label"]
        answer = max(label, key=lambda k: (label[k], k))  # the highest-scored answer (PathVQA has one, score 1)
    kind = str(row.get("answer_type") or "")
    if kind.lower() in ("yes/no", "yes_no"):
        kind = "CLOSED"
    return (None if image is None else str(image), None if question is None else str(question),
            None if answer is None else str(answer), kind)


def _pathvqa_rows(path: Path, result: ConversionResult) -> Any:
    if path.name.endswith((".pkl", ".pickle", ".pkl.gz")):
        from envs.data.safe_pickle import load_plain_pickle

        data = load_plain_pickle(_read_bytes(path), source=str(path))
        if isinstance(data, dict):  # some copies key the rows by question id
            data = list(data.values())
        if not isinstance(data, list):
            raise SourceFileError(f"{path}: expected a pickled list of question records, got {type(data).__name__}")
        for index, row in enumerate(data, start=1):
            result.rows_read += 1
            if not isinstance(row, dict):
                result.add_error(path, index, f"record {index}: expected a dict, got {type(row).__name__}")
                continue
            yield index, {**row, "__item__": index}
        return
    yield from iter_json_records(path, result)


def _read_bytes(path: Path) -> bytes:
    import gzip
    import zlib

    if not path.is_file():
        raise SourceFileError(f"{path}: file not found")
    try:
        return gzip.decompress(path.read_bytes()) if path.name.endswith(".gz") else path.read_bytes()
    except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
        raise SourceFileError(f"{path}: damaged or truncated gzip file ({type(exc).__name__}: {exc})") from None


def _vqa(fmt: str, image_key: str, *, lang_key: str | None = None) -> Callable[..., ConversionResult]:
    def convert(path: Path, domain: str = "visual_diagnosis", image_dir: str | Path | None = None,
                **_: Any) -> ConversionResult:
        images = _image_folder(fmt, image_dir, path)
        result = ConversionResult()
        rows = _pathvqa_rows(path, result) if fmt == "pathvqa" else iter_json_records(path, result)
        skipped: dict[str, int] = {}
        for line, row in rows:
            item = _item(row)
            if lang_key and row.get(lang_key, "en") != "en":
                language = str(row.get(lang_key))
                skipped[language] = skipped.get(language, 0) + 1
                continue  # SLAKE is bilingual; we keep the English questions
            if fmt == "pathvqa":
                name, question, answer, kind = _pathvqa_fields(row)
                if name is None or not question or answer is None or not answer.strip():
                    missing = "image" if name is None else "question" if not question else "answer"
                    result.add_error(path, line, f"{item}missing field {missing!r}")
                    continue
            else:
                missing = require(row, [image_key, "question", "answer"])
                if missing:
                    result.add_error(path, line, f"{item}missing field {missing!r}")
                    continue
                name, question, answer, kind = (str(row[image_key]), str(row["question"]), str(row["answer"]),
                                                str(row.get("answer_type", "")))
            image, problem = confined_image(images, name)
            if image is None:
                result.add_error(path, line, f"{item}{problem}")
                continue
            metadata = {k: row[k] for k in ("qid", "question_id", "question_type", "modality", "location",
                                            "content_type") if k in row}
            _add(result, path, line, _vqa_task(fmt, domain, name, image, question, answer, kind, metadata))
        for language, count in sorted(skipped.items()):
            result.notes.append(f"{path}: {count} question(s) with {lang_key} {language!r} skipped (English only)")
        return result

    return convert


# PMC-VQA (Zhang et al. 2023), as distributed at huggingface.co/datasets/xmcmic/PMC-VQA (README "Sample"):
# `train.csv` / `test.csv` / `test_clean.csv` (and the v2 `train2.csv` / `test2.csv`) with the header
# Figure_path,Question,Answer,Choice A,Choice B,Choice C,Choice D,Answer_label; each choice carries its
# letter as a prefix ("B:Focal uptake pattern"); Figure_path names a file of images.zip.
PMC_VQA_COLUMNS = ("Figure_path", "Question", "Choice A", "Choice B", "Choice C", "Choice D", "Answer_label")
_CHOICE_PREFIX = re.compile(r"^\s*([A-D])\s*[:.)]\s*")


def convert_pmc_vqa(path: Path, domain: str = "visual_diagnosis", image_dir: str | Path | None = None,
                    **_: Any) -> ConversionResult:
    images = _image_folder("pmc-vqa", image_dir, path)
    result = ConversionResult()
    records = csv_rows(path)
    first = next(records, None)
    header = [h.strip() for h in first[1]] if first and first[1] else []
    absent = [c for c in PMC_VQA_COLUMNS if c not in header]
    if absent:
        raise SourceFileError(f"{path}: not a PMC-VQA CSV: header lacks column(s) {absent} (found {header})")
    for line, cells, problem in records:
        if cells is None:
            result.rows_read += 1
            result.add_error(path, line, problem)
            continue
        if not cells or all(not c.strip() for c in cells):
            continue
        result.rows_read += 1
        if len(cells) != len(header):
            result.add_error(path, line, f"expected {len(header)} columns, got {len(cells)}")
            continue
        row = dict(zip(header, cells))
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
        image, problem = confined_image(images, row["Figure_path"].strip())
        if image is None:
            result.add_error(path, line, problem)
            continue
        _add(result, path, line, {
            "id": _task_id("pmc-vqa", f"{row['Figure_path']}|{row['Question']}|{label}|{_options_key(options)}"),
            "domain": domain, "ticket": row["Question"].strip(), "image_path": str(image), "options": options,
            "correct_answer": label, "answer_type": "choice", "raw_answer": (row.get("Answer") or "").strip(),
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
    images = _image_folder("vqa-med-2021", image_dir, path)
    result = ConversionResult()
    for line, text in iter_lines(path):
        if not text.strip():
            continue
        result.rows_read += 1
        fields = [f.strip() for f in text.rstrip("\r\n").split("|")]
        if len(fields) != 3:
            result.add_error(path, line, f"expected 3 '|'-separated fields (image id|question|answer), got {len(fields)}")
            continue
        image_id, question, answer = fields
        if not image_id or not question or not answer:
            result.add_error(path, line, "empty image id, question or answer")
            continue
        image, problem = confined_image(images, image_id)
        if image is None:
            result.add_error(path, line, problem)
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


@contextmanager
def cyclic_gc_paused() -> Iterator[None]:
    """Pause Python's cyclic garbage collector while a file converts.

    A converter keeps every task it makes alive until it returns (183k for MedMCQA's train set), and each
    full collection rescans all of them: on 60,000 MedMCQA rows that was 7.6 s of 7.6 s + 2.9 s
    (bench/converters.py). Tasks and rows hold no reference cycles, so nothing is left uncollected; reference
    counting frees as usual, and the collector runs again as soon as the conversion returns."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def convert(fmt: str, path: str | Path, **options: Any) -> ConversionResult:
    """Convert a benchmark file; raises SourceFileError when the whole file cannot be read."""
    if fmt not in CONVERTERS:
        raise ValueError(f"unknown format {fmt!r}; supported: {', '.join(sorted(CONVERTERS))} (and 'reference')")
    with cyclic_gc_paused():
        return CONVERTERS[fmt](Path(path), **{k: v for k, v in options.items() if v is not None})
