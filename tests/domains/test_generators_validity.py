"""Clinical validity of the task generators.

Each test checks every generated task of its kind against the clinical rule the generator must
respect, written here from the guideline rather than read back from the generator's own tables:
ACOG Practice Bulletin 222 (magnesium and severe-range treatment only with severe features or
HELLP), Fleischner 2017's scope (never applied to a patient with known cancer), vital signs that the
triage complaint implies, ACR TI-RADS lexicon combinations that can occur, rare-disease vignettes
that the domain's own differential tool identifies, and a named guideline on every generated task.
"""

from __future__ import annotations

import json
import re

import pytest

from envs import registry
from envs.calculators import CALCULATORS
from envs.core.paths import domain_build_dir

FLEISCHNER_CATEGORIES = {"no routine follow-up", "optional CT at 12 months", "CT at 6-12 months", "CT at 3-6 months",
                         "CT at 3 months, PET/CT or tissue sampling"}
# A CT done for cancer staging means a known primary cancer (MacMahon et al., Radiology 2017: the
# guideline does not apply to patients with known malignancy).
STAGING = re.compile(r"\bstaging\b|\bcancer\b|carcinoma|malignan", re.I)


# -- obstetrics: ACOG Practice Bulletin 222 ---------------------------------------------------------
@pytest.fixture(scope="module")
def obstetric_tasks():
    from envs.domains.obstetrics import build as ob_build
    from envs.domains.obstetrics import generate as G

    _, tasks = G.generate(ob_build.SEED)
    return [t for t in tasks if t["description"]["task_type"] == "hypertensive_disorder"]


def _orders_magnesium(task: dict) -> bool:
    return any(a["name"] == "order_medication" and "magnesium" in a["arguments"].get("drug", "")
               for a in task["evaluation_criteria"]["actions"])


def test_preeclampsia_without_severe_features_demands_no_magnesium_or_severe_range_treatment(obstetric_tasks):
    without = [t for t in obstetric_tasks if t["correct_answer"] in ("preeclampsia without severe features", "gestational hypertension",
                                                                     "chronic hypertension with superimposed preeclampsia")]
    assert any(t["correct_answer"] == "preeclampsia without severe features" for t in without)
    for t in without:
        assert not _orders_magnesium(t), t["id"]
        assert t.get("emergency") is None, t["id"]
        assert not any("severe-range" in a for a in t["evaluation_criteria"]["nl_assertions"]), t["id"]


def test_magnesium_exactly_when_severe_features_or_hellp(obstetric_tasks):
    for t in obstetric_tasks:
        severe = bool(t["metadata"]["severe_features"]) or t["metadata"]["hellp"]
        assert _orders_magnesium(t) == severe, t["id"]
        assert (t.get("emergency") == "eclampsia") == severe, t["id"]
        # Treating severe-range pressure is asked for only when the pressures were in the severe range.
        severe_bp = any(f.startswith("severe-range") for f in t["metadata"]["severe_features"])
        asks_bp = any("severe-range blood pressure" in a for a in t["evaluation_criteria"]["nl_assertions"])
        assert asks_bp == severe_bp, t["id"]


def test_hypertensive_categories_carry_their_acog_synonyms(obstetric_tasks):
    by_gold = {t["correct_answer"]: t for t in obstetric_tasks}
    assert "severe preeclampsia" in by_gold["preeclampsia with severe features"]["answer_aliases"]
    assert "superimposed preeclampsia" in by_gold["chronic hypertension with superimposed preeclampsia"]["answer_aliases"]


# -- radiology_report and visual_diagnosis: Fleischner 2017 scope --------------------------------------
@pytest.fixture(scope="module")
def radiology():
    from envs.domains.radiology_report import build as rad_build
    from envs.domains.radiology_report import generate as G
    from envs.domains.radiology_report.data_model import ReportTemplate

    templates = {k: ReportTemplate(key=k, **v)
                 for k, v in json.loads((rad_build.HERE / "templates.json").read_text())["templates"].items()}
    studies, tasks = G.generate(rad_build.SEED, {k: t.critical_categories for k, t in templates.items()})
    return {s.study_id: s for s in studies}, tasks


