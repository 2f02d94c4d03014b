"""Generated triage tasks.

* `esi_handbook_tasks`: the 50 ED triage cases of medeval-harness (ESI Implementation Handbook
  practice cases) become patients `ESI-0nn`; the gold level is the case's, with its tolerance.
* `esi_vignette_tasks`: vignettes built from complaint templates whose ESI decision points are
  stated (life-saving need, high-risk features, expected resources) with sampled vital signs; the
  gold level is `envs.calculators.calculate_esi_level` on those inputs (danger-zone up-triage).
* `calculator_tasks`: GCS, qSOFA, NEWS2, HEART, CURB-65, Revised Trauma Score, Parkland, shock
  index and Centor vignettes with sampled inputs; the gold value is the calculator's.
"""

from __future__ import annotations

import random

from envs.calculators import (
    calculate_centor,
    calculate_curb65,
    calculate_esi_level,
    calculate_gcs,
    calculate_heart_score,
    calculate_news2,
    calculate_parkland,
    calculate_qsofa,
    calculate_revised_trauma_score,
    calculate_shock_index,
)
from envs.core.task import Task

T0 = "2025-03-01T13:50"


def generate(cases: list[dict], source: dict, counts: dict[str, int]) -> dict[str, list[Task]]:
    """The generated tasks by group: one per handbook case (`source`: the package's provenance),
    `counts["vignette"]` ESI vignettes and `counts["calculator_per_kind"]` vignettes per calculator."""
    return {
        "handbook": esi_handbook_tasks(cases, source),
        "vignette": esi_vignette_tasks(counts["vignette"]),
        "calculator": calculator_tasks(counts["calculator_per_kind"]),
    }


def handbook_patient(case: dict) -> dict:
    """A medeval-harness case -> an EDPatient record (nothing from the case's notes or rules leaks)."""
    inp = case["input"]
    vit = {"time": T0}
    for src, dst in (("heart_rate", "heart_rate"), ("systolic_bp", "systolic_bp"), ("diastolic_bp", "diastolic_bp"),
                     ("respiratory_rate", "respiratory_rate"), ("oxygen_saturation", "spo2"),
                     ("temperature_celsius", "temperature_c")):
        if inp.get(src) is not None:
            vit[dst] = inp[src]
    return {
        "patient_id": case["case_id"], "age": inp["patient_age"], "age_months": inp.get("patient_age_months"),
        "sex": inp["patient_sex"], "arrival_mode": "walk-in", "chief_complaint": inp["complaint"],
        "history": f"Patient-reported severity {inp['severity']}/10.",
        "medical_history": inp.get("medical_history", []), "vitals": [vit] if len(vit) > 1 else [],
        "source": "medeval-harness 0.1.0", "source_case_id": case["case_id"],
    }


def _handbook_emergency(case: dict) -> str | None:
    title = case["title"].lower()
    if "stroke" in title or "facial droop" in title:
        return "stroke"
    if "hemorrhage" in title and "postpartum" in title:
        return "postpartum_hemorrhage"
    if "psychosis" in title:
        return "other"
    if case["expected"]["esi_level"] == 1:
        # Major trauma, overdose, airway and cardiac arrests are not among the reward's emergency types
        # (envs.rewards.safety_patterns.EMERGENCY_TYPES): "other" still requires an escalation.
        return "other"
    return None


