"""Synthetic imaging studies with structured findings (our code, seeded) and their generated tasks.

Gold categories are computed by `envs.calculators` (TI-RADS, BI-RADS, Fleischner 2017,
Lung-RADS v2022) on the study's recorded features, with the same derivations the tools use
(maximum diameter, mean of the axes, interval change against the prior screen).
"""

from __future__ import annotations

import random
from typing import Any

from envs.calculators import CALCULATORS
from envs.domains.radiology_report.data_model import (KNOWN_MALIGNANCY_ALIASES, KNOWN_MALIGNANCY_GUIDELINE, KNOWN_MALIGNANCY_MANAGEMENT,
                                                      Finding, PatientInfo, PriorStudy, Study)
from envs.domains.radiology_report.tools import mean_diameter

PROVENANCE = {"source": "authored", "generator": "envs.domains.radiology_report.generate", "license": "project (ours)"}
COMPOSITION = ["cystic", "spongiform", "mixed", "solid"]
ECHO = ["anechoic", "hyperechoic", "isoechoic", "hypoechoic", "very_hypoechoic"]
MARGIN = ["smooth", "ill_defined", "lobulated_irregular", "extrathyroidal_extension"]
FOCI = [["none"], ["large_comet_tail"], ["macrocalcifications"], ["peripheral_rim"], ["punctate"], ["macrocalcifications", "punctate"]]
LOBES = ["right upper lobe", "right middle lobe", "right lower lobe", "left upper lobe", "lingula", "left lower lobe"]


def act(name: str, arguments: dict, compare: list[str] | None = None) -> dict:
    return {"name": name, "arguments": arguments, "compare_args": list(arguments) if compare is None else compare}


# The guideline or reporting system each generated task type's gold follows (in the task's provenance).
GUIDELINES = {
    "tirads_category": "ACR TI-RADS (Tessler et al., J Am Coll Radiol 2017;14:587-595)",
    "tirads_management": "ACR TI-RADS (Tessler et al., J Am Coll Radiol 2017;14:587-595), FNA and follow-up size thresholds",
    "birads_category": "ACR BI-RADS Atlas, 5th edition (2013)",
    "fleischner": "Fleischner Society 2017 guidelines for incidental pulmonary nodules (MacMahon et al., Radiology 2017;284:228-243)",
    "lung_rads": "ACR Lung-RADS v2022",
    "report_workflow": "ACR Practice Parameter for Communication of Diagnostic Imaging Findings (2020); ACR TI-RADS 2017, BI-RADS 5th ed., "
                       "Fleischner 2017, Lung-RADS v2022",
}


def task_dict(task_id: str, ticket: str, answer: str, answer_type: str, task_type: str, actions: list[dict], category: str,
              metadata: dict | None = None, aliases: list[str] | None = None, assertions: list[str] | None = None,
              difficulty: str = "medium", guideline: str | None = None) -> dict:
    t: dict[str, Any] = {
        "id": task_id, "ticket": ticket, "correct_answer": answer, "answer_type": answer_type,
        "description": {"purpose": f"Radiology reporting: {category}.", "difficulty": difficulty, "source": "generated",
                        "category": category, "task_type": task_type,
                        "provenance": {**PROVENANCE, "guideline": guideline or GUIDELINES[task_type]}},
        "evaluation_criteria": {"actions": actions, "nl_assertions": assertions or [],
                                "reward_basis": ["ACTION", "ANSWER"] + (["NL_ASSERTION"] if assertions else [])},
        "metadata": metadata or {},
    }
    if aliases:
        t["answer_aliases"] = aliases
    return t


def narrative(s: Study) -> str:
    """The findings in words, as a preliminary read would dictate them."""
    parts = []
    for f in s.findings:
        if f.kind == "thyroid_nodule":
            dims = " x ".join(f"{d:g}" for d in f.dimensions_cm)
            foci = ", ".join(x.replace("_", " ") for x in f.echogenic_foci)
            parts.append(f"{f.location}: {dims} cm {f.composition} {f.echogenicity.replace('_', ' ')} nodule, "
                         f"{f.shape.replace('_', '-')}, {f.margin.replace('_', ' ')} margin, echogenic foci: {foci}")
        elif f.kind == "lung_nodule":
            extra = f" (solid component {f.solid_long_mm:g} x {f.solid_short_mm:g} mm)" if f.solid_long_mm else ""
            feats = f", {', '.join(f.suspicious_features)}" if f.suspicious_features else ""
            parts.append(f"{f.location}: {f.long_axis_mm:g} x {f.short_axis_mm:g} mm {f.nodule_type.replace('_', ' ')} nodule{extra}{feats}")
        elif f.kind.startswith("breast"):
            size = f"{f.size_mm:g} mm " if f.size_mm else ""
            parts.append(f"{f.location}: {size}{f.description}")
    return "; ".join(parts) if parts else "no focal abnormality described"


