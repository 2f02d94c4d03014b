"""Radiology-report domain: tools on known studies, the report lifecycle and its state, the task set,
gold replay reaching the expected final database state, and speed."""

from __future__ import annotations

import collections
import statistics
import time

import pytest

from envs import registry
from envs.calculators import CALCULATORS
from envs.validate import check_domain_contamination
from envs.core.tools import ToolError
from envs.domains.radiology_report import build as rad_build
from envs.domains.radiology_report.tools import mean_diameter, normalise_category

registry.DOMAINS.setdefault("radiology_report", "envs.domains.radiology_report.environment")


def use(toolkit, tool: str, **arguments):
    outcome = toolkit.call(tool, arguments)
    if outcome.error:
        raise ToolError(outcome.error)
    return outcome.result


@pytest.fixture(scope="module")
def built():
    return rad_build.build()


@pytest.fixture
def env(built):
    return registry.get_environment("radiology_report")


@pytest.fixture
def tk(env):
    return env.toolkit


@pytest.fixture(scope="module")
def tasks(built):
    return registry.get_tasks("radiology_report")


def test_measurements_and_category_spelling():
    assert mean_diameter(13.2, 11.0) == 12.1 and mean_diameter(7.4, 4.6) == 6.0
    assert normalise_category("ACR TI-RADS", "ti-rads tr 4") == "TR4"
    assert normalise_category("BI-RADS", "4b") == "BI-RADS 4B"
    assert normalise_category("Lung-RADS v2022", "lung-rads 4x") == "Lung-RADS 4X"
    assert normalise_category("Fleischner 2017", "ct at 6-12 months") == "CT at 6-12 months"
    assert normalise_category("BI-RADS", "7") is None


def test_study_tools(tk):
    s = use(tk, "get_study", study_id="rad-001")
    assert s["study_id"] == "RAD-001" and [f["finding_id"] for f in s["findings"]] == ["N1", "N2"]
    a = use(tk, "analyze_findings", study_id="RAD-013")
    f = a["findings"][0]
    assert a["applicable_system"] == "Lung-RADS v2022" and f["mean_diameter_mm"] == 13.0 and f["solid_component_mean_mm"] == 8.2
    assert use(tk, "analyze_findings", study_id="RAD-005")["lung_nodule_count"] == 2
    cmp = use(tk, "compare_with_prior", study_id="RAD-004")
    assert cmp["changes"][0]["status"] == "growing" and cmp["changes"][0]["change_mm"] == 5.1
    assert use(tk, "compare_with_prior", study_id="RAD-009")["changes"][0]["status"] == "stable"
    assert use(tk, "compare_with_prior", study_id="RAD-006")["context"] == "baseline"
    assert use(tk, "get_prior_report", study_id="RAD-009")["category"] == "4A"
    with pytest.raises(ToolError, match="no prior"):
        use(tk, "get_prior_report", study_id="RAD-006")
    tpl = use(tk, "get_report_template", modality="LDCT", region="chest")
    assert tpl["category_system"] == "Lung-RADS v2022" and "Lung-RADS 4B" in tpl["critical_categories"]
    assert use(tk, "get_patient_history", study_id="RAD-008")["lung_cancer_risk"] == "low"
    assert use(tk, "list_worklist", region="thyroid", limit=5)["count"] >= 40


