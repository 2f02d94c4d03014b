"""Every converter on every official layout (../shared/reference/benchmark_layouts.md), written here
row by row in the shapes the datasets are distributed in (never the datasets themselves).

The round-trip rule for each converter: the text of the gold option (or the gold answer) equals the
answer text the source gives for that row, so no import can be silently one letter off. Then the
files as users really have them: a BOM, CRLF, gzip, Latin-1, truncated gzip, damaged JSON arrays,
image names that try to leave the image folder, and MIMIC-III's length of stay to the second.
"""

from __future__ import annotations

import gzip
import json
import pickle
import shutil
from pathlib import Path

import pytest

from envs.converters import convert
from envs.converters.base import SourceFileError
from envs.converters.formats import closed_alternatives, parse_choices

FIX = Path(__file__).parents[1] / "fixtures" / "benchmarks"
IMAGES = FIX / "vqa_images"


def errors(result):
    return [(Path(e.path).name, e.line, e.message) for e in result.errors]


def gold_text(task) -> str:
    return task.options[task.correct_answer] if task.answer_type == "choice" else task.correct_answer


def write_jsonl(path: Path, rows: list[dict], *, newline: str = "\n", bom: bool = False) -> Path:
    text = newline.join(json.dumps(r, ensure_ascii=False) for r in rows) + newline
    path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode("utf-8"))
    return path


# -- MedQA ------------------------------------------------------------------------------------------
MEDQA_5 = {"question": "A 23-year-old woman has dysuria and frequency. Urinalysis shows nitrites. Which drug is best?",
           "answer": "Nitrofurantoin", "options": {"A": "Ampicillin", "B": "Ceftriaxone", "C": "Ciprofloxacin",
                                                   "D": "Doxycycline", "E": "Nitrofurantoin"},
           "meta_info": "step2&3", "answer_idx": "E"}
MEDQA_4 = {"question": MEDQA_5["question"], "answer": "Nitrofurantoin",
           "options": {"A": "Ampicillin", "B": "Ceftriaxone", "C": "Doxycycline", "D": "Nitrofurantoin"},
           "meta_info": "step2&3", "answer_idx": "D", "metamap_phrases": ["woman", "dysuria", "nitrites"]}


@pytest.mark.parametrize("row", [MEDQA_4, MEDQA_5, MEDQA_4 | {"realidx": "0042"}, MEDQA_5 | {"realidx": 7}],
                         ids=["4-options", "5-options", "4-options+realidx", "5-options+realidx"])
def test_medqa_round_trip_in_each_layout(tmp_path, row):
    result = convert("medqa", write_jsonl(tmp_path / "test.jsonl", [row]))
    assert result.errors == [] and len(result.tasks) == 1
    task = result.tasks[0]
    assert gold_text(task) == row["answer"] and task.correct_answer == row["answer_idx"]
    assert task.metadata.get("realidx") == row.get("realidx")


def test_medqa_bigbio_options_list_round_trip(tmp_path):
    row = MEDQA_5 | {"options": [{"key": k, "value": v} for k, v in MEDQA_5["options"].items()]}
    result = convert("medqa", write_jsonl(tmp_path / "bigbio.jsonl", [row]))
    assert result.errors == [] and gold_text(result.tasks[0]) == "Nitrofurantoin"
    assert result.tasks[0].id == convert("medqa", write_jsonl(tmp_path / "plain.jsonl", [MEDQA_5])).tasks[0].id


def test_medqa_answer_text_disagreeing_with_answer_idx_is_reported(tmp_path):
    result = convert("medqa", write_jsonl(tmp_path / "t.jsonl", [MEDQA_4 | {"answer_idx": "C"}]))
    assert result.tasks == []
    message = "answer 'Nitrofurantoin' is not the text of option C ('Doxycycline'): answer_idx and answer disagree"
    assert errors(result) == [("t.jsonl", 1, message)]