def _patient(rng: random.Random, sex: str | None = None, *, smoker: bool | None = None, age: tuple[int, int] = (28, 80)) -> PatientInfo:
    sex = sex or rng.choice(["female", "male"])
    smoker = rng.random() < 0.5 if smoker is None else smoker
    pack = float(rng.choice([20, 25, 30, 40, 45])) if smoker else 0.0
    return PatientInfo(age=rng.randint(*age), sex=sex, history=rng.choice(["no relevant history", "hypertension", "type 2 diabetes",
                                                                          "prior appendectomy", "hypothyroidism"]),
                       smoking_pack_years=pack, lung_cancer_risk="high" if smoker else "low",
                       risk_factors=[f"{pack:g} pack-year smoking history"] if smoker else ["never smoker", "no family history of lung cancer"])


# -- thyroid ---------------------------------------------------------------------------------------
def tirads_implausibility(feats: dict) -> str | None:
    """Why a combination of ACR TI-RADS features cannot occur in one nodule, or None if it can.

    From the ACR TI-RADS lexicon (Grant et al., J Am Coll Radiol 2015;12:1272-1279; Tessler et al.
    2017): "anechoic" describes a cystic or almost completely cystic nodule and nothing else, so a
    cyst is anechoic and a solid, mixed or spongiform nodule is not; a purely cystic nodule has no
    solid tissue to invade, lobulate or calcify (no extrathyroidal extension, irregular or
    ill-defined margin, taller-than-wide shape, punctate foci, macro- or rim calcification); a
    spongiform nodule (> 50 % small cystic spaces) is iso- or hyperechoic, with smooth or
    ill-defined margins and no extrathyroidal extension; large comet-tail artefacts arise in
    colloid within cystic spaces, so not in a solid nodule. Spongiform is the benign appearance
    that takes no further points (Tessler 2017), and ACR's TI-RADS guidance is to reconsider
    "spongiform" where there are suspicious echogenic foci: a spongiform nodule carries no
    point-scoring foci (macrocalcifications, rim calcification, punctate foci), only none or
    comet-tail artefacts.
    """
    comp, echo, margin, shape, foci = (feats["composition"], feats["echogenicity"], feats["margin"], feats["shape"],
                                       set(feats["echogenic_foci"]))
    if (comp == "cystic") != (echo == "anechoic"):
        return f"echogenicity {echo!r} with composition {comp!r} ('anechoic' is exactly the cystic nodule)"
    if comp == "cystic":
        if margin != "smooth":
            return f"a purely cystic nodule with a {margin!r} margin"
        if shape != "wider_than_tall":
            return "a purely cystic nodule that is taller than wide"
        if foci - {"none", "large_comet_tail"}:
            return f"a purely cystic nodule with echogenic foci {sorted(foci)}"
    if comp == "spongiform":
        if echo not in ("isoechoic", "hyperechoic"):
            return f"a spongiform nodule that is {echo!r}"
        if margin not in ("smooth", "ill_defined"):
            return f"a spongiform nodule with a {margin!r} margin"
        if foci - {"none", "large_comet_tail"}:
            return f"a spongiform nodule with echogenic foci {sorted(foci)} (reconsider spongiform)"
    if comp == "solid" and "large_comet_tail" in foci:
        return "large comet-tail artefacts in a solid nodule"
    return None


