"""Clinical-diagnosis domain: knowledge modules on known input, every tool on a known patient, the
task set (counts, splits, gold replay)."""

from __future__ import annotations

import importlib.util
import json

import pytest

from envs import registry

registry.DOMAINS.setdefault("clinical_diagnosis", "envs.domains.clinical_diagnosis.environment")

from envs.domains.clinical_diagnosis import build as cd_build  # noqa: E402
from envs.domains.clinical_diagnosis.hpo import PhenotypeIndex, frequency_value, parse_hpoa, parse_obo  # noqa: E402
from envs.core.icd10 import ICD10Index, normalise_code, parse_tabular  # noqa: E402
from envs.domains.clinical_diagnosis.labs import LabCatalog  # noqa: E402


@pytest.fixture(scope="module")
def built():
    summary = cd_build.build()
    return summary


@pytest.fixture
def env(built, monkeypatch):
    import envs.domains.clinical_diagnosis.environment as m

    monkeypatch.setattr(m, "shared_toolkits", lambda: [])
    return m.get_environment()


def call(env, name, **args):
    out = env.toolkit.call(name, args)
    assert out.ok, out.error
    return out.result


def fails(env, name, **args) -> str:
    out = env.toolkit.call(name, args)
    assert not out.ok, f"{name} should have failed: {out.result}"
    return out.error


# -- knowledge modules on hand-made input --------------------------------------------------------
OBO = """format-version: 1.2

[Term]
id: HP:0000118
name: Phenotypic abnormality

[Term]
id: HP:0000001
name: All

[Term]
id: HP:0000002
name: Seizure
synonym: "Epileptic seizure" EXACT []
is_a: HP:0000118 ! Phenotypic abnormality

[Term]
id: HP:0000003
name: Focal seizure
is_a: HP:0000002 ! Seizure

[Term]
id: HP:0000004
name: Tall stature
is_a: HP:0000118 ! Phenotypic abnormality

[Term]
id: HP:0000005
name: Obsolete thing
is_obsolete: true
"""
HPOA = "\n".join([
    "#description: test",
    "database_id\tdisease_name\tqualifier\thpo_id\treference\tevidence\tonset\tfrequency\tsex\tmodifier\taspect\tbiocuration",
    "OMIM:1\tAlpha disease\t\tHP:0000003\tPMID:1\tPCS\t\t3/4\t\t\tP\tx",
    "OMIM:1\tAlpha disease\t\tHP:0000004\tPMID:1\tPCS\t\tHP:0040281\t\t\tP\tx",
    "OMIM:2\tBeta disease\t\tHP:0000002\tPMID:1\tPCS\t\t\t\t\tP\tx",
    "OMIM:2\tBeta disease\tNOT\tHP:0000004\tPMID:1\tPCS\t\t\t\t\tP\tx",
    "OMIM:3\tGamma disease\t\tHP:0000004\tPMID:1\tPCS\t\t50%\t\t\tC\tx",
])


def test_frequency_values():
    assert frequency_value("3/4") == 0.75
    assert frequency_value("HP:0040281") == pytest.approx(0.895)
    assert frequency_value("20%") == pytest.approx(0.2)
    assert frequency_value("") is None
    with pytest.raises(ValueError):
        frequency_value("often")


def test_hpo_parse_and_rank_exact_scores():
    from envs.domains.clinical_diagnosis.hpo import compile_hpo

    terms = parse_obo(OBO)
    assert "HP:0000005" not in terms and terms["HP:0000002"]["synonyms"] == ["Epileptic seizure"]
    diseases = parse_hpoa(HPOA)
    assert set(diseases) == {"OMIM:1", "OMIM:2"}  # aspect C row ignored
    assert diseases["OMIM:2"]["excluded"] == {"HP:0000004"}
    index = PhenotypeIndex(compile_hpo(terms, diseases))
    assert index.resolve("epileptic seizure") == "HP:0000002"
    # IC: Seizure annotated (propagated) in both diseases -> -ln(3/3)=0; Tall stature in 1 -> -ln(2/3)
    ic_tall = index.ic("HP:0000004")
    assert ic_tall == pytest.approx(-__import__("math").log(2 / 3), abs=1e-4)
    ranked = index.rank(["HP:0000004"])
    assert [r["disease_id"] for r in ranked] == ["OMIM:1"]  # OMIM:2 excludes tall stature (negative)
    assert ranked[0]["score"] == pytest.approx(0.895, abs=1e-4)
    # Focal seizure observed: OMIM:1 has it exactly (3/4), OMIM:2 only the more general Seizure
    ranked = index.rank(["HP:0000003"])
    assert ranked[0]["disease_id"] == "OMIM:1" and ranked[0]["score"] == pytest.approx(0.75, abs=1e-4)
    assert ranked[0]["matches"][0]["match"] == "exact"