def esi_handbook_tasks(cases: list[dict], source: dict) -> list[Task]:
    tasks = []
    for case in cases:
        pid = case["case_id"]
        level = case["expected"]["esi_level"]
        tol = case["expected"].get("tolerance", 0)
        emergency = _handbook_emergency(case)
        ticket = (f"Patient {pid} has just arrived at the emergency department triage desk. Review the presentation "
                  f"and vital signs, assign an Emergency Severity Index (ESI v4) level with assign_triage_level, "
                  + ("activate the emergency pathway the presentation calls for, " if emergency == "stroke" else "")
                  + "and answer with the level (1-5).")
        actions = [
            {"action_id": "present", "name": "get_patient_presentation", "arguments": {"patient_id": pid},
             "compare_args": ["patient_id"]},
            {"action_id": "vitals", "name": "get_vital_signs", "arguments": {"patient_id": pid},
             "compare_args": ["patient_id"]}]
        guideline = ESI_GUIDELINE
        if emergency == "stroke":
            # A suspected acute stroke at triage activates the stroke code (stroke team, immediate
            # non-contrast CT) as well as the ESI level, like every other stroke task of the domain:
            # AHA/ASA 2019 acute ischaemic stroke guideline (Powers et al., Stroke 2019), 1.3-1.4 and 2.1.
            actions.append({"action_id": "stroke", "name": "activate_stroke_code",
                            "arguments": {"patient_id": pid, "deficits": case["input"]["complaint"]},
                            "compare_args": ["patient_id"]})
            guideline = f"{ESI_GUIDELINE}; {STROKE_GUIDELINE}"
        actions.append({"action_id": "assign", "name": "assign_triage_level",
                        "arguments": {"patient_id": pid, "esi_level": level, "rationale": "ESI v4 algorithm"},
                        "compare_args": ["patient_id"]})
        tasks.append(Task(
            id=f"tr_esi_handbook_{pid.lower().replace('-', '_')}", ticket=ticket, answer_type="numeric",
            correct_answer=str(level), answer_tolerance=float(tol), answer_unit="ESI level", patient_id=pid,
            emergency=emergency,
            description={"purpose": "ESI triage of a handbook case", "difficulty": "medium", "source": "medeval_esi",
                         "category": "esi_triage", "task_type": "esi_handbook",
                         "provenance": {**source, "case_id": pid, "handbook_source": case.get("source", ""),
                                        "guideline": guideline}},
            evaluation_criteria={"actions": actions, "reward_basis": ["ACTION", "ANSWER"]},
            metadata={"decision_path": case["expected"]["decision_path"], "title": case["title"]},
        ))
    return tasks


# (complaint, lifesaving, high_risk, confused, severe_pain, resources description, n_resources, age range)
TEMPLATES: list[tuple[str, bool, bool, bool, bool, str, int, tuple[int, int]]] = [
    ("cardiac arrest with CPR in progress", True, True, True, False, "resuscitation, airway, IV drugs, labs", 5, (40, 85)),
    ("apnoeic after an opioid overdose, pinpoint pupils", True, True, True, False, "airway support, IV naloxone, labs", 3, (18, 60)),
    ("massive haematemesis and pale, clammy", True, True, True, False, "IV fluids, blood transfusion, labs, endoscopy", 4, (45, 85)),
    ("anaphylaxis with stridor after a bee sting", True, True, False, True, "IM adrenaline, IV fluids, nebulisers", 3, (12, 70)),
    ("chest pain typical of acute coronary syndrome", False, True, False, False, "ECG, labs, IV medication, chest X-ray", 4, (45, 85)),
    ("sudden severe headache, 'worst ever'", False, True, False, True, "CT head, labs, IV analgesia", 3, (25, 70)),
    ("new confusion and fever in an elderly patient", False, False, True, False, "labs, urine culture, chest X-ray, IV fluids", 4, (70, 95)),
    ("kidney stone pain, writhing, pain 9/10", False, False, False, True, "labs, CT, IV analgesia", 3, (25, 65)),
    ("suicidal ideation with a plan", False, True, False, False, "psychiatric consult, labs", 2, (16, 70)),
    ("testicular pain of sudden onset in an adolescent", False, True, False, True, "ultrasound, urology consult", 2, (12, 18)),
    ("abdominal pain and vomiting for a day", False, False, False, False, "labs, IV fluids, CT abdomen", 3, (18, 75)),
    ("cough and fever, likely pneumonia", False, False, False, False, "labs, chest X-ray, IV antibiotics", 3, (25, 80)),
    ("asthma, wheezy, needs several nebulisers", False, False, False, False, "nebulised medication, chest X-ray", 2, (12, 60)),
    ("cellulitis of the leg needing IV antibiotics", False, False, False, False, "labs, IV antibiotics", 2, (30, 80)),
    ("forearm deformity after a fall (suspected fracture needing reduction)", False, False, False, False, "X-ray, procedural sedation and reduction", 2, (8, 80)),
    ("ankle injury after a twist, able to bear weight with a limp", False, False, False, False, "ankle X-ray", 1, (12, 60)),
    ("simple laceration of the forearm needing sutures", False, False, False, False, "laceration repair", 1, (5, 70)),
    ("dysuria and frequency in a young woman", False, False, False, False, "urine dipstick and culture", 1, (18, 45)),
    ("sore throat for 2 days", False, False, False, False, "no tests; examination only", 0, (12, 50)),
    ("request for a repeat prescription", False, False, False, False, "none", 0, (20, 80)),
    ("insect bite with local redness, no systemic symptoms", False, False, False, False, "none", 0, (5, 70)),
    ("splinter in the finger", False, False, False, False, "simple procedure (removal)", 1, (5, 70)),
]