def _study_id(task: dict) -> str:
    return task["id"].rsplit("_", 1)[-1]


def test_radiology_never_applies_fleischner_to_known_malignancy(radiology):
    studies, tasks = radiology
    checked = 0
    for t in tasks:
        if t["description"]["task_type"] not in ("fleischner", "report_workflow"):
            continue
        s = studies[_study_id(t)]
        if s.region != "chest" or s.modality != "CT":
            continue
        known_cancer = bool(STAGING.search(s.indication) or STAGING.search(s.patient.history))
        assert known_cancer == bool(s.patient.known_malignancy), s.study_id
        if known_cancer:
            checked += 1
            assert t["correct_answer"] not in FLEISCHNER_CATEGORIES, t["id"]
            assert t["correct_answer"] == "oncologic staging follow-up", t["id"]
            assert "MacMahon" in t["description"]["provenance"]["guideline"]
            assert not any(a["name"] == "fleischner_recommendation" for a in t["evaluation_criteria"]["actions"])
        else:
            assert t["correct_answer"] in FLEISCHNER_CATEGORIES, t["id"]
    assert checked >= 3  # the known-malignancy cases exist and are graded as such


def test_radiology_fleischner_tool_declines_a_staging_ct(radiology):
    from envs.domains.radiology_report import build as rad_build

    rad_build.build()
    env = registry.get_environment("radiology_report")
    staged = [s.study_id for s in radiology[0].values() if s.patient.known_malignancy]
    assert staged
    for sid in staged:
        out = env.toolkit.call("fleischner_recommendation", {"study_id": sid})
        assert out.error is None, out.error
        assert out.result["applicable"] is False and out.result["category"] == "oncologic staging follow-up", sid
    # Explicit inputs without a study still get the guideline's table.
    out = env.toolkit.call("fleischner_recommendation", {"nodule_type": "solid", "size_mm": 7, "multiple": False, "risk": "low"})
    assert out.result["category"] == "CT at 6-12 months"


@pytest.fixture(scope="module")
def visual():
    from envs.domains.visual_diagnosis import build as vis_build

    vis_build.build()
    env = registry.get_environment("visual_diagnosis")
    return env, registry.get_tasks("visual_diagnosis")


def test_visual_never_applies_fleischner_to_known_malignancy(visual):
    env, tasks = visual
    checked = 0
    for t in tasks:
        sid = t.metadata.get("study_id")
        study = env.toolkit.call("get_study_metadata", {"study_id": sid}) if sid else None
        if study is None or study.error is not None or study.result["modality"] != "CT":
            continue
        history = env.toolkit.call("get_clinical_history", {"study_id": sid}).result
        known_cancer = bool(STAGING.search(study.result["indication"]) or STAGING.search(history["history"]))
        assert known_cancer == bool(history["known_malignancy"]), sid
        if known_cancer:  # generated and authored alike: never a Fleischner category as gold
            assert t.correct_answer not in FLEISCHNER_CATEGORIES, t.id
        if t.description.task_type == "ct_fleischner" or t.correct_answer == "oncologic staging follow-up":
            if known_cancer:
                checked += 1
                assert t.correct_answer == "oncologic staging follow-up", t.id
                out = env.toolkit.call("fleischner_recommendation", {"study_id": sid})
                assert out.error is None and out.result["applicable"] is False, t.id
            else:
                assert t.correct_answer in FLEISCHNER_CATEGORIES, t.id
    assert checked >= 4  # generated cases and the authored breast-cancer staging CT