def thyroid_study(sid: str, rng: random.Random, want_level: int | None) -> tuple[Study, Any]:
    for _ in range(5000):
        comp = rng.choice(COMPOSITION)
        feats = {"composition": comp, "echogenicity": rng.choice(ECHO), "shape": rng.choice(["wider_than_tall"] * 3 + ["taller_than_wide"]),
                 "margin": rng.choice(MARGIN), "echogenic_foci": rng.choice(FOCI)}
        dims = sorted([round(rng.uniform(0.4, 3.2), 1) for _ in range(3)], reverse=True)
        if comp == "spongiform" and set(feats["echogenic_foci"]) - {"none", "large_comet_tail"}:
            # a spongiform nodule has no point-scoring foci (tirads_implausibility); set, not redrawn, so every
            # other study keeps its draws (spongiform scores TR1 whatever the foci)
            feats["echogenic_foci"] = ["none"]
        if tirads_implausibility(feats):
            continue
        res = CALCULATORS["calculate_tirads"](**feats, max_diameter_cm=dims[0])
        if want_level is None or res.category == f"TR{want_level}":
            break
    else:
        raise RuntimeError(f"{sid}: no plausible ACR TI-RADS feature set reached TR{want_level}")
    f = Finding(finding_id="N1", kind="thyroid_nodule", location=rng.choice(["right lobe, mid pole", "left lobe, lower pole",
                                                                              "right lobe, upper pole", "isthmus", "left lobe, mid pole"]),
                dimensions_cm=dims, **feats)
    s = Study(study_id=sid, modality="US", region="thyroid", exam="US thyroid",
              indication=rng.choice(["palpable neck lump", "incidental thyroid nodule on CT", "goitre follow-up", "abnormal TSH"]),
              technique="High-frequency linear-array grey-scale and colour Doppler ultrasound of the thyroid.",
              patient=_patient(rng, rng.choice(["female", "female", "male"])), findings=[f], provenance=PROVENANCE)
    return s, res


def tirads_task(sid: str, rng: random.Random, i: int) -> tuple[Study, list[dict]]:
    s, res = thyroid_study(sid, rng, [1, 2, 3, 4, 5][i % 5])
    ticket = (f"Thyroid ultrasound {sid} ({s.patient.age}-year-old {s.patient.sex}, indication: {s.indication}). Preliminary read: {narrative(s)}. "
              + rng.choice(["Assign the ACR TI-RADS level of the nodule.", "What is the ACR TI-RADS category (TR1-TR5) of the nodule?",
                            "Score the nodule with ACR TI-RADS and give its TR level."]))
    return s, [task_dict(f"rad_tirads_{sid}", ticket, res.category, "category", "tirads_category",
                         [act("analyze_findings", {"study_id": sid}), act("calculate_tirads", {"study_id": sid}, ["study_id"])],
                         "thyroid nodule classification", {"points": res.score}, aliases=[f"TI-RADS {res.category}"])]


def tirads_management_task(sid: str, rng: random.Random, i: int) -> tuple[Study, list[dict]]:
    s, res = thyroid_study(sid, rng, [3, 4, 5, 4, 3][i % 5])
    # Choose the size so that FNA, follow-up and neither are equally represented.
    thresholds = {"TR3": (2.5, 1.5), "TR4": (1.5, 1.0), "TR5": (1.0, 0.5)}[res.category]
    outcome = i % 3
    size = [thresholds[0] + rng.choice([0.2, 0.6, 1.1]), (thresholds[0] + thresholds[1]) / 2, thresholds[1] - 0.2][outcome]
    f = s.findings[0]
    f.dimensions_cm = sorted([round(size, 1), round(size * 0.8, 1), round(size * 0.6, 1)], reverse=True)
    feats = {k: getattr(f, k) for k in ("composition", "echogenicity", "shape", "margin", "echogenic_foci")}
    res = CALCULATORS["calculate_tirads"](**feats, max_diameter_cm=f.dimensions_cm[0])
    advice = res.components["recommendation"]
    gold = "fine-needle aspiration" if advice.startswith("FNA") else "ultrasound follow-up" if advice.startswith("follow-up") else "no FNA or follow-up"
    ticket = (f"Thyroid ultrasound {sid} ({s.patient.age}-year-old {s.patient.sex}, {s.indication}): {narrative(s)}. Using ACR TI-RADS and the "
              "nodule's size, what does the guideline recommend: fine-needle aspiration, ultrasound follow-up, or no FNA or follow-up?")
    return s, [task_dict(f"rad_tirmgmt_{sid}", ticket, gold, "exact", "tirads_management",
                         [act("analyze_findings", {"study_id": sid}), act("calculate_tirads", {"study_id": sid}, ["study_id"])],
                         "thyroid nodule management", {"level": res.category, "advice": advice},
                         aliases={"fine-needle aspiration": ["FNA", "FNA recommended", "fine needle aspiration biopsy"],
                                  "ultrasound follow-up": ["follow-up ultrasound", "sonographic follow-up", "US follow-up"],
                                  "no FNA or follow-up": ["no further evaluation", "no follow-up needed"]}[gold])]


