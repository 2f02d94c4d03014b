"""The 20 authored visual-diagnosis workflows: our clinical vignettes, rendered at build time.

Each entry fixes the study (finding, side, zone, size, patient) and the workflow the reader should
follow (analysis, measurement, comparison, retrieval, glossary, records, escalation). Images are
rendered and verified like the generated ones; the answers are the vignette's ground truth or a
value the tools reproduce from the image (checked by the tests).
"""

from __future__ import annotations

import random
from pathlib import Path

from envs.calculators import CALCULATORS
from envs.domains.visual_diagnosis import analysis as A
from envs.domains.visual_diagnosis import generate as G
from envs.domains.visual_diagnosis import render as R
from envs.domains.imaging_guidelines import KNOWN_MALIGNANCY_ALIASES, KNOWN_MALIGNANCY_MANAGEMENT
from envs.domains.visual_diagnosis.data_model import PatientInfo, Study
from envs.domains.visual_diagnosis.png import write_png

PROV = {"source": "authored", "license": "project (ours)"}


def _pt(age, sex, history, pack=0.0, symptoms=(), known_malignancy=None):
    return PatientInfo(age=age, sex=sex, history=history, smoking_pack_years=pack, lung_cancer_risk="high" if pack >= 10 else "low",
                       symptoms=list(symptoms), known_malignancy=known_malignancy)


_FLEISCHNER = "Fleischner Society 2017 guidelines for incidental pulmonary nodules (MacMahon et al., Radiology 2017;284:228-243)"
# The guideline or reference each authored workflow follows, by its category.
CATEGORY_GUIDELINES = {
    "chest emergency": "BTS Guideline for Pleural Disease (Roberts et al., Thorax 2023), pneumothorax; ATLS 10th edition (tension "
                       "pneumothorax: immediate decompression)",
    "infection": "Fleischner Society Glossary of Terms for Thoracic Imaging (Hansell et al., Radiology 2008); ATS/IDSA community-acquired "
                 "pneumonia guideline (Metlay et al., Am J Respir Crit Care Med 2019)",
    "nodule surveillance": _FLEISCHNER + "; Bankier et al., Radiology 2017 (nodule measurement and growth)",
    "incidental nodule management": _FLEISCHNER,
    "nodule in known malignancy": "Fleischner 2017 scope (MacMahon et al., Radiology 2017): excludes patients with known malignancy; NCCN "
                                  "Guidelines Breast Cancer (staging work-up)",
    "lesion measurement": "Fleischner Society recommendations for measuring pulmonary nodules at CT (Bankier et al., Radiology 2017)",
    "lung cancer": "Fleischner Society Glossary (mass > 3 cm); ACCP lung cancer diagnosis and management guideline, 3rd ed. (Chest 2013)",
    "chest radiograph interpretation": "Fleischner Society Glossary of Terms for Thoracic Imaging (Hansell et al., Radiology 2008)",
    "pleural disease": "BTS Guideline for Pleural Disease (Roberts et al., Thorax 2023)",
    "cardiac size": "Cardiothoracic ratio on a PA radiograph, > 0.50 = cardiomegaly (Danzer 1919; Fleischner Society Glossary, Hansell "
                    "et al., Radiology 2008)",
    "CT nodule characterisation": "Fleischner Society Glossary (solid, part-solid, ground-glass nodule; Hansell et al., Radiology 2008)",
    "CT nodule detection": "Fleischner Society recommendations for measuring pulmonary nodules at CT (Bankier et al., Radiology 2017)",
}


