"""Psychiatry domain: every tool on known input, WRITE tools change state that later reads see,
the task set (counts, splits, gradeability, emergencies, contamination), gold replay, speed."""

from __future__ import annotations

import collections
import statistics
import time

import pytest

from envs import registry
from envs.calculators import CALCULATORS
from envs.validate import check_domain_contamination
from envs.core.tools import ToolError
from envs.domains.psychiatry import build as psy_build
from envs.domains.psychiatry.instruments import score_mdq

registry.DOMAINS.setdefault("psychiatry", "envs.domains.psychiatry.environment")


def use(toolkit, tool: str, **arguments):
    outcome = toolkit.call(tool, arguments)
    if outcome.error:
        raise ToolError(outcome.error)
    return outcome.result


@pytest.fixture(scope="module")
def built():
    return psy_build.build()


@pytest.fixture
def env(built):
    return registry.get_environment("psychiatry")


@pytest.fixture
def tk(env):
    return env.toolkit


@pytest.fixture(scope="module")
def tasks(built):
    return registry.get_tasks("psychiatry")


def test_chart_and_interview_tools(tk):
    s = use(tk, "get_patient_summary", patient_id="psy-003")
    assert s["patient_id"] == "PSY-003" and {m["name"] for m in s["medications"]} == {"lithium", "ibuprofen"}
    h = use(tk, "get_psychiatric_history", patient_id="PSY-001")
    assert h["suicide_attempts"][0]["method"] == "sertraline overdose"
    tr = use(tk, "get_interview_transcript", patient_id="PSY-001", contains="intention")
    assert [u["speaker"] for u in tr["utterances"]] == ["clinician", "patient"] and "try again" in tr["utterances"][1]["text"]
    form = use(tk, "get_symptom_report", patient_id="PSY-004", instrument="epds")
    assert len(form["items"]) == 10 and form["items"][9]["score"] == 1
    with pytest.raises(ToolError, match="no gad7 form on file"):
        use(tk, "get_symptom_report", patient_id="PSY-004", instrument="gad7")
    with pytest.raises(ToolError, match="not found"):
        use(tk, "get_patient_summary", patient_id="PSY-999")


def test_instruments_fill_from_the_chart_and_explicit_inputs_win(tk):
    phq = use(tk, "administer_phq9", patient_id="PSY-009")
    assert phq["score"] == 22 and phq["category"] == "severe" and phq["flags"]
    assert use(tk, "administer_phq9", patient_id="PSY-009", responses=[0] * 9)["score"] == 0
    assert use(tk, "administer_gad7", patient_id="PSY-010")["score"] == 16
    assert use(tk, "administer_epds", patient_id="PSY-004")["category"] == "probable depression"
    audit = use(tk, "administer_audit_c", patient_id="PSY-011")
    assert audit["score"] == 4 and audit["category"] == "positive"
    assert use(tk, "administer_audit_c", patient_id="PSY-011", sex="male")["category"] == "positive"
    assert use(tk, "administer_audit_c", responses=[1, 1, 1], sex="male")["category"] == "negative"
    assert use(tk, "administer_cage", patient_id="PSY-011")["score"] == 2
    assert use(tk, "calculate_ciwa_ar", patient_id="PSY-006")["score"] == 19
    assert use(tk, "assess_suicide_risk", patient_id="PSY-009")["category"] == "high risk"
    assert use(tk, "assess_suicide_risk", wish_to_be_dead=True, suicidal_thoughts=False,
               suicidal_behavior="over_3_months_ago")["category"] == "moderate risk"
    with pytest.raises(ToolError, match="no completed PHQ9 form"):
        use(tk, "administer_phq9", patient_id="PSY-016")
    with pytest.raises(ToolError, match="suicidal_thoughts"):
        use(tk, "assess_suicide_risk", wish_to_be_dead=True, suicidal_thoughts=False, intent=True)


