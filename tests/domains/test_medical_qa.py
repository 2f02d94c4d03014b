"""Medical-QA domain: every tool on known input, the task set (counts, splits, gradeability,
contamination), authored answers re-derived from the tools, gold replay, and tool latency."""

from __future__ import annotations

import collections
import random
import statistics
import time

import pytest

from envs import registry
from envs.calculators import CALCULATORS
from envs.validate import check_domain_contamination
from envs.core.tools import ToolError
from envs.domains.medical_qa import build as mqa_build
from envs.domains.medical_qa.data_model import MedicalQADB, QAQuestion
from envs.domains.medical_qa.generate import disease_family
from envs.domains.medical_qa.knowledge import load_knowledge, norm
from envs.domains.medical_qa.tools import MedicalQATools

registry.DOMAINS.setdefault("medical_qa", "envs.domains.medical_qa.environment")


def use(toolkit, tool: str, **arguments):
    """Call a tool as the agent would; a tool error is raised as ToolError."""
    outcome = toolkit.call(tool, arguments)
    if outcome.error:
        raise ToolError(outcome.error)
    return outcome.result


@pytest.fixture(scope="module")
def kb():
    mqa_build.build()
    return load_knowledge()


@pytest.fixture
def tools(kb):
    return MedicalQATools(MedicalQADB(), kb)


@pytest.fixture(scope="module")
def tasks(kb):
    return registry.get_tasks("medical_qa")


# -- tools -------------------------------------------------------------------------------------
def test_pregnancy_data_follow_the_label_not_the_package_letter(tools):
    """drugdose says "A" for both; magnesium sulfate is D since the FDA's 2013 relabelling, calcium
    gluconate's label (8.1, PLLR) has no letter (envs/domains/pregnancy_labels.py). drugdose's
    "magnesium_sulfate" reaches the index's "magnesium sulfate"."""
    from envs.domains.pregnancy_labels import PACKAGE_LETTER_BASIS

    dosing = use(tools, "lookup_drug", name="magnesium sulfate")["dosing"]
    assert dosing["pregnancy_category"] == "D" and dosing["pregnancy"]["fda_category_date"] == "2013-05-30"
    rows = use(tools, "compare_treatments", treatments=["magnesium sulfate", "calcium gluconate", "midazolam"])
    by_drug = {r["drug"].lower(): r for r in rows["treatments"]}
    assert by_drug["magnesium sulfate"]["pregnancy_category"] == "D"
    assert by_drug["calcium gluconate"]["pregnancy_category"] is None
    assert "8.1" in by_drug["calcium gluconate"]["pregnancy"]["label_section"]
    # no label rule: drugdose's letter stays, named as package data
    assert by_drug["midazolam"]["pregnancy_category"] == "D"
    assert by_drug["midazolam"]["pregnancy"]["basis"] == PACKAGE_LETTER_BASIS


def test_lookup_icd10(tools):
    out = use(tools, "lookup_icd10", code="E119")
    assert out["code"] == "E11.9" and out["description"] == "Type 2 diabetes mellitus without complications"
    assert out["billable"] and out["parents"][0]["code"] == "E11" and out["chapter"]["number"] == "4"
    assert any("E11.A" in note for note in out["excludes1"])
    with pytest.raises(ToolError, match="not found"):
        use(tools, "lookup_icd10", code="Q99.999")


def test_search_and_category(tools):
    hits = use(tools, "search_icd10", query="Type 2 diabetes mellitus with hyperglycemia")["results"]
    assert hits[0]["code"] == "E11.65"
    cat = use(tools, "list_icd10_category", code="E11.65")
    assert cat["category"] == "E11" and {"E11.9", "E11.65"} <= {c["code"] for c in cat["billable_codes"]}
    assert "E10" in {c["code"] for c in cat["block"]["categories"]}
    with pytest.raises(ToolError, match="limit"):
        use(tools, "search_icd10", query="diabetes", limit=0)