def _cxr_pair(sid: str, rng: random.Random, image_dir: Path) -> tuple[Study, dict]:
    """Effusion with cardiomegaly (two findings on one film)."""
    for _ in range(40):
        seed = rng.randint(0, 10 ** 9)
        made = G.cxr_spec("pleural effusion", rng, seed, side="right")
        spec, f = made
        spec["ctr"] = round(rng.uniform(0.57, 0.62), 4)
        img, _ = R.render_cxr(spec, seed)
        out = A.analyze_cxr(img, R.CXR_SPACING_MM)
        if [x["finding"] for x in out["findings"]] == ["pleural effusion", "cardiomegaly"] and out["findings"][0]["side"] == "right" \
                and abs(out["cardiothoracic_ratio"] - spec["ctr"]) <= 0.02:
            write_png(image_dir / f"{sid}.png", img)
            s = Study(study_id=sid, modality="CR", body_part="chest", view="PA", image_file=f"images/{sid}.png", width=R.SIZE,
                      height=R.SIZE, pixel_spacing_mm=R.CXR_SPACING_MM, orientation=G.ORIENT_CXR, indication="breathlessness",
                      acquired="today", patient=_pt(81, "female", "hypertension"), provenance=PROV)
            return s, {"finding": "pleural effusion", "side": "right", "ctr": spec["ctr"]}
    raise RuntimeError(sid)


def act(name, args, compare=None):
    return {"name": name, "arguments": args, "compare_args": list(args) if compare is None else compare}


# The reasoning a complete gold submission gives with its answer (envs.validate.gold_replay submits
# metadata.gold_reasoning): the interpretation and the management each task's assertions check,
# following the guideline the task names (Fleischner 2017, BTS pleural disease 2023 / pneumothorax
# 2010, ESC heart failure 2021, ATLS for tension pneumothorax).
GOLD_REASONING = {
    "vis_a_tension_ptx": "Right pneumothorax. Because the patient is hypotensive and hypoxic, this is a suspected tension "
                         "pneumothorax: escalates immediately for needle decompression (ATLS 10th edition).",
    "vis_a_pneumonia": "Right lower zone consolidation with air bronchograms. Relates the image to the fever and productive "
                       "cough and suggests pneumonia.",
    "vis_a_effusion_heart": "Right pleural effusion and cardiomegaly together in a breathless, orthopnoeic patient: suggests "
                            "heart failure as a unifying explanation (ESC heart failure 2021); echocardiography.",
    "vis_a_growing_nodule": "The solid nodule shows growth over 12 months of about 3.5 mm in mean diameter. Interval growth "
                            "in a heavy smoker is suspicious for malignancy: recommends tissue sampling or PET/CT "
                            "(Fleischner 2017, BTS 2015).",
    "vis_a_multiple_solid": "Two solid nodules, the largest about 7 mm. Fleischner 2017 does not apply to a patient with known "
                            "cancer: the nodules are assessed within the breast-cancer staging, metastasis being considered.",
    "vis_a_cxr_nodule": "Left upper zone nodule under 30 mm. In a smoker, recommends CT chest for further characterisation.",
    "vis_a_mass": "Right lung mass larger than 30 mm in a heavy smoker with haemoptysis and weight loss: recommends urgent CT "
                  "staging and tissue diagnosis (suspected lung cancer pathway, NICE NG122).",
    "vis_a_normal": "Systematic review: no abnormality, with a cardiothoracic ratio within normal limits; no lesion is called.",
    "vis_a_cardiomegaly": "Cardiomegaly: CTR above 0.50 on a PA film. After a myocardial infarction with orthopnoea, recommends "
                          "echocardiography (ESC heart failure 2021).",
    "vis_a_aspiration": "Right lower zone consolidation after choking on food: raises aspiration pneumonia given the dysphagia "
                        "after stroke.",
    "vis_a_ggn": "A single pure ground-glass nodule of about 9 mm: Fleischner 2017 recommends CT at 6-12 months to confirm "
                 "persistence, then every 2 years to 5 years.",
    "vis_a_three_nodules": "Three nodules recorded with their sizes and types. In a colorectal cancer staging scan, metastases "
                           "are the main concern; Fleischner 2017 excludes patients with known cancer.",
    "vis_a_shrinking": "Compared with the prior, the nodule has shrunk by about 4 mm in mean diameter. Shrinkage after "
                       "pneumonia favours a resolving inflammatory lesion.",
    "vis_a_left_effusion": "Left pleural effusion with a meniscus. Given the breast cancer history, suggests diagnostic "
                           "thoracentesis with cytology for a possible malignant effusion (BTS pleural disease 2023).",
    "vis_a_large_solid": "A solid nodule of about 12 mm in a high-risk patient (emphysema, 45 pack-years): Fleischner 2017 "
                         "recommends CT at 3 months, PET/CT or tissue sampling.",
    "vis_a_nodule_side": "The nodule is on the patient's right (image left, radiological convention). Recommends CT for "
                         "characterisation.",
}