def test_mdq_rule():
    yes7 = [True] * 7 + [False] * 6
    assert score_mdq(yes7, True, "moderate problem").category == "positive"
    assert score_mdq(yes7, True, "minor problem").category == "negative"
    assert score_mdq(yes7, False, "serious problem").category == "negative"
    assert score_mdq([True] * 6 + [False] * 7, True, "serious problem").category == "negative"
    with pytest.raises(ValueError, match="items"):
        score_mdq([True] * 12, True, "serious problem")


def test_screen_bipolar_tool(tk):
    out = use(tk, "screen_bipolar", patient_id="PSY-005")
    assert out["category"] == "positive" and out["score"] == 10


def test_interactions(tk):
    out = use(tk, "check_psych_med_interactions", patient_id="PSY-008", proposed_drug="Zoloft")
    assert out["highest_severity"] == "contraindicated"
    # tranylcypromine is not in the drug_interaction database: the psychiatry rule grades it (Parnate 4.1)
    parnate = use(tk, "check_psych_med_interactions", medications=["tranylcypromine", "sertraline"])
    assert parnate["highest_severity"] == "contraindicated" and parnate["interactions"][0]["rule"] == "PIR-01"
    li = use(tk, "check_psych_med_interactions", patient_id="PSY-003")
    assert li["highest_severity"] == "major" and {"lithium", "ibuprofen"} == set(li["interactions"][0]["drugs"])
    # a triptan with an SNRI: the labels ask for observation (Imitrex 5, Cymbalta 7), an MAO-A inhibitor is
    # contraindicated (Imitrex 4); the generic two-serotonergic-drugs rule does not apply to it
    trip = use(tk, "check_psych_med_interactions", medications=["duloxetine", "sumatriptan"])
    assert trip["highest_severity"] == "moderate" and [f["rule"] for f in trip["interactions"]] == ["PIR-19"]
    assert use(tk, "check_psych_med_interactions", medications=["phenelzine", "Imitrex"])["highest_severity"] == "contraindicated"
    none = use(tk, "check_psych_med_interactions", medications=["sertraline", "atorvastatin"])
    assert none["highest_severity"] == "none" and none["interactions"] == []
    with pytest.raises(ToolError, match="not in the psychiatry formulary"):
        use(tk, "check_psych_med_interactions", patient_id="PSY-003", proposed_drug="unobtainium")


@pytest.fixture(scope="module")
def psych_db(built):
    from envs.domains.psychiatry.data_model import PsychiatryDB
    from envs.core.paths import domain_build_dir

    return PsychiatryDB.load(domain_build_dir("psychiatry") / "db.json")


def test_one_interaction_scale_with_drug_interaction(built, psych_db):
    """Every formulary pair the drug_interaction domain grades gets the same severity here (the reward's
    safety context and the tool); the serotonergic pairs are the case that differed (PIR-03 'major' against
    the Ultram 7 'moderate' of overlay US-006)."""
    import itertools

    from envs.domains.drug_reference import DrugReference, load_formulary
    from envs.domains.psychiatry.safety import PsychiatrySafetyContext

    reference = DrugReference(load_formulary())  # the live drug_interaction database, not the psychiatry build's copy
    ctx = PsychiatrySafetyContext(lambda: psych_db)
    graded = differ = 0
    mismatches = []
    for a, b in itertools.combinations(sorted(psych_db.formulary), 2):
        theirs = reference.interaction(a, b)
        if theirs is None:
            continue
        graded += 1
        ours = ctx.interaction(a, b)
        if ours is None or ours[0] != theirs[0]:
            mismatches.append((a, b, ours and ours[0], theirs[0], theirs[1][:40]))
    assert reference.status == "drug_interaction database loaded", reference.status
    assert graded > 200 and not mismatches, mismatches[:10]
    assert ctx.interaction("sertraline", "tramadol")[0] == "moderate" == reference.interaction("sertraline", "tramadol")[0]