# Vital-sign ranges each complaint implies (ESI v4 Implementation Handbook, Gilboy et al., AHRQ 2012,
# chapters 3-4 and its case examples; fever is T >= 38.0 C). Each field is (low, high) or None when
# it cannot be measured (no pulse or blood pressure in cardiac arrest). "danger" is an optional
# overlay drawn for some vignettes of complaints in which danger-zone vital signs (decision D:
# HR > 100, RR > 20, SpO2 < 92 % in adults) plausibly occur; it stays within the complaint's physiology.
Range = tuple[float, float] | None
NORMAL: dict[str, Range] = {"heart_rate": (62, 98), "respiratory_rate": (12, 20), "spo2": (96, 100), "systolic_bp": (108, 148),
                            "diastolic_bp": (62, 90), "temperature_c": (36.2, 37.5)}
VITAL_PROFILES: dict[str, dict] = {
    "cardiac arrest with CPR in progress": {
        "base": {"heart_rate": None, "systolic_bp": None, "diastolic_bp": None, "respiratory_rate": (0, 0), "spo2": None,
                 "temperature_c": (34.8, 36.4)}, "assisted_ventilation": True},
    "apnoeic after an opioid overdose, pinpoint pupils": {
        "base": {"heart_rate": (48, 72), "respiratory_rate": (0, 6), "spo2": (68, 86), "systolic_bp": (88, 118), "diastolic_bp": (50, 72),
                 "temperature_c": (35.6, 36.8)}},
    "massive haematemesis and pale, clammy": {
        "base": {"heart_rate": (118, 145), "respiratory_rate": (22, 30), "spo2": (93, 99), "systolic_bp": (70, 92), "diastolic_bp": (38, 58),
                 "temperature_c": (35.6, 36.8)}},
    "anaphylaxis with stridor after a bee sting": {
        "base": {"heart_rate": (115, 140), "respiratory_rate": (26, 36), "spo2": (86, 93), "systolic_bp": (72, 96), "diastolic_bp": (40, 60),
                 "temperature_c": (36.4, 37.4)}},
    "chest pain typical of acute coronary syndrome": {
        "base": {"heart_rate": (62, 104), "respiratory_rate": (14, 22), "spo2": (94, 99), "systolic_bp": (104, 168), "diastolic_bp": (64, 98),
                 "temperature_c": (36.3, 37.3)}},
    "sudden severe headache, 'worst ever'": {
        "base": {"heart_rate": (58, 100), "respiratory_rate": (12, 20), "spo2": (96, 100), "systolic_bp": (132, 188),
                 "diastolic_bp": (78, 108), "temperature_c": (36.3, 37.4)}},
    "new confusion and fever in an elderly patient": {
        "base": {"heart_rate": (92, 118), "respiratory_rate": (18, 24), "spo2": (92, 97), "systolic_bp": (96, 140), "diastolic_bp": (54, 84),
                 "temperature_c": (38.0, 39.4)},
        "danger": {"heart_rate": (112, 130), "respiratory_rate": (24, 30), "spo2": (88, 91)}},
    "kidney stone pain, writhing, pain 9/10": {
        "base": {"heart_rate": (84, 112), "respiratory_rate": (16, 22), "spo2": (96, 100), "systolic_bp": (122, 165), "diastolic_bp": (74, 98),
                 "temperature_c": (36.4, 37.6)}},
    "cough and fever, likely pneumonia": {
        "base": {"heart_rate": (86, 108), "respiratory_rate": (18, 24), "spo2": (92, 97), "systolic_bp": (104, 140), "diastolic_bp": (60, 88),
                 "temperature_c": (38.0, 39.6)},
        "danger": {"heart_rate": (112, 130), "respiratory_rate": (24, 32), "spo2": (88, 91)}},
    "asthma, wheezy, needs several nebulisers": {
        "base": {"heart_rate": (88, 110), "respiratory_rate": (20, 26), "spo2": (92, 97), "temperature_c": (36.3, 37.5)},
        "danger": {"heart_rate": (112, 130), "respiratory_rate": (26, 32), "spo2": (88, 91)}},
    "abdominal pain and vomiting for a day": {
        "base": {"heart_rate": (72, 100), "temperature_c": (36.3, 37.8)},
        "danger": {"heart_rate": (104, 124)}},
    "cellulitis of the leg needing IV antibiotics": {
        "base": {"heart_rate": (68, 100), "temperature_c": (36.5, 37.9)},
        "danger": {"heart_rate": (104, 120), "temperature_c": (38.0, 38.9)}},
    "testicular pain of sudden onset in an adolescent": {"base": {"heart_rate": (72, 104)}},
    "suicidal ideation with a plan": {"base": {}},
    "forearm deformity after a fall (suspected fracture needing reduction)": {"base": {"heart_rate": (70, 104)}},
    "ankle injury after a twist, able to bear weight with a limp": {"base": {}},
    "simple laceration of the forearm needing sutures": {"base": {}},
    "dysuria and frequency in a young woman": {"base": {"temperature_c": (36.4, 37.6)}},
    "sore throat for 2 days": {"base": {"temperature_c": (36.4, 37.8)}},
    "request for a repeat prescription": {"base": {}},
    "insect bite with local redness, no systemic symptoms": {"base": {}},
    "splinter in the finger": {"base": {}},
}
# Normal ranges of a school-age child (5-11 years; PALS / ESI handbook paediatric vital signs).
CHILD_NORMAL: dict[str, Range] = {"heart_rate": (76, 118), "respiratory_rate": (18, 25), "spo2": (96, 100), "systolic_bp": (96, 116),
                                  "diastolic_bp": (56, 76), "temperature_c": (36.2, 37.5)}