# -- breast ------------------------------------------------------------------------------------------
# Each finding comes with the indications it can be imaged for (ACR BI-RADS Atlas, 5th ed., 2013): a screening
# examination is assessed 0, 1 or 2 only, so suspicious findings are worked up after a screening recall or for a
# symptom; category 3 is for a non-palpable finding at diagnostic work-up of a baseline screening recall (a
# palpable mass at >= 40 years gets diagnostic mammography and ultrasound: ACR Appropriateness Criteria,
# Palpable Breast Masses, 2022); a finding unchanged for years has prior films; category 6 is a biopsy-proven
# cancer imaged before surgery. Screening indications get a screening exam (`breast_exam`).
SCREENING = "routine screening"
CALC_RECALL = "screening recall for calcifications"
BREAST_PLAN = [
    {"mass": ("oval", "circumscribed", True, False, "simple cyst"), "indications": ["palpable lump", "screening recall"]},
    {"mass": ("oval", "circumscribed", False, False, "solid oval circumscribed mass, no prior films"),
     "indications": ["baseline screening recall"]},
    {"mass": ("oval", "circumscribed", False, True, "circumscribed mass unchanged for 3 years"),
     "indications": [SCREENING, "follow-up of a prior finding"]},
    {"mass": ("irregular", "spiculated", False, False, "irregular spiculated mass"), "indications": ["palpable lump", "screening recall"]},
    {"mass": ("irregular", "indistinct", False, False, "irregular mass with indistinct margins"),
     "indications": ["palpable lump", "screening recall"]},
    {"mass": ("round", "microlobulated", False, False, "round microlobulated mass"), "indications": ["palpable lump", "screening recall"]},
    {"calc": "amorphous", "indications": [CALC_RECALL]}, {"calc": "fine_pleomorphic", "indications": [CALC_RECALL, "nipple discharge"]},
    {"calc": "fine_linear_branching", "indications": [CALC_RECALL, "nipple discharge"]},
    {"calc": "typically_benign", "indications": [SCREENING, CALC_RECALL]},
    {"calc": "coarse_heterogeneous", "indications": [CALC_RECALL]}, {"distortion": True, "indications": ["screening recall"]},
    {"mass": ("oval", "obscured", False, False, "partially obscured mass"), "indications": [SCREENING]},
    {"incomplete": True, "mass": ("oval", "circumscribed", False, False, "possible mass seen on one view only"),
     "indications": [SCREENING]},
    {"malignant": True, "mass": ("irregular", "spiculated", False, False, "biopsy-proven carcinoma before surgery"),
     "indications": ["pre-operative staging of biopsy-proven carcinoma"]},
    {"none": True, "indications": [SCREENING, "nipple discharge"]},
]


def breast_exam(indication: str) -> tuple[str, str]:
    """The examination (and its technique) an indication calls for: a screening or a diagnostic mammogram."""
    if indication == SCREENING:
        return "MG bilateral screening mammogram", "Bilateral CC and MLO views."
    return "MG bilateral diagnostic mammogram", "Bilateral CC and MLO views with spot compression as needed."