# -- MedMCQA ----------------------------------------------------------------------------------------
MEDMCQA = [{"id": "e9ad821a-c438-4965-9f77-760819dfa155", "question": "Drug of choice for absence seizures in a child?",
            "opa": "Phenytoin", "opb": "Carbamazepine", "opc": "Ethosuximide", "opd": "Phenobarbitone",
            "choice_type": "single", "exp": "Ethosuximide is first line.", "subject_name": "Pharmacology",
            "topic_name": "Antiepileptics"},
           {"id": "7c1e8a5e-0000-4000-8000-000000000002", "question": "Most common site of carcinoid tumour?",
            "opa": "Appendix", "opb": "Ileum", "opc": "Rectum", "opd": "Stomach", "choice_type": "single",
            "exp": None, "subject_name": "Pathology", "topic_name": "GIT"},
           {"id": "7c1e8a5e-0000-4000-8000-000000000003", "question": "Vitamin deficient in Wernicke encephalopathy?",
            "opa": "Niacin", "opb": "Riboflavin", "opc": "Pyridoxine", "opd": "Thiamine", "choice_type": "single",
            "exp": None, "subject_name": "Medicine", "topic_name": "Nutrition"},
           {"id": "7c1e8a5e-0000-4000-8000-000000000004", "question": "Antidote for paracetamol overdose?",
            "opa": "N-acetylcysteine", "opb": "Naloxone", "opc": "Flumazenil", "opd": "Atropine",
            "choice_type": "single", "exp": None, "subject_name": "Pharmacology", "topic_name": "Toxicology"}]
ANSWERS = ["Ethosuximide", "Ileum", "Thiamine", "N-acetylcysteine"]  # the released answers (cop 3, 2, 4, 1 one-based)


@pytest.mark.parametrize("base", [1, 0], ids=["original-1-based", "hugging-face-0-based"])
def test_medmcqa_round_trip_in_both_layouts(tmp_path, base):
    cops = [3 - 1 + base, 2 - 1 + base, 4 - 1 + base, 1 - 1 + base]
    rows = [r | {"cop": c} for r, c in zip(MEDMCQA, cops)]
    result = convert("medmcqa", write_jsonl(tmp_path / "dev.json", rows))
    assert result.errors == []
    assert [gold_text(t) for t in result.tasks] == ANSWERS


# -- MMLU -------------------------------------------------------------------------------------------
MMLU_ROWS = [("Which nerve innervates the diaphragm?", ["Vagus", "Phrenic", "Intercostal", "Accessory"], 1),
             ('A "quoted", multi-line\nquestion about the femur?', ["Tibia", "Humerus", "Femur", "Fibula"], 2)]


def test_mmlu_original_header_less_csv_round_trip(tmp_path):
    import csv

    path = tmp_path / "anatomy_test.csv"
    with path.open("w", encoding="utf-8", newline="") as handle:
        writer = csv.writer(handle)
        for question, choices, answer in MMLU_ROWS:
            writer.writerow([question, *choices, "ABCD"[answer]])
    result = convert("mmlu", path)
    assert result.errors == []
    assert [gold_text(t) for t in result.tasks] == [c[a] for _, c, a in MMLU_ROWS]
    assert result.tasks[1].ticket.startswith('A "quoted", multi-line\nquestion')
    assert {t.metadata["subject"] for t in result.tasks} == {"anatomy"}