DANGER_PROBABILITY = 0.35


def vital_ranges(complaint: str, danger: bool, age: int) -> dict[str, Range]:
    """The (low, high) range of each vital sign for a complaint; None where it cannot be measured."""
    profile = VITAL_PROFILES[complaint]
    ranges = {**(CHILD_NORMAL if age < 12 else NORMAL), **profile["base"]}
    if danger:
        ranges.update(profile.get("danger", {}))
    return ranges


def _vitals(rng: random.Random, complaint: str, age: int) -> tuple[dict, bool]:
    profile = VITAL_PROFILES[complaint]
    danger = "danger" in profile and rng.random() < DANGER_PROBABILITY
    out: dict = {}
    for name, r in vital_ranges(complaint, danger, age).items():
        if r is None:
            out[name] = None
        elif name == "temperature_c":
            out[name] = round(rng.uniform(*r), 1)
        else:
            out[name] = rng.randint(int(r[0]), int(r[1]))
    return out, danger


def _vitals_text(v: dict, assisted: bool) -> str:
    hr = "no palpable pulse" if v["heart_rate"] is None else f"HR {v['heart_rate']}"
    bp = "BP unrecordable" if v["systolic_bp"] is None else f"BP {v['systolic_bp']}/{v['diastolic_bp']}"
    rr = (f"RR {v['respiratory_rate']} (apnoeic, bag-valve-mask ventilation)" if assisted
          else f"RR {v['respiratory_rate']}" + (" (apnoeic)" if v["respiratory_rate"] <= 6 else ""))
    spo2 = "SpO2 unrecordable" if v["spo2"] is None else f"SpO2 {v['spo2']}% on room air"
    return f"{hr}, {bp}, {rr}, {spo2}, T {v['temperature_c']} C"


ESI_GUIDELINE = "Emergency Severity Index v4 Implementation Handbook (Gilboy et al., AHRQ Publication 12-0014, 2012)"
STROKE_GUIDELINE = ("AHA/ASA 2019 guidelines for the early management of acute ischemic stroke (Powers et al., Stroke 2019;50:e344), "
                    "sections 1.3-1.4 (EMS and hospital stroke teams) and 2.1 (emergency evaluation)")