def task(tid, ticket, s: Study, root: Path, answer, answer_type, actions, assertions, category, *, unit=None, tol=None,
         options=None, aliases=None, emergency=None, truth=None):
    t = {"id": tid, "ticket": ticket, "correct_answer": answer, "answer_type": answer_type, "image_path": str(root / s.image_file),
         "description": {"purpose": "Authored image-interpretation workflow: analyse, measure, compare, retrieve, record and act.",
                         "difficulty": "hard", "source": "authored", "category": category, "task_type": "workflow",
                         "provenance": {**PROV, "guideline": CATEGORY_GUIDELINES[category]}},
         "evaluation_criteria": {"actions": actions, "nl_assertions": assertions, "reward_basis": ["ACTION", "ANSWER", "NL_ASSERTION"]},
         "metadata": {"study_id": s.study_id, "truth": truth or {},
                      **({"gold_reasoning": GOLD_REASONING[tid]} if tid in GOLD_REASONING else {})}}
    for k, v in (("answer_unit", unit), ("answer_tolerance", tol), ("options", options), ("emergency", emergency)):
        if v is not None:
            t[k] = v
    if aliases:
        t["answer_aliases"] = aliases
    return t


def build_authored(root: Path) -> tuple[list[Study], list[dict]]:
    rng = random.Random(2024)
    img_dir = root / "images"
    S, T = [], []

    def cxr(sid, kind, patient, indication, **kw):
        s, truth = G.make_cxr(sid, rng, kind, img_dir, **kw)
        s = s.model_copy(update={"patient": patient, "indication": indication, "provenance": PROV})
        S.append(s)
        return s, truth

    def ct(sid, plan, patient, indication, prior_plan=None):
        s, truth, prior = G.make_ct(sid, rng, img_dir, plan, smoker=patient.smoking_pack_years >= 10, prior_plan=prior_plan)
        s = s.model_copy(update={"patient": patient, "indication": indication, "provenance": PROV})
        S.append(s)
        if prior is not None:
            S.append(prior.model_copy(update={"patient": patient, "provenance": PROV}))
        return s, truth, prior

    s, tr = cxr("VIS-001", "pneumothorax", _pt(24, "male", "tall, thin; no lung disease", 0, ["sudden dyspnoea", "hypotension 84/50"]),
                "sudden pleuritic chest pain and breathlessness, now hypotensive", side="right")
    T.append(task("vis_a_tension_ptx", "PA chest radiograph VIS-001: a 24-year-old man with sudden chest pain who is now hypotensive and hypoxic (image attached). Interpret the film, confirm the key sign, record the finding and act. What is the finding?",
                  s, root, "pneumothorax", "exact",
                  [act("analyze_medical_image", {"study_id": "VIS-001"}),
                   act("escalate_critical_finding", {"study_id": "VIS-001", "finding": "right pneumothorax with haemodynamic compromise (suspected tension)", "recipient": "emergency physician"}, ["study_id"]),
                   act("lookup_imaging_sign", {"term": "visceral pleural line"}),
                   act("record_finding", {"study_id": "VIS-001", "finding": "pneumothorax", "side": "right", "location": "right apical and lateral"}, ["study_id", "finding", "side"])],
                  ["The agent identifies a right pneumothorax.", "Because the patient is hypotensive, the agent escalates immediately for needle decompression (suspected tension pneumothorax)."],
                  "chest emergency", aliases=["right pneumothorax", "tension pneumothorax"], emergency="tension_pneumothorax", truth=tr))

    s, tr = cxr("VIS-002", "consolidation", _pt(46, "female", "no relevant history", 0, ["fever 39 C", "productive cough"]),
                "fever and productive cough for 4 days", side="right", zone="lower")
    T.append(task("vis_a_pneumonia", "PA chest radiograph VIS-002: 46-year-old woman with fever and a productive cough (image attached). Characterise the opacity, check the sign that supports your reading, compare with similar confirmed cases and record your finding. What is the most likely diagnosis among the similar cases?",
                  s, root, "community-acquired pneumonia", "exact",
                  [act("analyze_medical_image", {"study_id": "VIS-002"}), act("lookup_imaging_sign", {"term": "air bronchogram"}),
                   act("search_similar_cases", {"study_id": "VIS-002"}, ["study_id"]),
                   act("record_finding", {"study_id": "VIS-002", "finding": "consolidation", "side": "right", "location": "right lower zone"}, ["study_id", "finding", "side"])],
                  ["The agent describes right lower zone consolidation with air bronchograms.", "The agent relates the image to the fever and cough and suggests pneumonia."],
                  "infection", truth=tr))

    s, tr = _cxr_pair("VIS-003", rng, img_dir)
    S.append(s)
    T.append(task("vis_a_effusion_heart", "PA chest radiograph VIS-003: 81-year-old woman with breathlessness and orthopnoea (image attached). Identify all findings, measure the heart size and record them. What is the cardiothoracic ratio?",
                  s, root, f"{tr['ctr']:.2f}", "numeric",
                  [act("analyze_medical_image", {"study_id": "VIS-003"}), act("measure_cardiothoracic_ratio", {"study_id": "VIS-003"}),
                   act("record_finding", {"study_id": "VIS-003", "finding": "pleural effusion", "side": "right", "location": "right base"}, ["study_id", "finding", "side"]),
                   act("record_finding", {"study_id": "VIS-003", "finding": "cardiomegaly", "side": "central", "location": "cardiac silhouette"}, ["study_id", "finding"])],
                  ["The agent reports both a right pleural effusion and cardiomegaly.", "The agent suggests heart failure as a unifying explanation."],
                  "cardiac size", tol=0.03, truth=tr))

    s, tr, prior = ct("VIS-004", [("solid", 11.0)], _pt(67, "male", "COPD", 40, ["weight loss"]), "follow-up of a right lung nodule", prior_plan=[7.5])
    n_now, n_before = tr["nodules"][0], tr["prior_nodules"][0]
    delta = round((n_now["long_mm"] + n_now["short_mm"]) / 2 - (n_before["long_mm"] + n_before["short_mm"]) / 2, 1)
    T.append(task("vis_a_growing_nodule", "Axial chest CT VIS-004: 67-year-old man, 40 pack-years, follow-up of a lung nodule (image attached; prior VIS-004-P from 12 months ago). Compare with the prior, measure the change, record the finding and find similar confirmed cases. By how many millimetres has the mean diameter grown?",
                  s, root, f"{delta:.1f}", "numeric",
                  [act("get_clinical_history", {"study_id": "VIS-004"}), act("compare_with_prior", {"study_id": "VIS-004"}),
                   act("search_similar_cases", {"study_id": "VIS-004"}, ["study_id"]),
                   act("record_finding", {"study_id": "VIS-004", "finding": "nodule", "side": n_now["side"], "location": f"{n_now['side']} lung", "size_mm": 11.0}, ["study_id", "finding"])],
                  ["The agent reports growth of the solid nodule over 12 months (about 3.5 mm).", "The agent states that interval growth in a heavy smoker is suspicious for malignancy and recommends tissue sampling or PET/CT."],
                  "nodule surveillance", unit="mm", tol=1.0, truth={"delta_mm": delta}))

    # Breast-cancer staging: a known malignancy, outside Fleischner 2017 (MacMahon et al., Radiology 2017).
    s, tr, _ = ct("VIS-005", [("solid", 7.0), ("solid", 5.0)],
                  _pt(62, "female", "ex-smoker; breast cancer diagnosed this month, staging in progress", 30, known_malignancy="breast cancer"),
                  "staging CT for breast cancer")
    T.append(task("vis_a_multiple_solid", "Axial chest CT VIS-005: 62-year-old woman, 30 pack-years, staging for breast cancer (image attached). Count and measure the nodules, then say what follow-up is appropriate (if a guideline does not apply to this patient, say so and give the management that does).",
                  s, root, KNOWN_MALIGNANCY_MANAGEMENT, "exact",
                  [act("analyze_medical_image", {"study_id": "VIS-005"}), act("get_clinical_history", {"study_id": "VIS-005"})],
                  ["The agent counts two solid nodules, the largest about 7 mm.", "The agent states that Fleischner 2017 does not apply to a patient with known cancer and that the nodules are assessed within the breast-cancer staging, metastasis being considered."],
                  "nodule in known malignancy", aliases=KNOWN_MALIGNANCY_ALIASES, truth=tr))

    s, tr, _ = ct("VIS-006", [("part_solid", 12.0)], _pt(58, "male", "no relevant history", 20), "chronic cough")
    T.append(task("vis_a_part_solid", "Axial chest CT VIS-006: 58-year-old man, 20 pack-years, chronic cough (image attached). Characterise the nodule, check the definition of its type and give the Fleischner recommendation. Which type is it?",
                  s, root, "B", "choice",
                  [act("analyze_medical_image", {"study_id": "VIS-006"}), act("lookup_imaging_sign", {"term": "part-solid nodule"}),
                   act("fleischner_recommendation", {"study_id": "VIS-006"}, ["study_id"])],
                  ["The agent identifies a part-solid nodule with a measurable solid component.", "The agent recommends CT at 3-6 months to confirm persistence."],
                  "CT nodule characterisation", options={"A": "Solid", "B": "Part-solid", "C": "Pure ground-glass"}, truth=tr))

    s, tr = cxr("VIS-007", "nodule", _pt(59, "male", "hypertension", 35, ["cough"]), "chronic cough in a smoker", side="left", zone="upper")
    x, y = (int(round(c)) for c in tr["centroid_px"])
    T.append(task("vis_a_cxr_nodule", "PA chest radiograph VIS-007: 59-year-old man, 35 pack-years, chronic cough (image attached). Locate and measure the nodule, look up the definition that applies to its size, and record it. What is its diameter in mm?",
                  s, root, f"{tr['diameter_mm']:.1f}", "numeric",
                  [act("analyze_medical_image", {"study_id": "VIS-007"}), act("measure_lesion", {"study_id": "VIS-007", "x": x, "y": y}, ["study_id"]),
                   act("lookup_imaging_sign", {"term": "pulmonary nodule"}),
                   act("record_finding", {"study_id": "VIS-007", "finding": "nodule", "side": "left", "location": "left upper zone", "size_mm": tr["diameter_mm"]}, ["study_id", "finding", "side"])],
                  ["The agent reports a left upper zone nodule under 30 mm.", "The agent recommends CT chest for further characterisation in a smoker."],
                  "lesion measurement", unit="mm", tol=2.0, truth=tr))

    s, tr = cxr("VIS-008", "mass", _pt(71, "male", "COPD", 50, ["haemoptysis", "weight loss"]), "haemoptysis and weight loss", side="right")
    T.append(task("vis_a_mass", "PA chest radiograph VIS-008: 71-year-old man, 50 pack-years, haemoptysis and weight loss (image attached). Analyse the film, size the lesion, and compare with confirmed archive cases. Which diagnosis dominates among the similar cases?",
                  s, root, "squamous cell carcinoma", "exact",
                  [act("analyze_medical_image", {"study_id": "VIS-008"}), act("search_similar_cases", {"study_id": "VIS-008"}, ["study_id"]),
                   act("record_finding", {"study_id": "VIS-008", "finding": "mass", "side": "right", "location": "right mid zone", "size_mm": tr["diameter_mm"]}, ["study_id", "finding", "side"])],
                  ["The agent identifies a right lung mass larger than 30 mm.", "The agent recommends urgent CT staging and tissue diagnosis."],
                  "lung cancer", truth=tr))

    s, tr = cxr("VIS-009", "normal", _pt(29, "female", "no relevant history"), "pre-employment screening")
    T.append(task("vis_a_normal", "PA chest radiograph VIS-009: 29-year-old woman, pre-employment screening (image attached). Review the film systematically, including heart size, and record the result. Is there any abnormality?",
                  s, root, "A", "choice",
                  [act("analyze_medical_image", {"study_id": "VIS-009"}), act("measure_cardiothoracic_ratio", {"study_id": "VIS-009"}),
                   act("record_finding", {"study_id": "VIS-009", "finding": "normal", "side": "central", "location": "whole chest"}, ["study_id", "finding"])],
                  ["The agent reports no abnormality with a normal cardiothoracic ratio.", "The agent records the film as normal, with no lesion recorded."],
                  "chest radiograph interpretation", options={"A": "No abnormality", "B": "Pulmonary nodule", "C": "Cardiomegaly", "D": "Pleural effusion"}, truth=tr))

    s, tr = cxr("VIS-010", "cardiomegaly", _pt(66, "male", "prior myocardial infarction", 20, ["orthopnoea"]), "ankle swelling and orthopnoea")
    T.append(task("vis_a_cardiomegaly", "PA chest radiograph VIS-010: 66-year-old man after a myocardial infarction with orthopnoea (image attached). Measure the cardiothoracic ratio, look up its threshold, and record the finding. What is the CTR?",
                  s, root, f"{tr['ctr']:.2f}", "numeric",
                  [act("measure_cardiothoracic_ratio", {"study_id": "VIS-010"}), act("lookup_imaging_sign", {"term": "cardiothoracic ratio"}),
                   act("record_finding", {"study_id": "VIS-010", "finding": "cardiomegaly", "side": "central", "location": "cardiac silhouette"}, ["study_id", "finding"])],
                  ["The agent reports cardiomegaly (CTR above 0.50 on a PA film).", "The agent recommends echocardiography."], "cardiac size", tol=0.03, truth=tr))

    s, tr = cxr("VIS-011", "consolidation", _pt(79, "male", "stroke with dysphagia", 0, ["fever"]), "fever after a choking episode", side="right", zone="lower")
    T.append(task("vis_a_aspiration", "PA chest radiograph VIS-011: 79-year-old man with dysphagia after a stroke, febrile after choking on food (image attached). Localise the opacity, compare with archived cases, and record it. In which zone is the consolidation?",
                  s, root, "lower", "exact",
                  [act("analyze_medical_image", {"study_id": "VIS-011"}), act("search_similar_cases", {"study_id": "VIS-011"}, ["study_id"]),
                   act("record_finding", {"study_id": "VIS-011", "finding": "consolidation", "side": "right", "location": "right lower zone"}, ["study_id", "finding", "side"])],
                  ["The agent localises the consolidation to the right lower zone.", "The agent raises aspiration pneumonia given the dysphagia."],
                  "infection", aliases=["right lower zone", "lower zone"], truth=tr))

    s, tr = cxr("VIS-012", "pneumothorax", _pt(72, "male", "severe COPD", 45, ["sudden dyspnoea"]), "sudden breathlessness", side="left")
    T.append(task("vis_a_secondary_ptx", "PA chest radiograph VIS-012: 72-year-old man with severe COPD and sudden breathlessness, haemodynamically stable (image attached). Identify the finding and its side, compare with archive cases and record it. Which type of pneumothorax do the similar cases suggest?",
                  s, root, "secondary pneumothorax (COPD)", "exact",
                  [act("analyze_medical_image", {"study_id": "VIS-012"}), act("search_similar_cases", {"study_id": "VIS-012"}, ["study_id"]),
                   act("record_finding", {"study_id": "VIS-012", "finding": "pneumothorax", "side": "left", "location": "left apical and lateral"}, ["study_id", "finding", "side"])],
                  ["The agent identifies a left pneumothorax.", "The agent notes that secondary pneumothorax in COPD usually needs drainage and admission."],
                  "chest emergency", aliases=["secondary pneumothorax"], truth=tr))

    s, tr, _ = ct("VIS-013", [("ground_glass", 9.0)], _pt(52, "female", "no relevant history", 0), "abdominal CT lung bases")
    res = CALCULATORS["fleischner_recommendation"](nodule_type="ground_glass", size_mm=9.0, multiple=False, risk="low")
    T.append(task("vis_a_ggn", "Axial chest CT VIS-013: 52-year-old never-smoker (image attached). Characterise and measure the nodule, then give the Fleischner 2017 follow-up. What is the recommendation?",
                  s, root, res.category, "exact",
                  [act("analyze_medical_image", {"study_id": "VIS-013"}), act("lookup_imaging_sign", {"term": "ground-glass opacity"}),
                   act("fleischner_recommendation", {"study_id": "VIS-013"}, ["study_id"])],
                  ["The agent identifies a single pure ground-glass nodule of about 9 mm.", "The agent recommends CT at 6-12 months to confirm persistence, then every 2 years to 5 years."],
                  "incidental nodule management", truth=tr))

    s, tr, _ = ct("VIS-014", [("solid", 12.0), ("solid", 8.0), ("ground_glass", 6.0)], _pt(64, "male", "colorectal cancer", 10, known_malignancy="colorectal adenocarcinoma"), "staging of colorectal cancer")
    T.append(task("vis_a_three_nodules", "Axial chest CT VIS-014: 64-year-old man staged for colorectal cancer (image attached). Detect and record every nodule. How many nodules are there?",
                  s, root, "3", "numeric",
                  [act("analyze_medical_image", {"study_id": "VIS-014"}),
                   act("record_finding", {"study_id": "VIS-014", "finding": "nodule", "side": tr["nodules"][0]["side"], "location": "largest nodule", "size_mm": 12.0}, ["study_id", "finding"])],
                  ["The agent reports three nodules with their sizes and types.", "The agent raises metastases as the main concern in a cancer-staging scan."],
                  "CT nodule detection", tol=0, truth=tr))

    s, tr, prior = ct("VIS-015", [("solid", 8.0)], _pt(44, "female", "recent pneumonia", 0), "follow-up after pneumonia", prior_plan=[12.0])
    n_now, n_before = tr["nodules"][0], tr["prior_nodules"][0]
    delta = round((n_now["long_mm"] + n_now["short_mm"]) / 2 - (n_before["long_mm"] + n_before["short_mm"]) / 2, 1)
    T.append(task("vis_a_shrinking", "Axial chest CT VIS-015: 44-year-old woman, follow-up after pneumonia (image attached; prior VIS-015-P). Compare with the prior and interpret the change. By how many millimetres has the mean diameter changed (negative if smaller)?",
                  s, root, f"{delta:.1f}", "numeric",
                  [act("compare_with_prior", {"study_id": "VIS-015"}), act("get_clinical_history", {"study_id": "VIS-015"})],
                  ["The agent reports that the nodule has shrunk by about 4 mm.", "The agent interprets shrinkage as favouring a resolving inflammatory lesion."],
                  "nodule surveillance", unit="mm", tol=1.0, truth={"delta_mm": delta}))

    s, tr = cxr("VIS-016", "pleural effusion", _pt(58, "female", "breast cancer", 0, ["breathlessness"]), "breathlessness in known breast cancer", side="left")
    T.append(task("vis_a_left_effusion", "PA chest radiograph VIS-016: 58-year-old woman with breast cancer and breathlessness (image attached). Identify the finding and its side, look up the sign that confirms it and record it. On which side is the effusion?",
                  s, root, "left", "exact",
                  [act("analyze_medical_image", {"study_id": "VIS-016"}), act("lookup_imaging_sign", {"term": "meniscus sign"}),
                   act("record_finding", {"study_id": "VIS-016", "finding": "pleural effusion", "side": "left", "location": "left base"}, ["study_id", "finding", "side"])],
                  ["The agent reports a left pleural effusion with a meniscus.", "The agent suggests thoracentesis with cytology given the cancer history."],
                  "pleural disease", aliases=["left side", "patient's left"], truth=tr))

    s, tr, _ = ct("VIS-017", [("solid", 12.0)], _pt(69, "male", "emphysema", 45), "chronic cough")
    res = CALCULATORS["fleischner_recommendation"](nodule_type="solid", size_mm=12.0, multiple=False, risk="high")
    T.append(task("vis_a_large_solid", "Axial chest CT VIS-017: 69-year-old man with emphysema, 45 pack-years (image attached). Measure the nodule, check similar confirmed cases and give the Fleischner 2017 recommendation. What is it?",
                  s, root, res.category, "exact",
                  [act("analyze_medical_image", {"study_id": "VIS-017"}), act("search_similar_cases", {"study_id": "VIS-017"}, ["study_id"]),
                   act("fleischner_recommendation", {"study_id": "VIS-017"}, ["study_id"])],
                  ["The agent measures a solid nodule of about 12 mm in a high-risk patient.", "The agent recommends CT at 3 months, PET/CT or tissue sampling."],
                  "incidental nodule management", truth=tr))

    s, tr = cxr("VIS-018", "consolidation", _pt(37, "male", "no relevant history", 0, ["fever", "cough"]), "fever and cough", side="left", zone="upper")
    T.append(task("vis_a_luz_consolidation", "PA chest radiograph VIS-018: 37-year-old man with fever and cough (image attached). Describe the opacity, the sign inside it, and record it. Which lung and zone are involved?",
                  s, root, "left upper zone", "exact",
                  [act("analyze_medical_image", {"study_id": "VIS-018"}), act("lookup_imaging_sign", {"term": "air bronchogram"}),
                   act("record_finding", {"study_id": "VIS-018", "finding": "consolidation", "side": "left", "location": "left upper zone"}, ["study_id", "finding", "side"])],
                  ["The agent localises consolidation to the left upper zone.", "The agent identifies air bronchograms within it."],
                  "infection", aliases=["left upper lobe", "left upper"], truth=tr))

    s, tr, _ = ct("VIS-019", [("solid", 4.0)], _pt(33, "female", "trauma", 0), "trauma CT")
    res = CALCULATORS["fleischner_recommendation"](nodule_type="solid", size_mm=4.0, multiple=False, risk="low")
    T.append(task("vis_a_tiny_nodule", "Axial chest CT VIS-019: 33-year-old never-smoker scanned after trauma (image attached). A tiny nodule is seen. Measure it and give the Fleischner recommendation. What is it?",
                  s, root, res.category, "exact",
                  [act("analyze_medical_image", {"study_id": "VIS-019"}), act("get_clinical_history", {"study_id": "VIS-019"}),
                   act("fleischner_recommendation", {"study_id": "VIS-019"}, ["study_id"])],
                  ["The agent measures a solid nodule under 6 mm in a low-risk patient.", "The agent recommends no routine follow-up and avoids unnecessary imaging."],
                  "incidental nodule management", truth=tr))

    s, tr = cxr("VIS-020", "nodule", _pt(54, "female", "no relevant history", 0, ["none"]), "routine pre-operative film", side="right", zone="middle")
    T.append(task("vis_a_nodule_side", "PA chest radiograph VIS-020: 54-year-old never-smoker, pre-operative film (image attached). Find the lesion, state its side (the patient's) and zone, and record it. On which side is it?",
                  s, root, "right", "exact",
                  [act("get_study_metadata", {"study_id": "VIS-020"}), act("analyze_medical_image", {"study_id": "VIS-020"}),
                   act("record_finding", {"study_id": "VIS-020", "finding": "nodule", "side": "right", "location": "right mid zone"}, ["study_id", "finding", "side"])],
                  ["The agent reports the nodule on the patient's right (image left) using the radiological convention.", "The agent recommends CT for characterisation."],
                  "chest radiograph interpretation", aliases=["right side", "patient's right"], truth=tr))
    return S, T