def test_authored_radiology_staging_ct_is_not_given_a_fleischner_category():
    from envs.domains.radiology_report import build as rad_build

    rad_build.build()
    env = registry.get_environment("radiology_report")
    checked = 0
    for t in registry.get_tasks("radiology_report"):
        sids = set(re.findall(r"\bRAD-\d{3}\b", t.ticket))
        for sid in sids:
            study = env.toolkit.call("get_study", {"study_id": sid}).result
            history = env.toolkit.call("get_patient_history", {"study_id": sid}).result
            if study["region"] != "chest" or study["modality"] != "CT":
                continue
            if STAGING.search(study["indication"]) or STAGING.search(history["history"]):
                checked += 1
                assert history["known_malignancy"], sid
                assert t.correct_answer not in FLEISCHNER_CATEGORIES, t.id
    assert checked >= 8  # the 7 staging CTs the seeded generator draws and the authored colon-cancer case


# -- triage_emergency: vital signs the complaint implies ------------------------------------------------
@pytest.fixture(scope="module")
def vignettes():
    from envs.domains.triage_emergency import generate as G

    return G.esi_vignette_tasks(110)


def test_every_vignette_has_the_vital_signs_its_complaint_implies(vignettes):
    from envs.domains.triage_emergency import generate as G

    for t in vignettes:
        c, v, age = t.metadata["complaint"], t.metadata["vitals"], t.metadata["inputs"]["age_years"]
        if "cardiac arrest" in c:  # no pulse, no blood pressure, ventilated
            assert v["heart_rate"] is None and v["systolic_bp"] is None and v["spo2"] is None, t.id
            assert "no palpable pulse" in t.ticket and "bag-valve-mask" in t.ticket
            continue
        assert 30 <= v["heart_rate"] <= 200 and 60 <= v["systolic_bp"] <= 220 and 60 <= v["spo2"] <= 100, t.id
        assert v["diastolic_bp"] < v["systolic_bp"], t.id
        assert f"HR {v['heart_rate']}," in t.ticket and f"SpO2 {v['spo2']}%" in t.ticket
        if "apnoeic" in c:
            assert v["respiratory_rate"] <= 6 and v["spo2"] < 90, t.id
        else:
            assert v["respiratory_rate"] >= 10, t.id
        if "fever" in c:
            assert v["temperature_c"] >= 38.0, t.id
        elif "cellulitis" not in c:  # only an infection may be febrile without saying so
            assert v["temperature_c"] < 38.0, t.id
        if "haematemesis" in c and "clammy" in c:  # haemorrhagic shock
            assert v["heart_rate"] > 100 and v["systolic_bp"] < 100, t.id
        if "stridor" in c:
            assert v["respiratory_rate"] > 20 and v["spo2"] < 95, t.id
        if "asthma" in c:
            assert v["respiratory_rate"] >= 20, t.id
        ranges = G.vital_ranges(c, t.metadata["danger_zone_draw"], age)
        for name, r in ranges.items():
            assert r is not None and r[0] <= v[name] <= r[1], (t.id, name)


def test_vignette_gold_follows_the_esi_algorithm_on_the_stated_vitals(vignettes):
    for t in vignettes:
        inputs = t.metadata["inputs"]
        assert str(CALCULATORS["calculate_esi_level"](**inputs).score) == t.correct_answer, t.id
        assert inputs["heart_rate"] == t.metadata["vitals"]["heart_rate"]


# -- radiology_report: ACR TI-RADS combinations ---------------------------------------------------------
def test_no_generated_thyroid_nodule_has_an_impossible_tirads_combination(radiology):
    from envs.domains.radiology_report import generate as G

    nodules = [f for s in radiology[0].values() for f in s.findings if f.kind == "thyroid_nodule"]
    assert len(nodules) >= 60
    for f in nodules:
        feats = {k: getattr(f, k) for k in ("composition", "echogenicity", "shape", "margin", "echogenic_foci")}
        assert G.tirads_implausibility(feats) is None, (f, feats)
        if f.composition == "cystic":  # nothing solid to extend beyond the capsule
            assert f.margin != "extrathyroidal_extension" and f.echogenicity == "anechoic"
        else:
            assert f.echogenicity != "anechoic"