def test_classification_tools_fill_from_the_study(tk):
    assert use(tk, "calculate_tirads", study_id="RAD-001", finding_id="N1")["category"] == "TR5"
    assert use(tk, "calculate_tirads", study_id="RAD-001", finding_id="N2")["category"] == "TR2"
    with pytest.raises(ToolError, match="give 'finding_id'"):
        use(tk, "calculate_tirads", study_id="RAD-001")
    assert use(tk, "calculate_tirads", study_id="RAD-007")["category"] == "TR1"
    assert use(tk, "calculate_tirads", study_id="RAD-007", composition="solid")["category"] != "TR1"
    assert use(tk, "calculate_birads", study_id="RAD-010")["category"] == "BI-RADS 4C"
    assert use(tk, "calculate_birads", study_id="RAD-002")["category"] == "BI-RADS 0"
    assert use(tk, "calculate_birads", study_id="RAD-011")["category"] == "BI-RADS 2"
    with pytest.raises(ToolError, match="BI-RADS applies to breast"):
        use(tk, "calculate_birads", study_id="RAD-001")
    # RAD-005 is a colon-cancer staging CT: Fleischner 2017 excludes known malignancy.
    staged = use(tk, "fleischner_recommendation", study_id="RAD-005")
    assert staged["applicable"] is False and staged["category"] == "oncologic staging follow-up"
    assert use(tk, "fleischner_recommendation", nodule_type="ground_glass", size_mm=8, multiple=True, risk="low")["category"] == "CT at 3-6 months"
    assert use(tk, "fleischner_recommendation", study_id="RAD-008")["category"] == "no routine follow-up"
    assert use(tk, "fleischner_recommendation", study_id="RAD-008", risk="high")["category"] == "optional CT at 12 months"
    assert use(tk, "calculate_lung_rads", study_id="RAD-004")["category"] == "4B"
    assert use(tk, "calculate_lung_rads", study_id="RAD-009")["category"] == "3"
    assert use(tk, "calculate_lung_rads", study_id="RAD-019")["category"] == "4X"
    assert use(tk, "calculate_lung_rads", study_id="RAD-017")["category"] == "1"


def test_report_lifecycle_and_state(env, tk):
    h0 = env.db_hash()
    with pytest.raises(ToolError, match="not a valid BI-RADS"):
        use(tk, "draft_report", study_id="RAD-010", findings="x", impression="x", category="TR4", recommendation="x")
    with pytest.raises(ToolError, match="impression must state"):
        use(tk, "draft_report", study_id="RAD-010", findings="calcs", impression="suspicious", category="4C", recommendation="biopsy")
    assert env.db_hash() == h0
    out = use(tk, "draft_report", study_id="RAD-010", findings="calcs", impression="BI-RADS 4C.", category="4c", recommendation="biopsy")
    assert out["category"] == "BI-RADS 4C" and out["critical_result"] is True
    h1 = env.db_hash()
    with pytest.raises(ToolError, match="requires documented communication"):
        use(tk, "finalize_report", study_id="RAD-010")
    assert env.db_hash() == h1
    use(tk, "communicate_critical_result", study_id="RAD-010", recipient="Dr Lee", method="phone", finding="suspicious calcifications")
    assert use(tk, "finalize_report", study_id="RAD-010")["status"] == "final"
    with pytest.raises(ToolError, match="final"):
        use(tk, "draft_report", study_id="RAD-010", findings="x", impression="BI-RADS 2", category="BI-RADS 2", recommendation="x")
    assert tk.db.decision_state()["reports"]["RAD-010"] == {"status": "final", "category": "BI-RADS 4C"}
    assert all(s["study_id"] != "RAD-010" for s in use(tk, "list_worklist", region="breast", limit=100)["studies"])
    # The narrative text does not change the graded state.
    other = registry.get_environment("radiology_report")
    use(other.toolkit, "draft_report", study_id="RAD-010", findings="different words", impression="Category 4C", category="BI-RADS 4C",
        recommendation="stereotactic biopsy")
    use(other.toolkit, "communicate_critical_result", study_id="RAD-010", recipient="referrer", method="phone", finding="4C")
    use(other.toolkit, "finalize_report", study_id="RAD-010")
    assert other.db_hash() == env.db_hash()


def test_tasks_counts_splits(tasks):
    generated = [t for t in tasks if t.description.source == "generated"]
    authored = [t for t in tasks if t.description.source == "authored"]
    assert len(generated) >= 180 and len(authored) >= 20
    splits = registry.get_splits("radiology_report")
    assert len(splits["validation"]) == 10
    train, test, val = (set(splits[k]) for k in ("train", "test", "validation"))
    assert not (train & test or train & val or test & val) and train | test | val == {t.id for t in tasks}
    for t in tasks:
        assert t.has_gold_answer and t.evaluation_criteria.actions
        if t.description.task_type == "report_workflow":
            assert t.evaluation_criteria.expected_db_hash and "DB" in t.evaluation_criteria.reward_basis
    for t in authored:
        assert len(t.evaluation_criteria.actions) >= 5 and len(t.evaluation_criteria.nl_assertions) >= 2