def test_hpo_tools(tools):
    term = use(tools, "lookup_hpo_term", term="seizures")  # a synonym
    assert term["hpo_id"] == "HP:0001250" and term["name"] == "Seizure" and term["annotated_diseases"] > 1000
    marfan = use(tools, "lookup_disease_phenotypes", disease="OMIM:154700")["diseases"][0]
    assert marfan["name"] == "Marfan syndrome" and "Autosomal dominant inheritance" in marfan["inheritance"]
    assert "Ectopia lentis" in {p["name"] for p in marfan["phenotypes"]}
    ranked = use(tools, "search_diseases_by_phenotypes",
                            phenotypes=["Ectopia lentis", "Arachnodactyly", "Aortic root aneurysm", "HP:0000767"])
    top = {r["disease_id"] for r in ranked["results"][:5]}
    assert "OMIM:154700" in top and ranked["results"][0]["matched"] == 4
    found = use(tools, "search_diseases", query="marfan")["results"]
    assert "OMIM:154700" in {r["disease_id"] for r in found}
    with pytest.raises(ToolError, match="HPO phenotype"):
        use(tools, "lookup_hpo_term", term="not a phenotype at all")


def test_disease_family_reads_the_words_before_a_subtype():
    assert disease_family("Glycogen storage disease Ia") == disease_family(
        "Glycogen storage disease due to glucose-6-phosphatase deficiency") == "glycogen storage disease"
    assert disease_family("Cardiomyopathy, familial hypertrophic, 14") == "cardiomyopathy familial hypertrophic"
    assert disease_family("Costello syndrome") == "costello syndrome"
    assert disease_family("Costello syndrome") != disease_family("Stuve-Wiedemann syndrome")


def test_drug_tools(tools):
    zestril = use(tools, "lookup_drug", name="Zestril")
    assert zestril["drug"] == "Lisinopril"
    assert zestril["established_pharmacologic_class"] == ["Angiotensin Converting Enzyme Inhibitor"]
    members = use(tools, "list_drug_class_members", drug_class="HMG-CoA Reductase Inhibitor")["members"]
    assert {"Atorvastatin", "Simvastatin", "Rosuvastatin"} <= set(members)
    cmp = use(tools, "compare_treatments", treatments=["amiodarone", "digoxin"])
    pair = cmp["pairs"][0]
    assert pair["emergency_drug_interaction"]["severity"] == "major" and pair["shared_classes"] == []
    same = use(tools, "compare_treatments", treatments=["sertraline", "fluoxetine"])["pairs"][0]
    assert same["shared_classes"] == ["Serotonin Reuptake Inhibitor"]
    with pytest.raises(ToolError, match="drug 'notadrug' not found"):
        use(tools, "lookup_drug", name="notadrug")
    with pytest.raises(ToolError, match="2 to 6"):
        use(tools, "compare_treatments", treatments=["aspirin"])


def test_guideline_tools(tools):
    hits = use(tools, "search_guideline_sections", query="nimodipine delayed cerebral ischemia")["results"]
    assert hits[0]["section_id"] == "aha_asa_sah_2023/delayed_cerebral_ischemia"
    assert "cerebral ischemia" in hits[0]["excerpt"].lower()
    sec = use(tools, "read_guideline_section", section_id="kdigo_aki_2012/definition_and_staging")
    assert "0.3 mg/dL" in sec["text"] and sec["doi"]
    page = use(tools, "read_guideline_section", section_id="kdigo_aki_2012/definition_and_staging", offset=100)
    assert page["text"] == sec["text"][100:100 + len(page["text"])]
    with pytest.raises(ToolError, match="sections of that guideline"):
        use(tools, "read_guideline_section", section_id="kdigo_aki_2012/nope")


def test_entities_options_and_evidence(tools):
    ents = use(tools, "extract_clinical_entities", text="On lisinopril for E11.9; has seizures and arachnodactyly.")
    assert [d["drug"] for d in ents["drugs"]] == ["Lisinopril"]
    assert {p["hpo_id"] for p in ents["phenotypes"]} >= {"HP:0001250", "HP:0001166"}
    assert ents["icd10_codes"][0]["code"] == "E11.9"
    tools.db.question = QAQuestion(question_id="q1", stem='Which code is assigned to "Type 2 diabetes mellitus with hyperglycemia"?',
                                   options={"A": "E11.65", "B": "E11.9"})
    ev = use(tools, "analyze_answer_options")["options"]
    assert ev["A"]["icd10"]["exact_match_with_quoted"] is True and ev["B"]["icd10"]["exact_match_with_quoted"] is False
    use(tools, "record_evidence", option="a", finding="E11.65 is the exact description", source="lookup_icd10",
                   supports=True)
    assert tools.db.evidence[0].option == "A"
    before = tools.db.content_hash()
    outcome = tools.call("record_evidence", {"option": "Z", "finding": "x", "source": "y", "supports": False})
    assert outcome.error and "not one of" in outcome.error and tools.db.content_hash() == before