def breast_study(sid: str, rng: random.Random, plan: dict) -> tuple[Study, Any]:
    side = rng.choice(["left", "right"])
    clock = rng.randint(1, 12)
    findings = []
    args = {"mass_shape": "none", "mass_margin": "none", "mass_typically_benign": False, "mass_stable_2_years": False,
            "calcification_morphology": "none", "architectural_distortion": False, "exam_complete": not plan.get("incomplete", False),
            "known_biopsy_proven_malignancy": plan.get("malignant", False)}
    if "mass" in plan:
        shape, margin, benign, stable, desc = plan["mass"]
        findings.append(Finding(finding_id="F1", kind="breast_mass", location=f"{side} breast {clock} o'clock, middle depth",
                                mass_shape=shape, mass_margin=margin, mass_typically_benign=benign, stable_2_years=stable,
                                size_mm=float(rng.randint(6, 28)), description=desc))
        args.update(mass_shape=shape, mass_margin=margin, mass_typically_benign=benign, mass_stable_2_years=stable)
    if "calc" in plan:
        findings.append(Finding(finding_id="F2", kind="breast_calcifications", location=f"{side} breast upper outer quadrant",
                                calcification_morphology=plan["calc"], size_mm=float(rng.randint(4, 20)),
                                description=f"{plan['calc'].replace('_', ' ')} calcifications, grouped"))
        args.update(calcification_morphology=plan["calc"])
    if plan.get("distortion"):
        findings.append(Finding(finding_id="F3", kind="breast_distortion", location=f"{side} breast {clock} o'clock",
                                description="architectural distortion, no prior surgery at this site"))
        args.update(architectural_distortion=True)
    res = CALCULATORS["calculate_birads"](**args)
    indication = rng.choice(plan["indications"])
    exam, technique = breast_exam(indication)
    s = Study(study_id=sid, modality="MG", region="breast", exam=exam, indication=indication,
              technique=technique, exam_complete=args["exam_complete"],
              known_biopsy_proven_malignancy=args["known_biopsy_proven_malignancy"],
              # screening (and a screening recall) from 40 years (ACR 2023; USPSTF 2024), as is diagnostic
              # mammography for a palpable mass (ACR Appropriateness Criteria 2022)
              patient=_patient(rng, "female", smoker=False, age=(40, 79)), findings=findings, provenance=PROVENANCE)
    return s, res


def birads_task(sid: str, rng: random.Random, i: int) -> tuple[Study, list[dict]]:
    s, res = breast_study(sid, rng, BREAST_PLAN[i % len(BREAST_PLAN)])
    ticket = (f"Mammogram {sid}: {s.patient.age}-year-old woman, {s.indication}"
              + ("" if s.exam_complete else " (only one view obtained so far)") + f". Preliminary read: {narrative(s)}. "
              + rng.choice(["Give the overall BI-RADS assessment category.", "What BI-RADS category should the report assign?",
                            "Assign the final BI-RADS assessment (0-6, with 4A/4B/4C where applicable)."]))
    return s, [task_dict(f"rad_birads_{sid}", ticket, res.category, "category", "birads_category",
                         [act("analyze_findings", {"study_id": sid}), act("calculate_birads", {"study_id": sid}, ["study_id"])],
                         "breast imaging classification", {"components": dict(res.components)})]


# -- chest CT (Fleischner) and screening (Lung-RADS) -----------------------------------------------
def _axes(rng: random.Random, mean_target: float) -> tuple[float, float]:
    diff = rng.choice([0, 2, 4])
    short = max(1.0, round(mean_target - diff / 2))
    return float(short + diff), float(short)


# (indication, known primary cancer): a staging CT means a known malignancy, outside Fleischner 2017.
CT_INDICATIONS = [("staging of colorectal cancer", "colorectal adenocarcinoma"), ("trauma", None), ("chest pain", None), ("cough", None),
                  ("pre-operative assessment", None)]
# Equivalent phrasings of the Fleischner 2017 intervals (the guideline's own table wording).
FLEISCHNER_ALIASES = {"CT at 6-12 months": ["CT in 6 to 12 months", "follow-up CT at 6-12 months"],
                      "CT at 3-6 months": ["CT in 3 to 6 months", "follow-up CT at 3-6 months"],
                      "optional CT at 12 months": ["CT at 12 months (optional)"],
                      "no routine follow-up": ["no routine follow-up required"]}

FLEISCHNER_PLAN = [("solid", 4, False, "low"), ("solid", 4, False, "high"), ("solid", 7, False, "low"), ("solid", 7, True, "high"),
                   ("solid", 12, False, "high"), ("solid", 12, True, "low"), ("ground_glass", 4, False, "low"), ("ground_glass", 9, False, "high"),
                   ("part_solid", 8, False, "low"), ("part_solid", 4, True, "high"), ("solid", 6, False, "high"), ("ground_glass", 14, True, "low")]