def test_generated_answers_recomputed(tasks):
    for t in tasks:
        if t.description.task_type == "lung_rads":
            assert t.correct_answer == "Lung-RADS " + CALCULATORS["calculate_lung_rads"](**t.metadata["arguments"]).category


def test_no_held_out_leaks(tasks):
    assert check_domain_contamination("radiology_report") == []


def test_gold_replay_reaches_answer_and_state(tasks):
    from envs.validate import validate_task

    definitions = registry.get_environment("radiology_report").toolkit.definitions
    sample = [t for t in tasks if t.description.task_type == "report_workflow"]
    sample += list({t.description.task_type: t for t in tasks if t.description.source == "generated"}.values())
    for t in sample:
        report = validate_task(t, "radiology_report", definitions)
        assert report.ok, (t.id, report.problems)
        assert report.reward_components.get("safety") == 1.0, (t.id, report.reward_components)


def test_reset_and_tool_latency(tasks):
    registry.get_environment("radiology_report")
    start = time.perf_counter()
    for _ in range(50):
        registry.get_environment("radiology_report").db_hash()
    assert (time.perf_counter() - start) / 50 < 0.01
    times = collections.defaultdict(list)
    for t in tasks[::2]:
        env = registry.get_environment("radiology_report")
        for a in t.evaluation_criteria.actions:
            start = time.perf_counter()
            out = env.toolkit.call(a.name, a.arguments)
            times[a.name].append(time.perf_counter() - start)
            assert out.ok, (t.id, a.name, out.error)
    for name, values in times.items():
        assert statistics.median(values) < 0.005, (name, statistics.median(values))


def _study_measurements() -> dict[str, set[tuple[float, str]]]:
    """Per authored study the (value, unit) measurements a report can quote: lung-nodule axes and
    mean diameters (mm), thyroid-nodule dimensions (cm), breast finding sizes (mm)."""
    import json
    from pathlib import Path

    studies = json.loads((Path(rad_build.__file__).parent / "studies_authored.json").read_text(encoding="utf-8"))
    out: dict[str, set[tuple[float, str]]] = {}
    for s in studies:
        values: set[tuple[float, str]] = set()
        for f in s["findings"] + ((s.get("prior") or {}).get("findings") or []):
            for key in ("long_axis_mm", "short_axis_mm", "solid_long_mm", "solid_short_mm", "size_mm"):
                if f.get(key):
                    values.add((round(float(f[key]), 1), "mm"))
            if f.get("long_axis_mm") and f.get("short_axis_mm"):
                values.add((mean_diameter(f["long_axis_mm"], f["short_axis_mm"]), "mm"))
            if f.get("solid_long_mm") and f.get("solid_short_mm"):
                values.add((mean_diameter(f["solid_long_mm"], f["solid_short_mm"]), "mm"))
            for d in f.get("dimensions_cm") or []:
                values.add((round(float(d), 1), "cm"))
        out[s["study_id"]] = values
    return out


def test_gold_reports_are_real_reports(tasks):
    """A gold draft_report is a reference report: no placeholder findings or recommendation, and an
    authored gold's findings quote at least one measurement (number and unit) of its own study."""
    import re

    placeholders = ("as described", "per the acr/fleischner recommendation for this category", "findings as analysed",
                    "as per the guideline for this category")
    measurements = _study_measurements()
    drafts = collections.Counter()
    for t in tasks:
        for a in t.evaluation_criteria.actions:
            if a.name != "draft_report":
                continue
            drafts[t.description.source] += 1
            args = a.arguments
            for field in ("findings", "recommendation", "impression"):
                text = args[field].lower()
                assert not any(p in text for p in placeholders), (t.id, field, args[field])
            if t.description.source == "authored":
                quoted = {(round(float(v), 1), u) for v, u in re.findall(r"(\d+(?:\.\d+)?)\s*(mm|cm)\b", args["findings"])}
                assert quoted & measurements[args["study_id"]], (t.id, args["findings"], sorted(measurements[args["study_id"]]))
    # every authored task and the generated report workflows were checked
    assert drafts["authored"] >= 20 and drafts["generated"] >= 10, drafts