def test_interaction_controls_and_the_tool_agree(tk, psych_db):
    from envs.domains.psychiatry.safety import PsychiatrySafetyContext

    ctx = PsychiatrySafetyContext(lambda: psych_db)
    # SSRI + MAOI stays contraindicated on both sides of the boundary (ANSM for phenelzine, Parnate 4.1 for tranylcypromine)
    assert ctx.interaction("sertraline", "phenelzine")[0] == "contraindicated"
    assert ctx.interaction("Zoloft", "Parnate")[0] == "contraindicated"
    assert ctx.interaction("lithium", "ibuprofen")[0] == "major"
    assert ctx.interaction("sertraline", "atorvastatin") is None
    tram = use(tk, "check_psych_med_interactions", medications=["sertraline", "Ultram"])
    assert tram["highest_severity"] == "moderate" and [f["rule"] for f in tram["interactions"]] == ["US-006"]
    # a pair only psychiatry grades: two serotonergic antidepressants, monitored (Zoloft 5, Serotonin Syndrome), not avoided
    assert use(tk, "check_psych_med_interactions", medications=["sertraline", "trazodone"])["highest_severity"] == "moderate"
    assert ctx.interaction("ziprasidone", "citalopram")[0] == "contraindicated"  # Geodon 4


def test_interaction_rules_cite_their_source_and_each_applies(psych_db):
    """Each PIR rule names a label section or a guideline; 'contraindicated' only with a section 4 citation;
    and each still grades a formulary pair the drug_interaction domain does not (no rule shadowed everywhere)."""
    import itertools
    import re

    from envs.domains.psychiatry import interactions as IX

    section = re.compile(r"\b\d{1,2}(?:\.\d+)? [A-Z][A-Za-z ]{5,}|CONTRAINDICATIONS|Drug Safety Communication|Medical Eligibility Criteria")
    labelled = IX.label_index(psych_db.label_graded_pairs)
    groups = {n: d.groups for n, d in psych_db.formulary.items()}
    used = collections.Counter()
    for a, b in itertools.combinations(sorted(psych_db.formulary), 2):
        if IX.pair_key(a, b) not in labelled:
            used.update(r.id for r in psych_db.interaction_rules if IX.rule_matches(r, set(groups[a]), set(groups[b])))
    for rule in psych_db.interaction_rules:
        assert section.search(rule.reference), (rule.id, rule.reference)
        if rule.severity == "contraindicated":
            assert re.search(r"\b4(?:\.\d)? |CONTRAINDICATIONS", rule.reference), rule.id
        assert used[rule.id], f"{rule.id} grades no pair: the drug_interaction domain grades all its pairs"
    # and the generated interaction golds are what the tool's grading gives
    assert IX.pair_severity(IX.pair_findings("sertraline", "tramadol", groups, psych_db.interaction_rules, labelled)) == "moderate"


def test_order_lab_result_appears_only_after_ordering(tk):
    before = use(tk, "get_lab_results", patient_id="PSY-003")["results"]
    assert [r["value"] for r in before if r["name"] == "lithium level"] == [0.8]
    assert use(tk, "order_lab", patient_id="PSY-003", test="Lithium level")["status"] == "resulted"
    after = use(tk, "get_lab_results", patient_id="PSY-003")["results"]
    new = [r for r in after if r["name"] == "lithium level" and r["value"] == 2.3]
    assert new and new[0]["flag"] == "high"
    assert use(tk, "order_lab", patient_id="PSY-003", test="serum ammonia")["status"] == "not available"