def fleischner_task(sid: str, rng: random.Random, i: int, allow_known_malignancy: bool = True) -> tuple[Study, list[dict]]:
    kind, size, multiple, risk = FLEISCHNER_PLAN[i % len(FLEISCHNER_PLAN)]
    long_, short = _axes(rng, size + rng.choice([-0.5, 0, 0.5]) if size > 3 else size)
    if (long_ + short) % 2:  # keep the mean a whole millimetre
        long_ += 1
    nodules = [Finding(finding_id="N1", kind="lung_nodule", location=rng.choice(LOBES), nodule_type=kind, long_axis_mm=long_, short_axis_mm=short,
                       solid_long_mm=2.0 if kind == "part_solid" else None, solid_short_mm=2.0 if kind == "part_solid" else None)]
    if multiple:
        nodules.append(Finding(finding_id="N2", kind="lung_nodule", location=rng.choice(LOBES), nodule_type=kind,
                               long_axis_mm=max(2.0, short - 2), short_axis_mm=max(2.0, short - 2)))
    patient = _patient(rng, smoker=risk == "high", age=(40, 82))
    indication, cancer = rng.choice(CT_INDICATIONS)
    if cancer and not allow_known_malignancy:  # the report workflow grades a Fleischner category
        indication, cancer = CT_INDICATIONS[1 + i % (len(CT_INDICATIONS) - 1)]
    if cancer:
        patient = patient.model_copy(update={"known_malignancy": cancer, "history": f"{cancer} diagnosed this month, staging in progress"})
    s = Study(study_id=sid, modality="CT", region="chest", exam="CT chest with contrast", indication=indication,
              technique="Helical CT of the chest with IV contrast, 1 mm reconstructions.", patient=patient, findings=nodules,
              provenance=PROVENANCE)
    res = CALCULATORS["fleischner_recommendation"](nodule_type=kind, size_mm=(long_ + short) / 2, multiple=multiple, risk=risk)
    question = rng.choice(["What follow-up does the Fleischner Society 2017 guideline recommend?",
                           "Give the Fleischner 2017 recommendation for this finding.",
                           "Which Fleischner 2017 follow-up applies (consider nodule type, size, number and patient risk)?"])
    actions = [act("analyze_findings", {"study_id": sid}), act("get_patient_history", {"study_id": sid}),
               act("fleischner_recommendation", {"study_id": sid}, ["study_id"])]
    if cancer:
        # Fleischner 2017 excludes known malignancy: the gold is oncologic follow-up, and the
        # question no longer presumes the guideline applies.
        ticket = (f"CT chest {sid} ({patient.age}-year-old {patient.sex}, {'; '.join(patient.risk_factors)}, done for {s.indication}) "
                  f"shows pulmonary findings: {narrative(s)}. What follow-up is appropriate for the nodule? If a guideline does not "
                  "apply to this patient, say so and give the management that does.")
        return s, [task_dict(f"rad_fleischner_{sid}", ticket, KNOWN_MALIGNANCY_MANAGEMENT, "exact", "fleischner", actions[:2],
                             "pulmonary nodule in known malignancy", {"size_mm": res.score, "risk": risk, "multiple": multiple,
                                                                      "known_malignancy": cancer},
                             aliases=KNOWN_MALIGNANCY_ALIASES, guideline=KNOWN_MALIGNANCY_GUIDELINE,
                             assertions=["The agent does not apply the Fleischner 2017 guideline because the patient has a known malignancy."])]
    ticket = (f"CT chest {sid} ({patient.age}-year-old {patient.sex}, {'; '.join(patient.risk_factors)}, done for {s.indication}) "
              f"shows incidental pulmonary findings: {narrative(s)}. " + question)
    return s, [task_dict(f"rad_fleischner_{sid}", ticket, res.category, "exact", "fleischner", actions,
                         "incidental pulmonary nodule", {"size_mm": res.score, "risk": risk, "multiple": multiple},
                         aliases=FLEISCHNER_ALIASES.get(res.category))]