def test_calculator_tools_are_the_shared_calculators(tools):
    out = use(tools, "calculate_anion_gap", sodium=140, chloride=104, bicarbonate=24)
    assert out["score"] == 12 and out["category"] == "elevated"
    assert tools.definitions["calculate_meld_na"].parameters["required"] == [
        "bilirubin_mg_dl", "inr", "creatinine_mg_dl", "sodium_mmol_l", "on_dialysis"]
    outcome = tools.call("calculate_bmi", {"weight_kg": 70, "height_cm": 5})
    assert outcome.error and "height_cm" in outcome.error


# -- tasks -------------------------------------------------------------------------------------
def test_counts_splits_and_schema(tasks):
    generated = [t for t in tasks if t.description.source == "generated"]
    authored = [t for t in tasks if t.description.source == "authored"]
    assert len(generated) >= 1000 and len(authored) >= 20
    types = collections.Counter(t.description.task_type for t in generated)
    assert len(types) >= 10 and min(types.values()) >= 30, types
    splits = registry.get_splits("medical_qa")
    assert len(splits["validation"]) == 149
    train, test, val = (set(splits[k]) for k in ("train", "test", "validation"))
    assert not (train & test or train & val or test & val)
    assert train | test | val == {t.id for t in tasks}
    for t in tasks:
        assert t.answer_type == "choice" and t.has_gold_answer and t.options and len(t.options) in (4, 5)
        assert not any("all of the above" in o.lower() for o in t.options.values())
        assert t.evaluation_criteria.actions and t.description.provenance
    for t in authored:
        assert len(t.evaluation_criteria.actions) >= 1 and len(t.evaluation_criteria.nl_assertions) >= 2


def test_no_held_out_leaks(tasks):
    assert check_domain_contamination("medical_qa") == []


def test_generated_answers_follow_from_the_data(tasks, kb):
    for t in tasks:
        if t.description.source != "generated":
            continue
        gold = t.options[t.correct_answer]
        tt, meta = t.description.task_type, t.metadata
        if tt == "icd10_code_for_description":
            assert kb.icd_codes[gold]["desc"] in t.ticket
            assert all(kb.icd_codes[o]["desc"] not in t.ticket for k, o in t.options.items() if k != t.correct_answer)
        elif tt == "icd10_description_for_code":
            assert kb.icd_codes[meta["code"]]["desc"] == gold
        elif tt == "hpo_diagnosis":
            did = meta["disease_id"]
            assert all(h in kb.disease_pheno[did] for h in meta["phenotypes"])
            for k, name in t.options.items():
                if k != t.correct_answer:
                    other = kb.resolve_disease(name)[0]
                    covered = sum(kb.phenotype_match(other, h)[0] != "none" for h in meta["phenotypes"])
                    assert covered <= len(meta["phenotypes"]) // 2, (t.id, name)
                    # no distractor of the answer's own family (mqa_hpo_dx_ORPHA_364 offered "Glycogen storage
                    # disease Ia", one of the answer's two types, beside the answer)
                    assert disease_family(name) != disease_family(gold), (t.id, name, gold)
        elif tt == "hpo_inheritance":
            assert kb.diseases[meta["disease_id"]]["inheritance"] == [gold]
        elif tt == "drug_class":
            assert gold in kb.drugs[meta["drug"]]["epc"]
            assert all(o not in kb.drugs[meta["drug"]]["epc"] for k, o in t.options.items() if k != t.correct_answer)
        elif tt == "drug_class_member":
            for k, name in t.options.items():
                assert (meta["drug_class"] in kb.drugs[kb.resolve_drug(name)]["epc"]) == (k == t.correct_answer)
        elif tt == "calculator_vignette":
            value = CALCULATORS[meta["calculator"]](**meta["arguments"]).score
            assert abs(float(gold) - value) <= 0.51 * (10 ** -(len(gold.split(".")[1]) if "." in gold else 0)) * 2


def _run(tools, task):
    tools.db.question = QAQuestion(question_id=task.id, stem=task.ticket, options=dict(task.options))
    outs = {}
    for a in task.evaluation_criteria.actions:
        outs.setdefault(a.name, []).append(use(tools, a.name, **a.arguments))
    return outs