def test_write_tools_record_state(env, tk):
    h0 = env.db_hash()
    out = use(tk, "mental_status_exam", patient_id="PSY-013", appearance="bright clothes", behavior="pacing", speech="pressured",
              mood="fantastic", affect="euphoric", thought_process="flight of ideas", thought_content="grandiose",
              suicidal_ideation=False, homicidal_ideation=False, perception="denies hallucinations", cognition="oriented",
              insight="absent", judgment="poor")
    assert "formal thought disorder (flight of ideas)" in out["risk_flags"]
    assert any("insight" in f for f in out["risk_flags"]) and env.db_hash() != h0
    plan = use(tk, "create_safety_plan", patient_id="PSY-002", warning_signs=["insomnia"], coping_strategies=["walk"],
               social_contacts=["wife"], professional_contacts=["psychiatrist"], means_restriction="lock medicines")
    assert plan["warnings"] and "firearm" in plan["warnings"][0]
    assert use(tk, "escalate_care", patient_id="PSY-001", level="1:1 constant observation", reason="C-SSRS high")["escalated"]
    assert use(tk, "record_diagnosis", patient_id="PSY-010", icd10_code="f41.1")["description"] == "Generalized anxiety disorder"
    assert use(tk, "schedule_follow_up", patient_id="PSY-020", within_days=7, with_whom="CMHT", purpose="review")["booked"]
    db = tk.db
    assert (len(db.mse_records), len(db.safety_plans), len(db.escalations), len(db.diagnoses), len(db.follow_ups)) == (1, 1, 1, 1, 1)
    h1 = env.db_hash()
    bad = tk.call("create_safety_plan", {"patient_id": "PSY-002", "warning_signs": [], "coping_strategies": ["x"],
                                         "social_contacts": ["x"], "professional_contacts": ["x"], "means_restriction": "x"})
    assert bad.error and "warning_signs" in bad.error and env.db_hash() == h1
    bad = tk.call("record_diagnosis", {"patient_id": "PSY-010", "icd10_code": "F41"})
    assert bad.error and "F41.1" in bad.error and env.db_hash() == h1
    fresh = registry.get_environment("psychiatry")
    assert fresh.toolkit.db.mse_records == [] and fresh.db_hash() == h0


def test_tasks_counts_splits_and_emergencies(tasks):
    generated = [t for t in tasks if t.description.source == "generated"]
    authored = [t for t in tasks if t.description.source == "authored"]
    assert len(generated) >= 130 and len(authored) >= 20
    splits = registry.get_splits("psychiatry")
    assert len(splits["validation"]) == 20
    train, test, val = (set(splits[k]) for k in ("train", "test", "validation"))
    assert not (train & test or train & val or test & val) and train | test | val == {t.id for t in tasks}
    for t in tasks:
        assert t.has_gold_answer and t.patient_id and t.patient_id in t.ticket and t.evaluation_criteria.actions
        if t.correct_answer == "high risk":
            assert t.emergency == "suicidality"
            names = [a.name for a in t.evaluation_criteria.actions]
            assert "escalate_care" in names and names.index("escalate_care") <= 5
    for t in authored:
        assert len(t.evaluation_criteria.actions) >= 2 and len(t.evaluation_criteria.nl_assertions) >= 2
    assert collections.Counter(t.description.task_type for t in generated)["cssrs_triage"] >= 20


def test_generated_answers_recomputed(tasks):
    for t in tasks:
        m = t.metadata
        if t.description.task_type == "phq9_total":
            assert str(CALCULATORS["administer_phq9"](responses=m["responses"]).score) == t.correct_answer
        elif t.description.task_type == "cssrs_triage":
            assert CALCULATORS["assess_suicide_risk"](**m["answers"]).category == t.correct_answer


def test_no_held_out_leaks(tasks):
    assert check_domain_contamination("psychiatry") == []


def test_gold_replay_through_the_validator(tasks):
    from envs.validate import validate_task

    definitions = registry.get_environment("psychiatry").toolkit.definitions
    sample = [t for t in tasks if t.description.source == "authored"]
    sample += list({t.description.task_type: t for t in tasks if t.description.source == "generated"}.values())
    for t in sample:
        report = validate_task(t, "psychiatry", definitions)
        assert report.ok, (t.id, report.problems)
        assert report.reward_components.get("safety") == 1.0, (t.id, report.reward_components)


def test_reset_and_tool_latency(tasks):
    registry.get_environment("psychiatry")
    start = time.perf_counter()
    for _ in range(50):
        env = registry.get_environment("psychiatry")
        env.db_hash()
    assert (time.perf_counter() - start) / 50 < 0.01
    times = collections.defaultdict(list)
    for t in tasks[:80]:
        for a in t.evaluation_criteria.actions:
            fresh = registry.get_environment("psychiatry")
            start = time.perf_counter()
            out = fresh.toolkit.call(a.name, a.arguments)
            times[a.name].append(time.perf_counter() - start)
            assert out.ok, (t.id, a.name, out.error)
    for name, values in times.items():
        assert statistics.median(values) < 0.005, (name, statistics.median(values))