LUNG_RADS_PLAN = [("none", 0, "baseline"), ("solid", 4.5, "baseline"), ("solid", 7.0, "baseline"), ("solid", 10.5, "baseline"),
                  ("solid", 17.0, "baseline"), ("solid", 5.0, "new"), ("solid", 9.0, "new"), ("solid", 7.5, "growing"),
                  ("solid", 8.5, "stable"), ("ground_glass", 12.0, "baseline"), ("ground_glass", 32.0, "baseline"),
                  ("part_solid", 9.0, "baseline"), ("perifissural", 7.0, "baseline"), ("solid", 11.0, "baseline_spiculated"),
                  ("benign_calcified_or_fat", 9.0, "baseline")]


def lung_rads_task(sid: str, rng: random.Random, i: int) -> tuple[Study, list[dict]]:
    kind, size, ctx = LUNG_RADS_PLAN[i % len(LUNG_RADS_PLAN)]
    findings, prior = [], None
    args: dict = {"nodule_type": kind}
    if kind != "none":
        long_ = round(size + rng.choice([0.4, 1.0, 1.6]), 1)
        short = round(2 * size - long_, 1)
        f = Finding(finding_id="N1", kind="lung_nodule", location=rng.choice(LOBES), nodule_type=kind, long_axis_mm=long_, short_axis_mm=short,
                    suspicious_features=["spiculated margin"] if ctx == "baseline_spiculated" else [])
        if kind == "part_solid":
            f.solid_long_mm, f.solid_short_mm = round(size / 2 + 0.5, 1), round(size / 2 - 0.5, 1)
            args["solid_component_mm"] = mean_diameter(f.solid_long_mm, f.solid_short_mm)
        findings.append(f)
        args.update(size_mm=mean_diameter(long_, short), suspicious_features=bool(f.suspicious_features))
    context = "baseline" if ctx == "baseline_spiculated" else ctx
    if context != "baseline":
        prior_findings = []
        prior_cat = "2"
        if context in ("growing", "stable"):
            shrink = 2.2 if context == "growing" else 0.4
            prior_findings.append(Finding(finding_id="N1", kind="lung_nodule", location=findings[0].location, nodule_type=kind,
                                          long_axis_mm=round(findings[0].long_axis_mm - shrink, 1),
                                          short_axis_mm=round(findings[0].short_axis_mm - shrink, 1)))
            prior_cat = "3" if context == "stable" else "2"
        prior = PriorStudy(study_id=f"{sid}-P", months_ago=12, category=prior_cat, findings=prior_findings,
                           report=f"Annual low-dose screening CT. Lung-RADS {prior_cat}.")
        args["context"] = context
        if context == "stable":
            args["prior_category"] = prior_cat
    patient = _patient(rng, smoker=True, age=(52, 77))
    s = Study(study_id=sid, modality="LDCT", region="chest", exam="Low-dose CT lung cancer screening",
              indication=f"annual lung cancer screening, {patient.smoking_pack_years:g} pack-years",
              technique="Low-dose non-contrast helical CT, 1 mm reconstructions.", patient=patient, findings=findings, prior=prior,
              provenance=PROVENANCE)
    res = CALCULATORS["calculate_lung_rads"](**args)
    gold = f"Lung-RADS {res.category}"
    ticket = (f"Screening LDCT {sid}: {patient.age}-year-old {patient.sex}, {s.indication}; findings: {narrative(s)}; "
              + ("prior screen 12 months ago. " if prior else "first screening examination. ")
              + rng.choice(["Assign the Lung-RADS v2022 category.", "What Lung-RADS category does this screen receive?",
                            "Give the Lung-RADS v2022 assessment for the most suspicious finding."]))
    actions = [act("analyze_findings", {"study_id": sid})]
    if prior:
        actions.append(act("compare_with_prior", {"study_id": sid}))
    actions.append(act("calculate_lung_rads", {"study_id": sid}, ["study_id"]))
    return s, [task_dict(f"rad_lungrads_{sid}", ticket, gold, "category", "lung_rads", actions, "lung cancer screening",
                         {"arguments": args})]