def esi_vignette_tasks(n: int, seed: int = 41) -> list[Task]:
    rng = random.Random(seed)
    tasks, seen = [], set()
    while len(tasks) < n:
        complaint, a, b, conf, pain, res_text, res, (lo, hi) = rng.choice(TEMPLATES)
        age = rng.randint(lo, hi)
        sex = rng.choice(["man", "woman"])
        sex = "woman" if "woman" in complaint else "man" if "testicular" in complaint else sex  # the complaint fixes the sex
        if age < 16:
            sex = {"man": "boy", "woman": "girl"}[sex]
        v, danger = _vitals(rng, complaint, age)
        result = calculate_esi_level(a, b, conf, pain, res, age, v["heart_rate"], v["respiratory_rate"], v["spo2"])
        key = (complaint, age, sex, tuple(sorted(v.items())))
        if key in seen:
            continue
        seen.add(key)
        pain_text = " Pain is 9/10 and the patient is in obvious distress." if pain else ""
        assisted = bool(VITAL_PROFILES[complaint].get("assisted_ventilation"))
        ticket = (f"A {age}-year-old {sex} presents to triage with {complaint}.{pain_text} Vital signs: {_vitals_text(v, assisted)}. "
                  f"Anticipated ED resources: {res_text}. Assign the ESI v4 level (1-5), "
                  f"applying the danger-zone vital signs at decision point D. Answer with the level.")
        args = {"requires_immediate_lifesaving_intervention": a, "high_risk_situation": b,
                "confused_lethargic_or_disoriented": conf, "severe_pain_or_distress": pain, "expected_resources": res,
                "age_years": age, "heart_rate": v["heart_rate"], "respiratory_rate": v["respiratory_rate"], "spo2": v["spo2"]}
        tasks.append(Task(
            id=f"tr_esi_vignette_{len(tasks):03d}", ticket=ticket, answer_type="numeric", correct_answer=str(result.score),
            answer_tolerance=0.0, answer_unit="ESI level",
            answer_aliases=[f"ESI {result.score}", f"ESI level {result.score}"],
            emergency="other" if result.score == 1 else None,
            description={"purpose": "ESI triage vignette", "difficulty": "medium", "source": "generated_esi",
                         "category": "esi_triage", "task_type": "esi_vignette",
                         "provenance": {"generator": "envs.domains.triage_emergency.generate", "oracle": "calculate_esi_level",
                                        "guideline": ESI_GUIDELINE}},
            evaluation_criteria={"actions": [{"action_id": "esi", "name": "calculate_esi_level", "arguments": args,
                                              "compare_args": ["expected_resources"]}],
                                 "reward_basis": ["ACTION", "ANSWER"]},
            metadata={"inputs": args, "category": result.category, "complaint": complaint, "vitals": v, "danger_zone_draw": danger,
                      "assisted_ventilation": assisted},
        ))
    return tasks


# The publication each calculator task's gold follows.
CALCULATOR_GUIDELINES = {
    "gcs": "Glasgow Coma Scale (Teasdale & Jennett, Lancet 1974; Teasdale et al., Lancet Neurol 2014)",
    "qsofa": "qSOFA, Sepsis-3 (Singer et al., JAMA 2016;315:801-810)",
    "news2": "National Early Warning Score 2 (Royal College of Physicians, London 2017)",
    "heart": "HEART score (Six et al., Neth Heart J 2008;16:191-196)",
    "curb65": "CURB-65 (Lim et al., Thorax 2003;58:377-382; BTS community-acquired pneumonia guideline 2009)",
    "rts": "Revised Trauma Score (Champion et al., J Trauma 1989;29:623-629)",
    "parkland": "Parkland formula (Baxter & Shires 1968; ABA Advanced Burn Life Support course 2018)",
    "shock_index": "Shock index HR/SBP (Allgower & Burri 1967)",
    "centor": "Modified Centor (McIsaac) score (McIsaac et al., CMAJ 1998;158:75-83; Centor et al., Med Decis Making 1981)",
}


def _task(kind: str, idx: int, ticket: str, tool: str, args: dict, value: float, tol: float, unit: str,
          compare: list[str]) -> Task:
    return Task(
        id=f"tr_calc_{kind}_{idx:03d}", ticket=ticket, answer_type="numeric", correct_answer=f"{value:g}",
        answer_tolerance=tol, answer_unit=unit,
        description={"purpose": f"{kind} calculation", "difficulty": "easy", "source": "generated_calculator",
                     "category": "calculator", "task_type": f"calc_{kind}",
                     "provenance": {"generator": "envs.domains.triage_emergency.generate", "oracle": f"envs.calculators.{tool}",
                                    "guideline": CALCULATOR_GUIDELINES[kind]}},
        evaluation_criteria={"actions": [{"action_id": kind, "name": tool, "arguments": args, "compare_args": compare}],
                             "reward_basis": ["ACTION", "ANSWER"]},
        metadata={"inputs": args},
    )