def test_authored_answers_rederived_from_tools(tasks, kb):
    checked = 0
    for t in tasks:
        if t.description.source != "authored":
            continue
        tools = MedicalQATools(MedicalQADB(), kb)
        outs = _run(tools, t)
        check, gold = t.metadata["check"], t.options[t.correct_answer]
        kind = check["kind"]
        if kind == "icd":
            assert gold == check["code"] and outs["lookup_icd10"][0]["code"] == gold
        elif kind == "hpo_max":
            tools.db.question = QAQuestion(question_id=t.id, stem="\n".join(check["phenotypes"]), options=dict(t.options))
            ev = use(tools, "analyze_answer_options")["options"]
            cov = {k: ev[k]["phenotype_coverage"]["covered"] for k in t.options}
            assert cov[t.correct_answer] == len(check["phenotypes"]), (t.id, cov)
            assert all(c < cov[t.correct_answer] for k, c in cov.items() if k != t.correct_answer), (t.id, cov)
        elif kind == "classes":
            assert outs["compare_treatments"][0]["pairs"][0]["shared_classes"] == check["shared"]
        elif kind == "pairs":
            for k, pair in check["pairs"].items():
                shared = use(tools, "compare_treatments", treatments=pair)["pairs"][0]["shared_classes"]
                assert bool(shared) == (k == t.correct_answer), (t.id, k, shared)
        elif kind == "interaction":
            assert outs["compare_treatments"][0]["pairs"][0]["emergency_drug_interaction"]["severity"] == check["severity"]
            assert gold.lower() == check["severity"]
        elif kind == "pair_severity":
            for k, pair in check["pairs"].items():
                inter = use(tools, "compare_treatments", treatments=pair)["pairs"][0]["emergency_drug_interaction"]
                assert ((inter or {}).get("severity") == check["severity"]) == (k == t.correct_answer), (t.id, k)
        elif kind == "moa":
            assert outs["lookup_drug"][0]["mechanism_of_action"] == [gold]
        elif kind == "max_dose":
            routes = outs["lookup_drug"][0]["dosing"]["routes"]
            assert next(r for r in routes if r["route"] == check["route"])["max_single_dose_mg"] == check["mg"]
            assert gold == f"{check['mg']:g} mg"
        elif kind == "pregnancy":
            rows = {norm(r["drug"]): r.get("pregnancy_category") for r in outs["compare_treatments"][0]["treatments"]}
            for k, drug in check["drugs"].items():
                assert (rows[drug] == check["category"]) == (k == t.correct_answer), (t.id, drug, rows)
        elif kind == "guideline":
            assert norm(check["evidence"]) in norm(kb.guidelines[check["section"]]["text"])
        elif kind == "calc_category":
            assert CALCULATORS[check["calculator"]](**check["args"]).category == check["category"]
        elif kind == "calc_value":
            assert CALCULATORS[check["calculator"]](**check["args"]).score == check["value"] == float(gold)
        else:
            raise AssertionError(f"{t.id}: unknown check {kind}")
        checked += 1
    assert checked >= 20


def test_every_expected_action_runs(tasks, kb):
    tools = MedicalQATools(MedicalQADB(), kb)
    for t in tasks:
        for a in t.evaluation_criteria.actions:
            assert a.name in tools.definitions, (t.id, a.name)
            tools.db.question = QAQuestion(question_id=t.id, stem=t.ticket, options=dict(t.options))
            outcome = tools.call(a.name, a.arguments)
            assert outcome.ok, (t.id, a.name, outcome.error)


def test_gold_replay_through_the_validator(tasks):
    from envs.validate import validate_task

    definitions = registry.get_environment("medical_qa").toolkit.definitions
    by_type = {}
    for t in tasks:
        by_type.setdefault((t.description.source, t.description.task_type), t)
    for t in by_type.values():
        report = validate_task(t, "medical_qa", definitions)
        assert report.ok, (t.id, report.problems)


def test_reset_and_tool_latency(tasks):
    registry.get_environment("medical_qa")
    start = time.perf_counter()
    for _ in range(50):
        env = registry.get_environment("medical_qa")
    assert (time.perf_counter() - start) / 50 < 0.01
    from envs.domains.medical_qa.environment import _on_reset

    rng = random.Random(0)
    times = collections.defaultdict(list)
    for t in rng.sample(tasks, 120):
        _on_reset(env, t)
        for name, args in [("analyze_answer_options", {})] + [(a.name, a.arguments) for a in t.evaluation_criteria.actions]:
            best = min(_timed(env.toolkit, name, args) for _ in range(3))
            times[name].append(best)
    for name, values in times.items():
        assert statistics.median(values) < 0.005, (name, statistics.median(values))


def _timed(toolkit, name, args):
    start = time.perf_counter()
    toolkit.call(name, args)
    return time.perf_counter() - start