def test_run_together_omim_titles_are_separated():
    """The pinned phenotype.hpoa joins two OMIM titles without a separator in a few disease names; an
    option or alias must not read "deficiencymultiple"."""
    row = "OMIM:253260\tBiotinidase deficiencymultiple carboxylase deficiency, late-onset\t\tHP:0001992\tPMID:1\tPCS\t\t25/29\t\t\tP\tHPO:x"
    assert parse_hpoa(row)["OMIM:253260"]["name"] == "Biotinidase deficiency; multiple carboxylase deficiency, late-onset"
    from envs.data.reference_parsers import hpoa_disease_name

    assert hpoa_disease_name("Cataract syndromefoveal hypoplasia, isolated, included") == \
        "Cataract syndrome; foveal hypoplasia, isolated, included"
    # plurals and words that merely contain the stems stay as they are
    for name in ("Congenital myasthenic syndromes", "Immunodeficiency 14", "Nonsyndromic deafness"):
        assert hpoa_disease_name(name) == name


XML = """<?xml version="1.0"?><ICD10CM.tabular><chapter><name>4</name><desc>Endocrine (E00-E89)</desc>
<section id="E08-E13"><desc>Diabetes mellitus (E08-E13)</desc>
<diag><name>E11</name><desc>Type 2 diabetes mellitus</desc>
  <diag><name>E11.2</name><desc>Type 2 diabetes mellitus with kidney complications</desc>
    <diag><name>E11.21</name><desc>Type 2 diabetes mellitus with diabetic nephropathy</desc>
      <inclusionTerm><note>Type 2 diabetes mellitus with Kimmelstiel-Wilson disease</note></inclusionTerm></diag>
    <diag><name>E11.22</name><desc>Type 2 diabetes mellitus with diabetic chronic kidney disease</desc></diag>
  </diag>
  <diag><name>E11.9</name><desc>Type 2 diabetes mellitus without complications</desc></diag>
</diag></section></chapter></ICD10CM.tabular>"""


def test_icd10_parse_lookup_and_search():
    items = parse_tabular(XML)
    assert items["E11.21"]["billable"] and not items["E11.2"]["billable"] and items["E11"]["kind"] == "category"
    index = ICD10Index(items)
    assert normalise_code("e1121") == "E11.21"
    got = index.get("E1121")
    assert [h["code"] for h in got["hierarchy"]] == ["Chapter 4", "E08-E13", "E11", "E11.2"]
    hits = index.search("Kimmelstiel-Wilson")
    assert hits[0]["code"] == "E11.21" and "matched_inclusion_term" in hits[0]
    assert index.siblings("E11.21") == ["E11.22"]
    assert index.search("nothing like this") == []


def test_lab_catalog_flags_and_units():
    cat = LabCatalog([
        {"key": "creatinine", "name": "Creatinine", "unit": "mg/dL", "male": {"low": 0.74, "high": 1.35},
         "female": {"low": 0.59, "high": 1.04}, "critical_low": None, "critical_high": 10.0, "si_unit": "umol/L",
         "si_factor": 88.4},
        {"key": "potassium", "name": "Potassium", "aliases": ["k"], "unit": "mmol/L", "low": 3.5, "high": 5.1,
         "critical_low": 2.5, "critical_high": 6.5},
    ])
    assert cat.resolve("K") == "potassium"
    assert [cat.flag("potassium", v, None) for v in (2.5, 3.0, 4.0, 5.5, 6.5)] == \
        ["critical low", "low", "normal", "high", "critical high"]
    value, note = cat.to_conventional("creatinine", 176.8, "umol/L")
    assert value == pytest.approx(2.0) and "88.4" in note
    assert cat.flag("creatinine", 1.2, "female") == "high" and cat.flag("creatinine", 1.2, "male") == "normal"
    with pytest.raises(ValueError):
        cat.to_conventional("creatinine", 1.0, "g/L")