# -- report workflow ----------------------------------------------------------------------------------
def workflow_task(sid: str, rng: random.Random, i: int, critical_categories: dict[str, list[str]]) -> tuple[Study, list[dict]]:
    kind = ["thyroid", "breast", "ct", "ldct"][i % 4]
    if kind == "thyroid":
        s, res = thyroid_study(sid, rng, [2, 4, 5, 3][(i // 4) % 4])
        cat, calc, tpl = res.category, "calculate_tirads", ("US", "thyroid")
    elif kind == "breast":
        s, res = breast_study(sid, rng, BREAST_PLAN[[3, 1, 7, 0][(i // 4) % 4]])
        cat, calc, tpl = res.category, "calculate_birads", ("MG", "breast")
    elif kind == "ct":
        s, tasks = fleischner_task(sid, rng, [4, 2, 0, 7][(i // 4) % 4], allow_known_malignancy=False)
        cat, calc, tpl = tasks[0]["correct_answer"], "fleischner_recommendation", ("CT", "chest")
    else:
        s, tasks = lung_rads_task(sid, rng, [3, 4, 7, 1][(i // 4) % 4])
        cat, calc, tpl = tasks[0]["correct_answer"], "calculate_lung_rads", ("LDCT", "chest")
    key = f"{tpl[0]} {tpl[1]}" if tpl[1] != "chest" else ("LDCT chest" if tpl[0] == "LDCT" else "CT chest")
    critical = cat in critical_categories[key]
    core = cat.split()[-1] if not kind == "ct" else cat
    # the management the applicable ACR system or Fleischner 2017 attaches to the category (the
    # calculator's interpretation), written into the gold report's recommendation
    if kind in ("thyroid", "breast"):
        management = res.interpretation
    elif kind == "ldct":
        management = CALCULATORS["calculate_lung_rads"](**tasks[0]["metadata"]["arguments"]).interpretation
    else:
        management = f"Fleischner 2017: {cat}."
    actions = [act("get_study", {"study_id": sid}), act("get_report_template", {"modality": tpl[0], "region": tpl[1]}),
               act(calc, {"study_id": sid}, ["study_id"]),
               act("draft_report", {"study_id": sid, "findings": narrative(s), "impression": f"Assessment category: {core}. Management: {management}",
                                    "category": cat, "recommendation": management}, ["study_id", "category"])]
    if critical:
        actions.append(act("communicate_critical_result", {"study_id": sid, "recipient": "referring clinician", "method": "phone",
                                                           "finding": f"suspicious result ({cat}) communicated to the referring "
                                                                      "clinician by phone before the report is signed"}, ["study_id"]))
    actions.append(act("finalize_report", {"study_id": sid}))
    ticket = (f"Report study {sid} ({s.exam}; {s.patient.age}-year-old {s.patient.sex}, {s.indication}; preliminary read: {narrative(s)}). "
              "Use the structured template, "
              "assign the assessment category of the applicable ACR system, handle any result that must be communicated, and finalise "
              "the report. What category did you assign?")
    aliases = [f"TI-RADS {cat}"] if cat.startswith("TR") else []
    return s, [task_dict(f"rad_report_{sid}", ticket, cat, "category" if not kind == "ct" else "exact", "report_workflow", actions,
                         "structured reporting", {"critical": critical}, aliases=aliases,
                         assertions=["The report states the assessment category in the impression with its management recommendation.",
                                     "A suspicious result is communicated to the referring clinician before the report is signed."
                                     # ACR Practice Parameter for Communication of Diagnostic Imaging Findings
                                     # (2020): only critical or suspicious results need direct communication
                                     if critical else "The agent does not make a critical-result call to the referring clinician."],
                         difficulty="hard")]


PLAN = [("tirads", 40), ("tirmgmt", 20), ("birads", 40), ("fleischner", 36), ("lungrads", 36), ("workflow", 16)]


def generate(seed: int, critical_categories: dict[str, list[str]]) -> tuple[list[Study], list[dict]]:
    rng = random.Random(seed)
    studies, tasks = [], []
    n = 100
    makers = {"tirads": tirads_task, "tirmgmt": tirads_management_task, "birads": birads_task, "fleischner": fleischner_task,
              "lungrads": lung_rads_task}
    for kind, count in PLAN:
        for i in range(count):
            n += 1
            sid = f"RAD-{n:03d}"
            if kind == "workflow":
                s, ts = workflow_task(sid, rng, i, critical_categories)
            else:
                s, ts = makers[kind](sid, rng, i)
            studies.append(s)
            tasks += ts
    return studies, tasks