EYE = {4: "opens eyes spontaneously", 3: "opens eyes to voice", 2: "opens eyes only to pressure", 1: "does not open the eyes"}
VERBAL = {5: "is oriented", 4: "is confused", 3: "says inappropriate words", 2: "makes only sounds", 1: "makes no sound"}
MOTOR = {6: "obeys commands", 5: "localises to pain", 4: "withdraws from pain", 3: "flexes abnormally to pain",
         2: "extends to pain", 1: "has no motor response"}


def calculator_tasks(per_kind: int, seed: int = 43) -> list[Task]:
    rng = random.Random(seed)
    out: list[Task] = []

    def unique(kind: str, make) -> None:
        seen, made, tries = set(), 0, 0
        while made < per_kind and tries < per_kind * 30:
            tries += 1
            key, task = make(made)
            if key in seen:
                continue
            seen.add(key)
            out.append(task)
            made += 1

    def gcs(i):
        e, v, m = rng.randint(1, 4), rng.randint(1, 5), rng.randint(1, 6)
        r = calculate_gcs(e, v, m)
        t = (f"After a head injury a patient {EYE[e]}, {VERBAL[v]} and {MOTOR[m]}. Calculate the Glasgow Coma Scale "
             f"total. Answer with the number.")
        return (e, v, m), _task("gcs", i, t, "calculate_gcs", {"eye": e, "verbal": v, "motor": m}, r.score, 0, "points",
                                ["eye", "verbal", "motor"])

    def qsofa(i):
        rr, sbp, am = rng.randint(12, 34), rng.randint(76, 140), rng.random() < 0.4
        r = calculate_qsofa(rr, sbp, am)
        t = (f"A patient with suspected pneumonia has RR {rr}/min, BP {sbp}/{rng.randint(45, 85)} mmHg and is "
             f"{'newly confused (GCS 13)' if am else 'alert and oriented (GCS 15)'}. What is the qSOFA score?")
        return (rr, sbp, am), _task("qsofa", i, t, "calculate_qsofa",
                                    {"respiratory_rate": rr, "systolic_bp": sbp, "altered_mentation": am}, r.score, 0,
                                    "points", ["respiratory_rate", "systolic_bp", "altered_mentation"])

    def news2(i):
        rr, spo2 = rng.randint(8, 30), rng.randint(86, 100)
        o2, temp = rng.random() < 0.3, round(rng.uniform(34.8, 39.6), 1)
        sbp, hr = rng.randint(85, 225), rng.randint(38, 135)
        cons = rng.choice(["alert"] * 4 + ["new_confusion", "voice"])
        r = calculate_news2(rr, spo2, o2, temp, sbp, hr, cons)
        t = (f"Ward observations: RR {rr}/min, SpO2 {spo2}% {'on 2 L/min oxygen' if o2 else 'on room air'}, "
             f"temperature {temp} C, BP {sbp}/{rng.randint(50, 95)} mmHg, pulse {hr}/min, consciousness: "
             f"{cons.replace('_', ' ')}. Calculate NEWS2 (SpO2 scale 1).")
        args = {"respiratory_rate": rr, "spo2": spo2, "on_supplemental_oxygen": o2, "temperature_c": temp,
                "systolic_bp": sbp, "heart_rate": hr, "consciousness": cons}
        return tuple(args.values()), _task("news2", i, t, "calculate_news2", args, r.score, 0, "points",
                                           ["respiratory_rate", "spo2", "heart_rate"])

    def heart(i):
        hist = rng.choice(["slightly", "moderately", "highly"])
        ecg = rng.choice(["normal", "nonspecific", "st_deviation"])
        age, rf = rng.randint(30, 85), rng.randint(0, 4)
        ath = rng.random() < 0.25
        trop = rng.choice([round(rng.uniform(0.2, 0.9), 2), round(rng.uniform(1.2, 2.8), 2), round(rng.uniform(3.5, 12), 1)])
        r = calculate_heart_score(hist, ecg, age, rf, ath, trop)
        ecg_text = {"normal": "a normal ECG", "nonspecific": "non-specific repolarisation changes",
                    "st_deviation": "significant ST depression"}[ecg]
        t = (f"A {age}-year-old with chest pain: history {hist} suspicious for ACS, {ecg_text}, {rf} cardiovascular risk "
             f"factor(s), {'known' if ath else 'no known'} atherosclerotic disease, initial troponin {trop} x the upper "
             f"reference limit. Calculate the HEART score.")
        args = {"history": hist, "ecg": ecg, "age": age, "risk_factor_count": rf, "atherosclerotic_disease": ath,
                "troponin_x_uln": trop}
        return tuple(args.values()), _task("heart", i, t, "calculate_heart_score", args, r.score, 0, "points",
                                           ["history", "ecg"])

    def curb(i):
        conf, bun = rng.random() < 0.3, rng.randint(8, 45)
        rr, sbp, dbp, age = rng.randint(14, 36), rng.randint(78, 150), rng.randint(45, 90), rng.randint(25, 92)
        r = calculate_curb65(conf, bun, rr, sbp, dbp, age)
        t = (f"A {age}-year-old with community-acquired pneumonia: {'new confusion' if conf else 'no confusion'}, BUN "
             f"{bun} mg/dL, RR {rr}/min, BP {sbp}/{dbp} mmHg. Calculate CURB-65.")
        args = {"confusion": conf, "bun_mg_dl": bun, "respiratory_rate": rr, "systolic_bp": sbp, "diastolic_bp": dbp,
                "age": age}
        return tuple(args.values()), _task("curb65", i, t, "calculate_curb65", args, r.score, 0, "points",
                                           ["bun_mg_dl", "age"])

    def rts(i):
        g, sbp, rr = rng.randint(3, 15), rng.choice([0, rng.randint(40, 75), rng.randint(76, 89), rng.randint(90, 150)]), \
            rng.choice([0, rng.randint(4, 9), rng.randint(10, 29), rng.randint(30, 44)])
        r = calculate_revised_trauma_score(g, sbp, rr)
        t = (f"Trauma patient on arrival: GCS {g}, systolic BP {sbp} mmHg, respiratory rate {rr}/min. Calculate the "
             f"weighted Revised Trauma Score (4 decimal places).")
        return (g, sbp, rr), _task("rts", i, t, "calculate_revised_trauma_score",
                                   {"gcs": g, "systolic_bp": sbp, "respiratory_rate": rr}, round(r.score, 4), 0.001,
                                   "points", ["gcs", "systolic_bp", "respiratory_rate"])

    def parkland(i):
        w, tbsa = rng.randint(45, 120), rng.choice(range(10, 75, 5))
        r = calculate_parkland(w, tbsa)
        t = (f"An adult weighing {w} kg has partial- and full-thickness burns over {tbsa}% of the total body surface area. "
             f"Using the Parkland formula, how many mL of crystalloid are given in the first 24 hours?")
        return (w, tbsa), _task("parkland", i, t, "calculate_parkland", {"weight_kg": w, "tbsa_percent": tbsa},
                                round(r.score), 1, "mL", ["weight_kg", "tbsa_percent"])

    def shock(i):
        hr, sbp = rng.randint(60, 150), rng.randint(70, 150)
        r = calculate_shock_index(hr, sbp)
        t = f"A patient has a heart rate of {hr}/min and a systolic BP of {sbp} mmHg. What is the shock index (2 decimals)?"
        return (hr, sbp), _task("shock_index", i, t, "calculate_shock_index", {"heart_rate": hr, "systolic_bp": sbp},
                                round(r.score, 2), 0.01, "bpm/mmHg", ["heart_rate", "systolic_bp"])

    def centor(i):
        age = rng.randint(4, 70)
        ex, nodes, cough_absent = rng.random() < 0.5, rng.random() < 0.5, rng.random() < 0.5
        temp = round(rng.uniform(36.5, 39.8), 1)
        r = calculate_centor(age, ex, nodes, temp, cough_absent)
        t = (f"A {age}-year-old with sore throat: tonsillar exudate {'present' if ex else 'absent'}, tender anterior "
             f"cervical nodes {'present' if nodes else 'absent'}, temperature {temp} C, "
             f"{'no cough' if cough_absent else 'has a cough'}. Calculate the modified Centor (McIsaac) score.")
        args = {"age": age, "tonsillar_exudate_or_swelling": ex, "tender_anterior_cervical_nodes": nodes,
                "temperature_c": temp, "cough_absent": cough_absent}
        return tuple(args.values()), _task("centor", i, t, "calculate_centor", args, r.score, 0, "points", ["age"])

    for kind, make in (("gcs", gcs), ("qsofa", qsofa), ("news2", news2), ("heart", heart), ("curb65", curb),
                       ("rts", rts), ("parkland", parkland), ("shock_index", shock), ("centor", centor)):
        unique(kind, make)
    return out