# -- tools on known patients --------------------------------------------------------------------
def test_patient_reads(env):
    info = call(env, "get_patient_info", patient_id="CD-P01")
    assert info["allergies"][0]["substance"] == "penicillin" and info["age"] == 67
    vitals = call(env, "get_vital_signs", patient_id="CD-P01")["vitals"][0]
    assert vitals["mean_arterial_pressure"] == pytest.approx((134 + 2 * 78) / 3, abs=0.1)
    assert set(vitals["outside_adult_normal"]) == {"heart_rate", "respiratory_rate", "temperature_c", "spo2"}
    assert "Crackles" in call(env, "get_physical_exam", patient_id="CD-P01", system="lungs")["exam"]["lungs"]
    assert "was not examined" in fails(env, "get_physical_exam", patient_id="CD-P01", system="retina")
    assert "not found" in fails(env, "get_patient_info", patient_id="NOPE")


def test_order_lab_releases_hidden_result_and_flags(env):
    before = call(env, "get_patient_findings", patient_id="CD-P01")["findings"]
    assert "Leukocytosis" not in {f["label"] for f in before}
    assert call(env, "get_lab_results", patient_id="CD-P01", test="wbc")["status"] == "not ordered"
    out = call(env, "order_lab", patient_id="CD-P01", test="white cell count", priority="stat")
    assert out["status"] == "resulted" and out["result"]["value"] == 16.8 and out["result"]["flag"] == "high"
    rows = call(env, "get_lab_results", patient_id="CD-P01")["results"]
    assert {r["test"]: r["flag"] for r in rows}["wbc"] == "high"
    assert {r["test"]: r["flag"] for r in rows}["glucose"] == "high"  # 182 mg/dL
    after = call(env, "get_patient_findings", patient_id="CD-P01")["findings"]
    assert "Leukocytosis" in {f["label"] for f in after}
    assert "already ordered" in fails(env, "order_lab", patient_id="CD-P01", test="wbc")
    pending = call(env, "order_lab", patient_id="CD-P01", test="tsh")
    assert pending["status"] == "pending"
    assert "catalogue" in fails(env, "order_lab", patient_id="CD-P01", test="unobtainium")


def test_interpret_lab_value(env):
    out = call(env, "interpret_lab_value", test="creatinine", value=150, sex="male", unit="umol/L")
    assert out["value"] == pytest.approx(150 / 88.4, abs=1e-3) and out["flag"] == "high"
    assert call(env, "interpret_lab_value", test="sodium", value=118)["flag"] == "critical low"
    assert call(env, "interpret_lab_value", test="potassium", value=4.2)["flag"] == "normal"
    assert "unit" in fails(env, "interpret_lab_value", test="sodium", value=140, unit="g/L")
    assert len(call(env, "list_lab_tests", panel="CBC")) >= 5


def test_generate_ddx_from_patient_and_terms(env):
    call(env, "order_lab", patient_id="CD-P25", test="echocardiogram")
    ddx = call(env, "generate_ddx", patient_id="CD-P25", top_k=10, scope="rare")
    names = [d["name"].lower() for d in ddx["differential"]]
    assert any("marfan" in n for n in names[:5]), names
    scores = [d["score"] for d in ddx["differential"]]
    assert scores == sorted(scores, reverse=True)
    common = call(env, "generate_ddx", findings=["Fever", "Flank pain", "Costovertebral angle tenderness", "Pyuria"],
                  scope="common", top_k=3)
    assert common["differential"][0]["disease_id"] == "CD:pyelonephritis"
    assert "not recognised" in fails(env, "generate_ddx", findings=["feels funny"])
    assert call(env, "lookup_hpo_term", query="HP:0001166")[0]["name"] == "Arachnodactyly"
    marfan = call(env, "get_disease_phenotypes", disease="ORPHA:558")
    assert marfan["name"] == "Marfan syndrome" and marfan["n_phenotypes"] > 20


def test_icd10_and_record_diagnosis(env):
    assert call(env, "lookup_icd10", query="E11.21")["description"] == "Type 2 diabetes mellitus with diabetic nephropathy"
    hits = call(env, "lookup_icd10", query="Kimmelstiel-Wilson type 2")["matches"]
    assert hits[0]["code"] == "E11.21"
    assert "not billable" in fails(env, "record_diagnosis", patient_id="CD-P06", icd10_code="I21")
    assert "does not exist" in fails(env, "record_diagnosis", patient_id="CD-P06", icd10_code="Z99.999")
    out = call(env, "record_diagnosis", patient_id="CD-P06", icd10_code="i214", certainty="confirmed")
    assert out["recorded"] == "I21.4"
    assert env.db.patients["CD-P06"].diagnoses[0].icd10_code == "I21.4"