def test_mmlu_hugging_face_parquet_round_trip(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = tmp_path / "test-00000-of-00001.parquet"
    table = pa.table({"question": [q for q, _, _ in MMLU_ROWS], "subject": ["anatomy", "anatomy"],
                      "choices": [c for _, c, _ in MMLU_ROWS], "answer": pa.array([a for _, _, a in MMLU_ROWS],
                                                                                   type=pa.int64())})
    pq.write_table(table, path)
    result = convert("mmlu", path)
    assert result.errors == [] and result.rows_read == 2
    assert [gold_text(t) for t in result.tasks] == ["Phrenic", "Femur"]
    assert result.tasks[0].metadata["subject"] == "anatomy"


@pytest.mark.parametrize("style", ["python-list", "json-list", "numpy-array"])
def test_mmlu_hugging_face_csv_export_round_trip(tmp_path, style):
    import csv

    def cell(choices):
        if style == "python-list":
            return repr(choices)
        if style == "json-list":
            return json.dumps(choices)
        return "[" + " ".join(repr(c) for c in choices) + "]"  # pandas writes numpy arrays like this

    path = tmp_path / "clinical_knowledge.csv"
    with path.open("w", encoding="utf-8", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["question", "subject", "choices", "answer"])
        for question, choices, answer in MMLU_ROWS:
            writer.writerow([question, "clinical_knowledge", cell(choices), answer])
    result = convert("mmlu", path)
    assert result.errors == []
    assert [gold_text(t) for t in result.tasks] == ["Phrenic", "Femur"]


def test_mmlu_rows_with_empty_options_or_bad_answers_are_rejected(tmp_path):
    path = tmp_path / "virology_test.csv"
    path.write_text('"Empty option?",a,,c,d,A\n"Bad letter?",a,b,c,d,E\n"Fine?",a,b,c,d,D\n', encoding="utf-8")
    result = convert("mmlu", path)
    assert [gold_text(t) for t in result.tasks] == ["d"]
    assert errors(result) == [("virology_test.csv", 1, "option(s) ['B'] are empty"),
                              ("virology_test.csv", 2, "answer column must be A-D, got 'E'")]


def test_parse_choices_refuses_what_is_not_a_list():
    assert parse_choices("[\"it's\", 'b']") == ["it's", "b"]
    assert parse_choices("['a, b', 'c']") == ["a, b", "c"]
    assert parse_choices("['a' 'b'\n 'c' 'd']") == ["a", "b", "c", "d"]
    with pytest.raises(ValueError, match="not a list of option texts"):
        parse_choices("a; b; c; d")
    with pytest.raises(ValueError, match="not a list of option texts"):
        parse_choices("[__import__('os')]")


# -- PubMedQA ---------------------------------------------------------------------------------------
def test_pubmedqa_round_trip_and_a_string_context_is_not_split(tmp_path):
    data = {"21645374": {"QUESTION": "Do mitochondria play a role in remodelling lace plant leaves?",
                         "CONTEXTS": ["Programmed cell death occurs in lace plant leaves.", "Mitochondria were imaged."],
                         "LABELS": ["BACKGROUND", "RESULTS"], "MESHES": ["Mitochondria"], "YEAR": "2011",
                         "reasoning_required_pred": "yes", "reasoning_free_pred": "yes", "final_decision": "yes",
                         "LONG_ANSWER": "Results depicted mitochondrial dynamics."},
            "16418930": {"QUESTION": "Is the no-reflow phenomenon predictable?",
                         "CONTEXTS": "A single abstract string.", "final_decision": "maybe", "LONG_ANSWER": "x"}}
    path = tmp_path / "ori_pqal.json"
    path.write_text(json.dumps(data, indent=1), encoding="utf-8")
    result = convert("pubmedqa", path)
    assert result.errors == []
    assert [gold_text(t) for t in result.tasks] == ["yes", "maybe"]
    assert "Context:\nA single abstract string.\n\nQuestion:" in result.tasks[1].ticket


# -- MedLFQA ----------------------------------------------------------------------------------------
def test_medlfqa_round_trip():
    rows = [json.loads(line) for line in (FIX / "medlfqa.jsonl").read_text(encoding="utf-8").splitlines()]
    result = convert("medlfqa", FIX / "medlfqa.jsonl")
    assert [gold_text(t) for t in result.tasks] == [rows[0]["Free_form_answer"]]
    assert result.tasks[0].evaluation_criteria.nl_assertions == rows[0]["Must_have"]


# -- VQA --------------------------------------------------------------------------------------------
def test_vqa_rad_round_trip_and_closed_answers_that_are_not_yes_no(tmp_path):
    rows = [
        {"qid": 1, "image_name": "synpic100.jpg", "image_organ": "CHEST", "answer": "Yes", "answer_type": "CLOSED",
         "question_type": "PRES", "question": "Is there a pneumothorax?", "phrase_type": "freeform"},
        {"qid": 2, "image_name": "synpic100.jpg", "image_organ": "HEAD", "answer": "MRI", "answer_type": "CLOSED",
         "question_type": "MODALITY", "question": "Is this a CT or an MRI?", "phrase_type": "freeform"},
        {"qid": 3, "image_name": "synpic100.jpg", "image_organ": "CHEST", "answer": "right", "answer_type": "CLOSED",
         "question_type": "POS", "question": "Is the effusion on the right or left side?", "phrase_type": "para"},
        {"qid": 4, "image_name": "synpic100.jpg", "image_organ": "CHEST", "answer": "T2 weighted",
         "answer_type": "CLOSED", "question_type": "MODALITY", "question": "Is this T1 weighted or T2 weighted?",
         "phrase_type": "freeform"},
        {"qid": 5, "image_name": "synpic100.jpg", "image_organ": "CHEST", "answer": "2", "answer_type": "CLOSED",
         "question_type": "COUNT", "question": "Are there 1 or 2 lesions?", "phrase_type": "freeform"},
        {"qid": 6, "image_name": "synpic100.jpg", "image_organ": "ABD", "answer": "liver", "answer_type": "CLOSED",
         "question_type": "ORGAN", "question": "Which organ is abnormal?", "phrase_type": "freeform"},
        {"qid": 7, "image_name": "synpic100.jpg", "image_organ": "CHEST", "answer": "cardiomegaly",
         "answer_type": "OPEN", "question_type": "ABN", "question": "What is abnormal?", "phrase_type": "freeform"},
    ]
    path = tmp_path / "VQA_RAD Dataset Public.json"
    path.write_text(json.dumps(rows), encoding="utf-8")
    result = convert("vqa-rad", path, image_dir=IMAGES)
    assert result.errors == []
    tasks = result.tasks
    assert [gold_text(t) for t in tasks[1:]] == [r["answer"] for r in rows[1:]]
    assert gold_text(tasks[0]) == "yes"  # yes/no options are written lower-case
    assert [t.answer_type for t in tasks] == ["choice", "choice", "choice", "choice", "choice", "exact", "exact"]
    assert tasks[1].options == {"A": "CT", "B": "MRI"} and tasks[2].options == {"A": "right", "B": "left"}
    assert tasks[3].options == {"A": "T1 weighted", "B": "T2 weighted"} and tasks[4].options == {"A": "1", "B": "2"}
    # every CLOSED question is counted by the closed-question metric (evals: closed_accuracy)
    assert [t.description.task_type for t in tasks] == ["vqa_closed"] * 6 + ["vqa_open"]


def test_closed_alternatives():
    assert closed_alternatives("Is this a CT or an MRI?", "ct") == ["CT", "MRI"]
    assert closed_alternatives("Is the lesion on the left or right?", "right") == ["left", "right"]
    assert closed_alternatives("Is this a CT, MRI or X-ray?", "x-ray") == ["MRI", "X-ray"]
    assert closed_alternatives("Which organ is abnormal?", "liver") is None
    assert closed_alternatives("Is this a CT or an MRI?", "ultrasound") is None


def test_slake_round_trip_keeps_english_rows():
    rows = json.loads((FIX / "slake.json").read_text(encoding="utf-8"))
    result = convert("slake", FIX / "slake.json", image_dir=IMAGES)
    assert [gold_text(t) for t in result.tasks] == [r["answer"].lower() for r in rows if r["q_lang"] == "en"]
    assert any("1 question(s) with q_lang 'zh' skipped" in note for note in result.notes)


PATHVQA_ROWS = [{"image": "train_0001", "question": "Does this image show necrosis?", "answer": "yes"},
                {"image": "train_0001", "question": "What is present?", "answer": "granuloma"}]


def test_pathvqa_released_pickle_round_trip(tmp_path):
    path = tmp_path / "train_vqa.pkl"
    path.write_bytes(pickle.dumps(PATHVQA_ROWS, protocol=4))
    result = convert("pathvqa", path, image_dir=IMAGES)
    assert result.errors == []
    assert [gold_text(t) for t in result.tasks] == ["yes", "granuloma"]
    assert Path(result.tasks[0].image_path).name == "train_0001.png"


def test_pathvqa_lxmert_rows_in_a_pickle_and_in_json(tmp_path):
    rows = [{"answer_type": "yes/no", "img_id": "train_0001", "label": {"no": 1}, "question_id": 100422000,
             "question_type": "is", "sent": "Is the tissue normal?"},
            {"answer_type": "other", "img_id": "train_0001", "label": {"fibrosis": 1}, "question_id": 100422001,
             "question_type": "what", "sent": "What is shown?"}]
    (tmp_path / "val_vqa.pkl").write_bytes(pickle.dumps(rows))
    (tmp_path / "val.json").write_text(json.dumps(rows), encoding="utf-8")
    for name in ("val_vqa.pkl", "val.json"):
        result = convert("pathvqa", tmp_path / name, image_dir=IMAGES)
        assert result.errors == []
        assert [gold_text(t) for t in result.tasks] == ["no", "fibrosis"]
        assert result.tasks[0].answer_type == "choice" and result.tasks[0].metadata["question_id"] == 100422000


def test_pathvqa_pickle_with_code_is_refused_before_anything_runs(tmp_path):
    class Exploit:
        def __reduce__(self):
            return (shutil.rmtree, (str(tmp_path / "victim"),))

    (tmp_path / "victim").mkdir()
    path = tmp_path / "test_vqa.pkl"
    path.write_bytes(pickle.dumps([Exploit()]))
    with pytest.raises(ValueError, match=r"test_vqa.pkl: the pickle refers to shutil.rmtree"):
        convert("pathvqa", path, image_dir=IMAGES)
    assert (tmp_path / "victim").is_dir()


def test_pmc_vqa_round_trip():
    result = convert("pmc-vqa", FIX / "pmc_vqa.csv", image_dir=IMAGES)
    assert [gold_text(t) for t in result.tasks] == [t.raw_answer for t in result.tasks] == ["Focal uptake pattern", "H&E"]


def test_vqa_med_2021_round_trip():
    result = convert("vqa-med-2021", FIX / "vqa_med_2021.txt", image_dir=IMAGES)
    assert [gold_text(t) for t in result.tasks] == ["pulmonary embolism", "no"]


def test_quilt_vqa_round_trip():
    rows = json.loads((FIX / "quilt_vqa.json").read_text(encoding="utf-8"))
    result = convert("quilt-vqa", FIX / "quilt_vqa.json", image_dir=IMAGES)
    assert [gold_text(t) for t in result.tasks] == [r["answer"] for r in rows if "answer" in r]


# -- image paths --------------------------------------------------------------------------------------
def test_image_names_that_escape_the_image_folder_are_rejected_with_the_row(tmp_path):
    images = tmp_path / "images"
    images.mkdir()
    (images / "ok.jpg").write_bytes(b"\xff\xd8\xff")
    (tmp_path / "secret.jpg").write_bytes(b"\xff\xd8\xff")
    (images / "link.jpg").symlink_to(tmp_path / "secret.jpg")
    rows = [{"image_name": n, "question": "Is it normal?", "answer": "yes", "answer_type": "CLOSED"}
            for n in ("ok.jpg", "../secret.jpg", "../../../../etc/passwd", "/etc/passwd", "link.jpg")]
    path = tmp_path / "rad.json"
    path.write_text(json.dumps(rows, indent=1), encoding="utf-8")
    result = convert("vqa-rad", path, image_dir=images)
    assert [Path(t.image_path).name for t in result.tasks] == ["ok.jpg"]
    errs = errors(result)
    assert [(line, msg.split(":")[0]) for _, line, msg in errs] == [(8, "item 2"), (14, "item 3"), (20, "item 4"),
                                                                     (26, "item 5")]
    assert "'../secret.jpg' escapes the image folder" in errs[0][2]
    assert "'../../../../etc/passwd' escapes the image folder" in errs[1][2]
    assert "'/etc/passwd' is not a path inside the image folder" in errs[2][2]
    assert "'link.jpg' escapes the image folder" in errs[3][2]


def test_image_folder_defaults_to_the_dataset_folder(tmp_path):
    shutil.copy(IMAGES / "synpic100.jpg", tmp_path / "synpic100.jpg")
    path = tmp_path / "rad.json"
    path.write_text(json.dumps([{"image_name": "synpic100.jpg", "question": "Is it normal?", "answer": "no",
                                 "answer_type": "CLOSED"}]), encoding="utf-8")
    result = convert("vqa-rad", path)
    assert result.errors == [] and Path(result.tasks[0].image_path) == (tmp_path / "synpic100.jpg").resolve()


# -- encodings and damaged files ----------------------------------------------------------------------
def test_bom_and_crlf_lose_no_row(tmp_path):
    rows = [MEDQA_4, MEDQA_5]
    plain = convert("medqa", write_jsonl(tmp_path / "a.jsonl", rows))
    windows = convert("medqa", write_jsonl(tmp_path / "b.jsonl", rows, newline="\r\n", bom=True))
    assert windows.errors == [] and [t.id for t in windows.tasks] == [t.id for t in plain.tasks]
    # a JSON array with a BOM (VQA-RAD saved on Windows)
    path = tmp_path / "rad.json"
    path.write_bytes(b"\xef\xbb\xbf" + (FIX / "vqa_rad.json").read_bytes().replace(b"\n", b"\r\n"))
    assert len(convert("vqa-rad", path, image_dir=IMAGES).tasks) == 2
    # MMLU: the BOM must not end up inside the first question
    mmlu = tmp_path / "anatomy_test.csv"
    mmlu.write_bytes(b"\xef\xbb\xbf" + b'"Which nerve innervates the diaphragm?",Vagus,Phrenic,Intercostal,Accessory,B\r\n')
    assert convert("mmlu", mmlu).tasks[0].ticket == "Which nerve innervates the diaphragm?"


def test_latin1_file_is_a_clear_error_naming_file_and_line(tmp_path):
    path = tmp_path / "latin.jsonl"
    path.write_bytes(json.dumps(MEDQA_4).encode() + b"\n" + json.dumps(MEDQA_5 | {"question": "Caf\u00e9 au lait?"},
                                                                       ensure_ascii=False).encode("latin-1") + b"\n")
    with pytest.raises(SourceFileError, match=r"latin.jsonl:2: not UTF-8 \(byte 0xe9 at column \d+\).*Latin-1"):
        convert("medqa", path)


def test_gzip_input_and_truncated_gzip(tmp_path):
    data = "\n".join(json.dumps(r) for r in [MEDQA_4, MEDQA_5] * 400).encode()
    good = tmp_path / "test.jsonl.gz"
    good.write_bytes(gzip.compress(data))
    assert len(convert("medqa", good).tasks) == 800
    bad = tmp_path / "cut.jsonl.gz"
    bad.write_bytes(gzip.compress(data)[:-300])
    with pytest.raises(SourceFileError, match=r"cut.jsonl.gz:\d+: damaged or truncated gzip file"):
        convert("medqa", bad)


def test_json_array_errors_give_item_index_and_file_line(tmp_path):
    path = tmp_path / "rad.json"
    path.write_text('[\n {"image_name": "synpic100.jpg", "question": "Is it normal?", "answer": "no"},\n'
                    ' "a string",\n'
                    ' {"image_name": "synpic100.jpg", "question": "Is it big?"}\n]\n', encoding="utf-8")
    result = convert("vqa-rad", path, image_dir=IMAGES)
    assert len(result.tasks) == 1
    assert errors(result) == [("rad.json", 3, "item 2: expected a JSON object, got str"),
                              ("rad.json", 4, "item 3: missing field 'answer'")]
    broken = tmp_path / "broken.json"
    broken.write_text('[\n {"image_name": "a", "question": "q", "answer": "no"},\n {"image_name": "b",, }\n]',
                      encoding="utf-8")
    with pytest.raises(SourceFileError, match=r"broken.json:3: item 2 \(starting on line 3\) is not valid JSON"):
        convert("vqa-rad", broken, image_dir=IMAGES)


# -- MIMIC-III --------------------------------------------------------------------------------------
def _mimic_with_stay(tmp_path: Path, intime: str, outtime: str, los: str) -> Path:
    folder = tmp_path / "mimic"
    shutil.copytree(FIX / "mimic3", folder)
    icu = folder / "ICUSTAYS.csv"
    lines = icu.read_text(encoding="utf-8").splitlines()
    lines[2] = f'2,102,1002,2002,"carevue","SICU","SICU",33,33,"{intime}","{outtime}",{los}'
    icu.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return folder


def test_mimic3_length_of_stay_uses_the_seconds_and_matches_the_los_column(tmp_path):
    from envs.converters.ehr import convert_mimic3

    # 22 h 47 min 01 s = 0.9493 days; minute-truncated times would give 22 h 48 min = 0.9500 -> "0.95"
    folder = _mimic_with_stay(tmp_path, "2150-02-10 09:00:59", "2150-02-11 07:48:00", "0.9493")
    result = convert_mimic3(folder)
    los = {t.id: t for t in result.tasks}["mimic3_icu_los_2002"]
    stay = los.metadata["ehr_patient"]["admissions"][0]["icu_stays"][0]
    assert (stay["intime"], stay["outtime"]) == ("2150-02-10T09:00:59", "2150-02-11T07:48:00")
    assert abs(float(los.correct_answer) - 0.9493) < 0.005 and los.correct_answer == "0.95"
    # and one where seconds change the rounded answer: 0.9424 days, truncation would say 0.95
    folder2 = _mimic_with_stay(tmp_path / "b", "2150-02-10 09:00:59", "2150-02-11 07:38:00", "0.9424")
    task = {t.id: t for t in convert_mimic3(folder2).tasks}["mimic3_icu_los_2002"]
    assert task.correct_answer == "0.94"
    # the EHR tool answers the same from the imported record
    from envs.converters.ehr import _tools_for

    kit, patient = _tools_for(task.metadata["ehr_patient"])
    summary = kit.summarize_admission(patient.patient_id, "1002")
    assert summary["icu_stays"][0]["los_days"] == pytest.approx(0.9424, abs=5e-5)


def test_mimic3_gzip_tables_and_a_truncated_labevents(tmp_path):
    from envs.converters.ehr import convert_mimic3

    folder = tmp_path / "mimic_gz"
    folder.mkdir()
    for table in (FIX / "mimic3").glob("*.csv"):
        (folder / f"{table.name}.gz").write_bytes(gzip.compress(table.read_bytes()))
    plain = convert_mimic3(FIX / "mimic3")
    zipped = convert_mimic3(folder)
    assert {t.id: t.correct_answer for t in zipped.tasks} == {t.id: t.correct_answer for t in plain.tasks}
    labs = folder / "LABEVENTS.csv.gz"
    labs.write_bytes(labs.read_bytes()[:-12])
    with pytest.raises(SourceFileError, match=r"LABEVENTS.csv.gz:\d+: damaged or truncated gzip file"):
        convert_mimic3(folder)


def test_mimic3_latin1_table_names_file_and_line(tmp_path):
    from envs.converters.ehr import convert_mimic3

    folder = tmp_path / "mimic"
    shutil.copytree(FIX / "mimic3", folder)
    items = folder / "D_LABITEMS.csv"
    items.write_bytes(items.read_bytes() + '99999,51999,"Prot\u00e9ine","Blood","Chemistry",\n'.encode("latin-1"))
    lines = len(items.read_bytes().splitlines())
    with pytest.raises(SourceFileError, match=rf"D_LABITEMS.csv:{lines}: not UTF-8"):
        convert_mimic3(folder)


def test_mimic3_max_stays_keeps_only_the_selected_admissions_labs():
    from envs.converters.ehr import convert_mimic3

    full = convert_mimic3(FIX / "mimic3")
    one = convert_mimic3(FIX / "mimic3", max_stays=1)
    kept = {t.metadata["ehr_patient"]["admissions"][0]["hadm_id"] for t in one.tasks}
    assert one.tasks and len(kept) == 1
    assert len({t.metadata["ehr_patient"]["admissions"][0]["hadm_id"] for t in full.tasks}) > 1
    # the kept admission's record holds the same lab results as in the full conversion
    def labs(result):
        return {t.id: t.metadata["ehr_patient"]["admissions"][0]["lab_events"] for t in result.tasks}
    assert all(labs(full)[task_id] == events for task_id, events in labs(one).items())


def test_medmcqa_hugging_face_parquet_round_trip(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows = [r | {"cop": c} for r, c in zip(MEDMCQA, [2, 1, 3, 0])]
    table = pa.table({key: [r[key] for r in rows] for key in rows[0]})
    path = tmp_path / "train-00000-of-00001.parquet"
    pq.write_table(table, path)
    result = convert("medmcqa", path)
    assert result.errors == [] and result.rows_read == 4
    assert [gold_text(t) for t in result.tasks] == ANSWERS
    assert any("0-based" in note for note in result.notes)
    damaged = tmp_path / "cut.parquet"
    damaged.write_bytes(path.read_bytes()[:200])
    with pytest.raises(SourceFileError, match="cut.parquet: not a readable parquet file"):
        convert("medmcqa", damaged)


def test_mimic3_and_eicu_count_the_icu_stays_they_read():
    from envs.converters.ehr import convert_eicu, convert_mimic3

    icustays = (FIX / "mimic3" / "ICUSTAYS.csv").read_text(encoding="utf-8").strip().splitlines()
    patients = (FIX / "eicu" / "patient.csv").read_text(encoding="utf-8").strip().splitlines()
    assert convert_mimic3(FIX / "mimic3").rows_read == len(icustays) - 1
    assert convert_eicu(FIX / "eicu").rows_read == len(patients) - 1