@pytest.mark.parametrize("feats", [
    {"composition": "cystic", "echogenicity": "anechoic", "shape": "wider_than_tall", "margin": "extrathyroidal_extension",
     "echogenic_foci": ["none"]},
    {"composition": "solid", "echogenicity": "anechoic", "shape": "wider_than_tall", "margin": "smooth", "echogenic_foci": ["none"]},
    {"composition": "cystic", "echogenicity": "anechoic", "shape": "wider_than_tall", "margin": "smooth", "echogenic_foci": ["punctate"]},
    {"composition": "spongiform", "echogenicity": "very_hypoechoic", "shape": "wider_than_tall", "margin": "smooth",
     "echogenic_foci": ["none"]},
    # ACR TI-RADS: reconsider "spongiform" with suspicious echogenic foci (RAD-126 read spongiform with punctate foci)
    {"composition": "spongiform", "echogenicity": "isoechoic", "shape": "wider_than_tall", "margin": "smooth",
     "echogenic_foci": ["macrocalcifications", "punctate"]},
    {"composition": "spongiform", "echogenicity": "hyperechoic", "shape": "wider_than_tall", "margin": "smooth",
     "echogenic_foci": ["peripheral_rim"]},
])
def test_impossible_tirads_combinations_are_named(feats):
    from envs.domains.radiology_report import generate as G

    assert G.tirads_implausibility(feats)


def test_a_spongiform_nodule_with_comet_tails_or_no_foci_is_plausible():
    from envs.domains.radiology_report import generate as G

    for foci in (["none"], ["large_comet_tail"]):
        assert G.tirads_implausibility({"composition": "spongiform", "echogenicity": "isoechoic", "shape": "wider_than_tall",
                                        "margin": "smooth", "echogenic_foci": foci}) is None


# -- clinical_diagnosis: rare-disease vignettes the differential identifies -------------------------------
def test_every_rare_disease_vignette_ranks_its_gold_in_the_top_three_of_generate_ddx():
    from envs.domains.clinical_diagnosis import build as cd_build

    cd_build.build()
    env = registry.get_environment("clinical_diagnosis")
    tasks = [t for t in registry.get_tasks("clinical_diagnosis") if t.description.task_type == "rare_disease_dx"]
    assert len(tasks) >= 300
    for t in tasks:
        out = env.toolkit.call("generate_ddx", {"findings": t.metadata["phenotypes"], "scope": "rare", "top_k": 3})
        assert out.error is None, out.error
        assert t.metadata["disease_id"] in [d["disease_id"] for d in out.result["differential"]], t.id
        # Built from features the disease shows at least frequently (HPO >= 30 %), never occasional ones.
        for label in t.metadata["phenotype_frequencies"].values():
            assert label in ("frequent (30-79%)", "very frequent (80-99%)", "obligate (100%)"), (t.id, label)
        assert t.options[t.correct_answer] == t.answer_aliases[0]


# -- every generated task names its guideline ---------------------------------------------------------------
# Every domain with a data build generates tasks and is checked here, a new one included.
GENERATING_DOMAINS = [d for d in registry.list_domains() if (registry.DOMAINS_DIR / d / "build.py").is_file()]


@pytest.mark.parametrize("domain", GENERATING_DOMAINS)
def test_every_task_names_the_guideline_or_label_it_follows(domain):
    import importlib

    importlib.import_module(f"envs.domains.{domain}.build").build(offline=True)  # skipped when up to date
    generated = json.loads((domain_build_dir(domain) / "tasks.json").read_text(encoding="utf-8"))
    assert generated, f"{domain}: no generated tasks"
    tasks = registry.get_tasks(domain)  # generated and authored
    assert len(tasks) >= len(generated)
    missing = [t.id for t in tasks if not (t.description.provenance.get("guideline") or "").strip()]
    assert not missing, f"{domain}: {len(missing)} tasks name no guideline, e.g. {missing[:5]}"