def test_prescribing_checks_allergies_and_doses(env):
    before = env.db.content_hash()
    err = fails(env, "prescribe_medication", patient_id="CD-P01", drug="amoxicillin", dose_mg=1000, route="oral",
                frequency="tid")
    assert "allergic to penicillin" in err and env.db.content_hash() == before
    check = call(env, "check_drug_allergy", patient_id="CD-P01", drug="ceftriaxone")
    assert check["safe_to_prescribe"] and "cross-reactivity" in check["warnings"][0]["note"]
    assert not call(env, "check_drug_allergy", patient_id="CD-P06", drug="aspirin")["safe_to_prescribe"]
    assert "maximum daily dose" in fails(env, "prescribe_medication", patient_id="CD-P01", drug="doxycycline",
                                         dose_mg=200, route="oral", frequency="bid")
    assert "route" in fails(env, "prescribe_medication", patient_id="CD-P01", drug="doxycycline", dose_mg=100,
                            route="rectal", frequency="bid")
    out = call(env, "prescribe_medication", patient_id="CD-P01", drug="Vibramycin", dose_mg=100, route="oral",
               frequency="bid", duration_days=5)
    assert out["drug"] == "doxycycline"
    meds = call(env, "get_medication_list", patient_id="CD-P01")
    assert meds["prescriptions"][0]["drug"] == "doxycycline"
    assert env.db.content_hash() != before


def test_notes_and_escalation_are_in_the_chart(env):
    call(env, "write_clinical_note", patient_id="CD-P16", note_type="progress",
         content="K 7.1 with peaked T waves; calcium gluconate given, insulin-dextrose started.")
    call(env, "escalate_care", patient_id="CD-P16", reason="critical hyperkalaemia with ECG changes", team="icu")
    notes = call(env, "get_clinical_notes", patient_id="CD-P16")["notes"]
    assert [n["note_type"] for n in notes] == ["progress", "escalation"]
    assert "too short" in fails(env, "write_clinical_note", patient_id="CD-P16", note_type="progress", content="ok")


# -- tasks -------------------------------------------------------------------------------------
def test_task_counts_and_splits(built):
    tasks = registry.get_tasks("clinical_diagnosis")
    splits = registry.get_splits("clinical_diagnosis")
    assert len(tasks) >= 780
    assert len(splits["validation"]) == 25
    ids = [set(v) for v in splits.values()]
    assert sum(len(s) for s in ids) == len(set().union(*ids)) == len(tasks)
    kinds = {t.description.task_type for t in tasks}
    assert {"rare_disease_dx", "icd10_coding", "lab_interpretation", "diagnostic_workflow"} <= kinds
    authored = [t for t in tasks if t.description.source == "authored"]
    assert len(authored) >= 20 and all(len(t.evaluation_criteria.actions) >= 6 for t in authored)
    by_id = {t.id: t for t in tasks}
    norm = lambda t: " ".join(t.ticket.lower().split())  # noqa: E731
    train = {norm(by_id[i]) for i in splits["train"]}
    assert not train & {norm(by_id[i]) for i in splits["test"] + splits["validation"]}
    for t in tasks:
        if t.answer_type == "choice":
            assert len(set(t.options.values())) == len(t.options)


def test_gold_actions_replay_without_errors(built, monkeypatch):
    import envs.domains.clinical_diagnosis.environment as m

    monkeypatch.setattr(m, "shared_toolkits", lambda: [])
    for task in registry.get_tasks("clinical_diagnosis"):
        env = m.get_environment()
        for action in task.evaluation_criteria.actions:
            out = env.toolkit.call(action.name, action.arguments)
            assert out.ok, (task.id, action.name, out.error)
        if task.description.task_type == "lab_interpretation":
            assert out.result["flag"] == task.correct_answer, task.id


@pytest.mark.skipif(importlib.util.find_spec("envs.rewards") is None, reason="rewards package not present yet")
def test_core_validator_on_a_sample(built, monkeypatch):
    import envs.domains.clinical_diagnosis.environment as m
    from envs.validate import validate_task

    monkeypatch.setattr(m, "shared_toolkits", lambda: [])

    tasks = registry.get_tasks("clinical_diagnosis")
    definitions = registry.get_environment("clinical_diagnosis").toolkit.definitions
    by_type: dict[str, list] = {}
    for t in tasks:
        by_type.setdefault(t.description.task_type, []).append(t)
    sample = [group[i] for group in by_type.values() for i in (0, len(group) // 2)]
    problems = [r for r in (validate_task(t, "clinical_diagnosis", definitions) for t in sample) if not r.ok]
    assert not problems, [(r.task_id, r.problems) for r in problems[:5]]
