"""Synthetic obstetric patients (our code, seeded) and their generated tasks.

CTG tracings are synthesised from a specification (`ctg.synthesise`); the gold NICHD category is
the specification's designed category (`ctg.classify_spec`), and the build keeps a tracing only
when `ctg.interpret`, reading the series alone, recovers that category, baseline and variability.
Bishop, Apgar and biophysical-profile answers come from `envs.calculators`; dating and
hypertensive-disorder answers from `rules.py` on the same inputs.
"""

from __future__ import annotations

import random
from datetime import date, timedelta
from typing import Any

from envs.calculators import CALCULATORS
from envs.coherence import SYMPTOM_WORDS
from envs.domains.obstetrics import ctg as CTG
from envs.domains.obstetrics import rules
from envs.domains.obstetrics.data_model import (
    BloodPressure, CervicalExam, CTGTracing, LabResult, NewbornObservation, Patient, Symptoms, Ultrasound, Vitals,
)

TODAY = date(2026, 3, 2)
FIRST = ["Amelia", "Nora", "Leila", "Camila", "Hana", "Freya", "Adaeze", "Ruth", "Imani", "Sofia", "Keira", "Mira",
         "Yasmin", "Eva", "Thandi", "Lucia", "Anya", "Beatriz", "Naomi", "Ayesha", "Clara", "Ines"]
LAST = ["Whitfield", "Okonkwo", "Sato", "Herrera", "Lindgren", "Bakr", "Novak", "Mbeki", "Dubois", "Kaur", "Moreno",
        "Fischer", "Adeyemi", "Larsen", "Costa", "Petrov", "Nakamura", "Walsh", "Diaz", "Osei"]
PROVENANCE = {"source": "authored", "generator": "envs.domains.obstetrics.generate", "license": "project (ours)"}
# The guideline each generated task type's gold follows (recorded in the task's provenance so a
# reviewer can check the answer against it).
GUIDELINES = {
    "ctg_category": "NICHD three-tier FHR classification (Macones et al., Obstet Gynecol 2008); ACOG Practice Bulletin 106 (2009)",
    "bishop_score": "Bishop pelvic score (Bishop, Obstet Gynecol 1964); ACOG Practice Bulletin 107 (2009), Induction of Labor",
    "apgar_score": "Apgar score (Apgar 1953); ACOG/AAP Committee Opinion 644 (2015), The Apgar Score",
    "biophysical_profile": "Biophysical profile (Manning et al. 1980); ACOG Practice Bulletin 229 (2021), Antepartum Fetal Surveillance",
    "gestational_age": "ACOG Committee Opinion 700 (2017), Methods for Estimating the Due Date",
    "due_date": "ACOG Committee Opinion 700 (2017), Methods for Estimating the Due Date",
    "hypertensive_disorder": "ACOG Practice Bulletin 222 (2020), Gestational Hypertension and Preeclampsia",
    "cord_prolapse": "RCOG Green-top Guideline 50 (2014), Umbilical Cord Prolapse",
}
# Accepted equivalent phrasings of the hypertensive-disorder categories (ACOG PB 222 wording and
# the common clinical synonyms), so grading by meaning accepts them.
HTN_ALIASES = {
    "preeclampsia with severe features": ["severe preeclampsia", "pre-eclampsia with severe features", "severe pre-eclampsia"],
    "preeclampsia without severe features": ["pre-eclampsia without severe features", "non-severe preeclampsia"],
    "chronic hypertension with superimposed preeclampsia with severe features": [
        "superimposed preeclampsia with severe features", "chronic hypertension with superimposed pre-eclampsia with severe features"],
    "chronic hypertension with superimposed preeclampsia": ["superimposed preeclampsia", "chronic hypertension with superimposed pre-eclampsia"],
    "HELLP syndrome": ["HELLP", "hemolysis, elevated liver enzymes and low platelets syndrome"],
    "severe gestational hypertension": ["gestational hypertension with severe-range blood pressure"],
    "no hypertensive disorder": ["normotensive", "no hypertensive disorder of pregnancy"],
}


def _patient(pid: str, rng: random.Random, ga_days: int, setting: str, complaint: str, history: str) -> Patient:
    lmp = TODAY - timedelta(days=ga_days)
    gravida = rng.randint(1, 4)
    return Patient(patient_id=pid, name=f"{rng.choice(FIRST)} {rng.choice(LAST)}", age=rng.randint(19, 42), gravida=gravida,
                   para=rng.randint(0, gravida - 1), setting=setting, presenting_complaint=complaint, history=history,
                   lmp_date=lmp.isoformat(),
                   vitals=Vitals(blood_pressures=[BloodPressure(hours_ago=0, systolic=rng.randint(104, 128), diastolic=rng.randint(62, 82))],
                                 heart_rate=rng.randint(72, 98), respiratory_rate=rng.randint(14, 18),
                                 temperature_c=round(rng.uniform(36.5, 37.3), 1), spo2=rng.randint(97, 100)),
                   allergies=rng.choice([[], [], [], ["penicillin"], ["latex"]]), provenance=PROVENANCE,
                   # the structured symptoms say what the complaint and history say (envs.coherence)
                   symptoms=Symptoms(**{flag: True for flag, words in SYMPTOM_WORDS.items()
                                        if words.search(f"{complaint} {history}")}))


def _intro(p: Patient) -> str:
    ga = rules.weeks_days((TODAY - date.fromisoformat(p.lmp_date)).days) if p.lmp_date else "unknown gestation"
    return f"{p.name} ({p.patient_id}), {p.age}, G{p.gravida}P{p.para} at {ga} by LMP, is in the {p.setting}: {p.presenting_complaint}."


def act(name: str, arguments: dict, compare: list[str] | None = None) -> dict:
    return {"name": name, "arguments": arguments, "compare_args": list(arguments) if compare is None else compare}


def task_dict(task_id: str, ticket: str, *, answer: str, answer_type: str, task_type: str, patient_id: str, actions: list[dict],
              category: str, unit: str | None = None, tolerance: float | None = None, aliases: list[str] | None = None,
              emergency: str | None = None, assertions: list[str] | None = None, metadata: dict | None = None,
              difficulty: str = "medium") -> dict:
    t: dict[str, Any] = {
        "id": task_id, "ticket": ticket, "correct_answer": answer, "answer_type": answer_type, "patient_id": patient_id,
        "description": {"purpose": f"Obstetric assessment: {category}.", "difficulty": difficulty, "source": "generated",
                        "category": category, "task_type": task_type, "provenance": {**PROVENANCE, "guideline": GUIDELINES[task_type]}},
        "evaluation_criteria": {"actions": actions, "nl_assertions": assertions or [],
                                "reward_basis": ["ACTION", "ANSWER"] + (["NL_ASSERTION"] if assertions else [])},
        "metadata": metadata or {},
    }
    for key, value in (("answer_unit", unit), ("answer_tolerance", tolerance), ("emergency", emergency)):
        if value is not None:
            t[key] = value
    if aliases:
        t["answer_aliases"] = aliases
    return t


# -- CTG ---------------------------------------------------------------------------------------
CTG_KINDS = ["cat1", "cat1_early", "minimal", "tachy", "marked", "absent", "brady_mod", "late", "variable", "prolonged",
             "cat3_late", "cat3_var", "cat3_brady"]
CTG_CONTEXT = {
    "cat1": "in spontaneous labour, progressing normally", "cat1_early": "in active labour at 6 cm",
    "minimal": "received IV opioid analgesia an hour ago", "tachy": "has a maternal temperature of 38.4 C in labour",
    "marked": "in the second stage, pushing", "absent": "reduced fetal movements for a day",
    "brady_mod": "in labour after an epidural top-up", "late": "on oxytocin augmentation",
    "variable": "had spontaneous rupture of membranes with scant fluid", "prolonged": "had a sudden drop in the FHR after an epidural",
    "cat3_late": "on oxytocin with a tracing the midwife is worried about", "cat3_var": "with thick meconium-stained liquor",
    "cat3_brady": "with a persistently low FHR on the monitor",
}


def ctg_spec(kind: str, rng: random.Random) -> dict:
    spec = {"minutes": 20, "baseline": rng.choice([120, 125, 130, 135, 140, 145, 150]), "variability_amplitude": rng.uniform(9, 18),
            "contraction_interval_s": rng.randint(160, 210), "accelerations": 0, "decelerations": []}
    if kind == "cat1":
        spec["accelerations"] = rng.randint(2, 3)
    elif kind == "cat1_early":
        spec["accelerations"] = rng.randint(0, 2)
    elif kind == "minimal":
        spec["variability_amplitude"] = rng.uniform(3.5, 4.5)
    elif kind == "tachy":
        spec["baseline"] = rng.choice([165, 170, 175])
    elif kind == "marked":
        spec["variability_amplitude"] = rng.uniform(28, 34)
    elif kind in ("absent", "cat3_late", "cat3_var", "cat3_brady"):
        spec["variability_amplitude"] = rng.uniform(0.6, 1.4)
    if kind == "brady_mod":
        spec["baseline"] = rng.choice([95, 100, 105])
    if kind == "cat3_brady":
        spec["baseline"] = rng.choice([90, 95, 100])
    if kind == "prolonged":
        spec["decelerations"] = [{"type": "prolonged", "depth": rng.randint(30, 40), "duration_s": rng.randint(170, 300),
                                  "onset_s": rng.randint(300, 700)}]
    return spec


def place_decels(spec: dict, kind: str, rng: random.Random, n_contr: int) -> None:
    spec["n_contractions"] = n_contr
    if kind in ("late", "cat3_late"):
        ks = range(n_contr) if kind == "cat3_late" else sorted(rng.sample(range(n_contr), max(1, (n_contr + 1) // 2)))
        spec["decelerations"] = [{"type": "late", "contraction": k, "depth": rng.randint(22, 30)} for k in ks]
    elif kind in ("variable", "cat3_var"):
        ks = range(n_contr) if kind == "cat3_var" else sorted(rng.sample(range(n_contr), rng.randint(1, max(1, n_contr // 2))))
        spec["decelerations"] = [{"type": "variable", "contraction": k, "depth": rng.randint(30, 50)} for k in ks]
    elif kind == "cat1_early":
        ks = sorted(rng.sample(range(n_contr), rng.randint(1, max(1, n_contr // 2))))
        spec["decelerations"] = [{"type": "early", "contraction": k, "depth": rng.randint(22, 28)} for k in ks]


def make_tracing(kind: str, rng: random.Random, tracing_id: str) -> tuple[CTGTracing, dict, str]:
    """A tracing whose interpretation recovers its designed category, baseline and variability."""
    for _ in range(20):
        spec = ctg_spec(kind, rng)
        seed = rng.randint(0, 10 ** 9)
        probe = CTG.synthesise({**spec, "decelerations": [d for d in spec["decelerations"] if d["type"] == "prolonged"]}, seed)
        place_decels(spec, kind, rng, len(probe["contractions"]))
        data = CTG.synthesise(spec, seed)
        gold = CTG.classify_spec(spec)
        out = CTG.interpret(data)
        amp = spec["variability_amplitude"]
        vclass = "absent" if amp <= 2 else "minimal" if amp <= 5 else "moderate" if amp <= 25 else "marked"
        if out["category"] == gold and out["baseline_bpm"] == spec["baseline"] and out["variability"] == vclass:
            tracing = CTGTracing(tracing_id=tracing_id, minutes=data["minutes"], sample_interval_s=data["sample_interval_s"],
                                 fhr=data["fhr"], contractions=data["contractions"], recorded="last 20 minutes")
            return tracing, spec, gold
    raise RuntimeError(f"could not synthesise a {kind} tracing that interprets as designed")


ALIASES = {"Category I": ["NICHD Category I", "Category 1"], "Category II": ["NICHD Category II", "Category 2"],
           "Category III": ["NICHD Category III", "Category 3"]}


def ctg_task(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    kind = CTG_KINDS[i % len(CTG_KINDS)]
    p = _patient(pid, rng, rng.randint(37 * 7, 41 * 7 + 2), "labour and delivery unit", CTG_CONTEXT[kind],
                 "Uncomplicated pregnancy; continuous CTG in progress.")
    tracing, spec, gold = make_tracing(kind, rng, f"{pid}-CTG1")
    p.ctg = [tracing]
    actions = [act("interpret_ctg", {"patient_id": pid}, ["patient_id"])]
    emergency, assertions = None, []
    if gold == "Category III":
        actions.append(act("escalate_care", {"patient_id": pid, "level": "obstetric emergency team",
                                             "reason": "Category III tracing: expedite delivery"}, ["patient_id"]))
        # ACOG Practice Bulletin 116 (2010): a Category III tracing needs intrauterine resuscitation
        # while expedited delivery is arranged; the note records both, as the assertion asks.
        actions.append(act("write_obstetric_note", {
            "patient_id": pid, "assessment": "Category III tracing (NICHD): abnormal, predictive of fetal acidaemia.",
            "plan": "Intrauterine resuscitation started: oxytocin switched off, left lateral position, IV fluid bolus, correct "
                    "hypotension, oxygen if hypoxic. Expedited delivery arranged with the obstetric emergency team."},
            ["patient_id"]))
        emergency = "fetal_compromise"
        assertions = ["The agent starts intrauterine resuscitation and arranges expedited delivery for the Category III tracing."]
    ticket = _intro(p) + " " + rng.choice([
        "Interpret the current CTG (baseline, variability, accelerations, decelerations) and give its NICHD category. Act on it if needed.",
        "What NICHD category is the tracing on the monitor? Review it systematically and take any action the category requires.",
        "Classify the last 20 minutes of CTG with the three-tier NICHD system and respond appropriately."])
    return p, [task_dict(f"ob_ctg_{pid}", ticket, answer=gold, answer_type="category", task_type="ctg_category", patient_id=pid,
                         actions=actions, category="intrapartum fetal monitoring", aliases=ALIASES[gold], emergency=emergency,
                         assertions=assertions, difficulty="hard", metadata={"kind": kind, "spec": {k: v for k, v in spec.items() if k != "decelerations"},
                                                                              "decelerations": [d["type"] for d in spec["decelerations"]]})]


# -- Bishop, Apgar, BPP ------------------------------------------------------------------------
LATE_TERM_INDUCTION = "Late-term pregnancy (41 weeks): induction of labour."
LATE_TERM_SURVEILLANCE = "Late-term pregnancy (41 weeks): antenatal fetal surveillance."


def bishop_task(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    # The indication and the gestation are drawn together: induction for a late-term pregnancy from 41 0/7 weeks
    # (ACOG Practice Bulletin 146, 2014), the other indications before 41 weeks.
    history = rng.choice([LATE_TERM_INDUCTION, "Induction for gestational diabetes.", "Induction for reduced fetal movements with normal CTG."])
    ga = rng.randint(41 * 7, 41 * 7 + 4) if history == LATE_TERM_INDUCTION else rng.randint(39 * 7, 40 * 7 + 6)
    p = _patient(pid, rng, ga, "antenatal day unit", "booked for induction of labour", history)
    exam = CervicalExam(dilation_cm=rng.choice([0, 1, 1.5, 2, 3, 3.5, 4, 5]), effacement_percent=rng.choice([20, 30, 40, 50, 60, 70, 80]),
                        station=rng.choice([-3, -2, -1, 0, 1]), consistency=rng.choice(["firm", "medium", "soft"]),
                        position=rng.choice(["posterior", "mid", "anterior"]))
    p.cervical_exam = exam
    res = CALCULATORS["calculate_bishop_score"](**exam.model_dump(exclude={"membranes", "findings"}))
    actions = [act("get_cervical_exam", {"patient_id": pid}), act("calculate_bishop_score", {"patient_id": pid}, ["patient_id"])]
    ticket = _intro(p) + " " + rng.choice(["Calculate the Bishop score from today's vaginal examination.",
                                           "What is her Bishop score (0-13) on the current cervical findings?",
                                           "Score the cervix for induction: give the Bishop score."])
    return p, [task_dict(f"ob_bishop_{pid}", ticket, answer=str(res.score), answer_type="numeric", unit="points", tolerance=0,
                         task_type="bishop_score", patient_id=pid, actions=actions, category="induction of labour",
                         metadata={"exam": exam.model_dump(), "category": res.category})]


def apgar_task(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    p = _patient(pid, rng, rng.randint(37 * 7, 41 * 7), "delivery room", "delivered a baby a few minutes ago",
                 rng.choice(["Spontaneous vaginal delivery.", "Emergency cesarean for fetal distress.", "Vacuum-assisted delivery."]))
    def obs(minute: int, good: bool) -> NewbornObservation:
        return NewbornObservation(
            minute=minute, heart_rate=rng.choice([0, 70, 90, 110, 130, 150]) if not good else rng.choice([110, 130, 150]),
            respiratory_effort=rng.choice(["absent", "weak", "strong"]) if not good else rng.choice(["weak", "strong"]),
            muscle_tone=rng.choice(["limp", "some_flexion", "active"]), reflex_irritability=rng.choice(["none", "grimace", "cry"]),
            color=rng.choice(["blue_pale", "acrocyanosis", "pink"]) if not good else rng.choice(["acrocyanosis", "pink"]))
    p.newborn = [obs(1, False), obs(5, rng.random() < 0.6)]
    five = p.newborn[1]
    res = CALCULATORS["calculate_apgar"](**five.model_dump(exclude={"minute"}))
    actions = [act("calculate_apgar", {"patient_id": pid, "minute": 5}, ["patient_id", "minute"])]
    ticket = _intro(p) + " " + rng.choice(["What is the baby's 5-minute Apgar score?", "Score the newborn at 5 minutes (Apgar 0-10).",
                                           "Give the Apgar score from the 5-minute observation."])
    return p, [task_dict(f"ob_apgar_{pid}", ticket, answer=str(res.score), answer_type="numeric", unit="points", tolerance=0,
                         task_type="apgar_score", patient_id=pid, actions=actions, category="newborn assessment")]


def bpp_task(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    # Surveillance of a late-term pregnancy starts at 41 0/7 weeks (ACOG Practice Bulletin 146, 2014): that history
    # comes with a late-term gestation, the others with 32-40 weeks.
    history = rng.choice(["Pregnancy complicated by gestational hypertension.", LATE_TERM_SURVEILLANCE, "Type 1 diabetes in pregnancy."])
    ga = rng.randint(41 * 7, 41 * 7 + 6) if history == LATE_TERM_SURVEILLANCE else rng.randint(32 * 7, 40 * 7 + 6)
    p = _patient(pid, rng, ga, "antenatal day unit", "reduced fetal movements", history)
    scan = Ultrasound(scan="biophysical profile", fetal_breathing=rng.random() < 0.7, body_movements_count=rng.choice([0, 1, 2, 3, 4, 6]),
                      fetal_tone=rng.random() < 0.75, deepest_vertical_pocket_cm=rng.choice([1.5, 1.9, 2.5, 3.4, 4.8, 6.0]),
                      nst_reactive=rng.choice([True, True, False]), notes="30-minute observation")
    p.ultrasounds = [scan]
    res = CALCULATORS["calculate_biophysical_profile"](fetal_breathing=scan.fetal_breathing, body_movements_count=scan.body_movements_count,
                                                       fetal_tone=scan.fetal_tone, deepest_vertical_pocket_cm=scan.deepest_vertical_pocket_cm,
                                                       nst_reactive=scan.nst_reactive)
    actions = [act("get_ultrasound_report", {"patient_id": pid}), act("calculate_biophysical_profile", {"patient_id": pid}, ["patient_id"])]
    ticket = _intro(p) + " " + rng.choice(["A biophysical profile with NST was done today. What is the BPP score out of 10?",
                                           "Score today's biophysical profile (including the NST).",
                                           "What does the biophysical profile score (0-10) come to?"])
    return p, [task_dict(f"ob_bpp_{pid}", ticket, answer=str(res.score), answer_type="numeric", unit="points", tolerance=0,
                         task_type="biophysical_profile", patient_id=pid, actions=actions, category="antenatal fetal surveillance",
                         metadata={"category": res.category})]


# -- dating ------------------------------------------------------------------------------------
def dating_task(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    ga_lmp = rng.randint(14 * 7, 38 * 7)
    p = _patient(pid, rng, ga_lmp, "antenatal clinic", "routine antenatal visit", "Dating scan in the first trimester.")
    scan_ga = rng.randint(7 * 7, 13 * 7 + 5)
    weeks_ago = (ga_lmp - scan_ga) / 7
    shift = rng.choice([0, 2, -3, 9, -10, 12, -8, 4]) if i % 2 == 0 else rng.choice([0, 3, -2, 11, -9])
    # CRL consistent with scan_ga + shift days (inverse Robinson formula).
    target = scan_ga + shift
    crl = round(((target - 23.73) / 8.052) ** 2, 1)
    if not 3 <= crl <= 84:
        crl = round(((scan_ga - 23.73) / 8.052) ** 2, 1)
    p.ultrasounds = [Ultrasound(scan="dating", weeks_ago=round(weeks_ago, 3), crown_rump_length_mm=crl, notes="single live intrauterine pregnancy")]
    scan_date = TODAY - timedelta(days=int(round(weeks_ago * 7)))
    out = rules.gestational_age(TODAY, date.fromisoformat(p.lmp_date), crl, scan_date)
    best = out["best_estimate"]
    actions = [act("calculate_gestational_age", {"patient_id": pid}, ["patient_id"])]
    if i % 2 == 0:
        ticket = _intro(p) + " " + rng.choice([
            "Using the LMP and the dating scan (apply the ACOG redating rule), how many completed weeks pregnant is she today?",
            "What is today's gestational age in completed weeks by the best obstetric estimate (LMP vs first-trimester CRL)?"])
        return p, [task_dict(f"ob_ga_{pid}", ticket, answer=str(best["completed_weeks"]), answer_type="numeric", unit="weeks", tolerance=0,
                             task_type="gestational_age", patient_id=pid, actions=actions, category="pregnancy dating",
                             metadata={"basis": best["basis"], "discrepancy": out.get("discrepancy_days")})]
    ticket = _intro(p) + " " + rng.choice([
        "Confirm her estimated date of delivery from the LMP and the dating scan (ACOG redating rule). Give the EDD as YYYY-MM-DD.",
        "What is the EDD by the best obstetric estimate? Answer in YYYY-MM-DD format."])
    return p, [task_dict(f"ob_edd_{pid}", ticket, answer=best["edd"], answer_type="exact", task_type="due_date", patient_id=pid,
                         actions=actions, category="pregnancy dating", metadata={"basis": best["basis"], "discrepancy": out.get("discrepancy_days")})]


# -- hypertensive disorders ----------------------------------------------------------------------
PE_SCENARIOS = ["none_single", "none", "gestational", "gestational", "pe_no_severe", "pe_no_severe", "pe_severe_bp", "pe_severe_plt",
                "pe_severe_symptoms", "hellp", "chronic", "superimposed", "pe_severe_cr"]


def _lab(name: str, value: float, unit: str, lo: float | None, hi: float | None, hours_ago: float = 1) -> LabResult:
    return LabResult(name=name, value=value, unit=unit, ref_low=lo, ref_high=hi, hours_ago=hours_ago)


def preeclampsia_task(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    kind = PE_SCENARIOS[i % len(PE_SCENARIOS)]
    p = _patient(pid, rng, rng.randint(28 * 7, 39 * 7), "obstetric triage unit", "raised blood pressure at an antenatal visit",
                 "Referred from the antenatal clinic.")
    normal = lambda: (rng.randint(112, 132), rng.randint(68, 84))  # noqa: E731
    elevated = lambda: (rng.randint(142, 154), rng.randint(88, 102))  # noqa: E731
    severe = lambda: (rng.randint(162, 176), rng.randint(104, 116))  # noqa: E731
    bp_plan = {"none_single": [normal(), elevated(), normal()], "none": [normal(), normal()],
               "gestational": [elevated(), elevated(), elevated()], "pe_no_severe": [elevated(), elevated()],
               "pe_severe_bp": [severe(), elevated(), severe()], "pe_severe_plt": [elevated(), elevated()],
               "pe_severe_symptoms": [elevated(), elevated()], "hellp": [elevated(), elevated()],
               "chronic": [elevated(), elevated()], "superimposed": [elevated(), elevated()], "pe_severe_cr": [elevated(), elevated()]}[kind]
    hours = [6.0, 3.0, 0.0] if len(bp_plan) == 3 else [5.0, 0.0]
    if kind == "none_single":
        hours = [8.0, 4.0, 0.0]
    bps = []
    for (s, d), h in zip(bp_plan, hours):
        if kind in ("gestational", "pe_no_severe", "chronic", "superimposed") and s >= 160:
            s = 155
        bps.append(BloodPressure(hours_ago=h, systolic=s, diastolic=min(d, 108) if s < 160 else d))
    p.vitals = p.vitals.model_copy(update={"blood_pressures": bps})
    upcr = {"pe_no_severe": 0.42, "pe_severe_bp": 0.55, "pe_severe_plt": 0.38, "pe_severe_symptoms": 0.6, "hellp": 0.8,
            "superimposed": 0.5, "pe_severe_cr": 0.7}.get(kind, round(rng.uniform(0.05, 0.2), 2))
    plt = {"pe_severe_plt": 86, "hellp": 72}.get(kind, rng.randint(160, 310))
    cr = {"pe_severe_cr": 1.3}.get(kind, round(rng.uniform(0.5, 0.8), 2))
    ast = 160 if kind == "hellp" else rng.randint(14, 32)
    alt = 140 if kind == "hellp" else rng.randint(12, 30)
    ldh = 740 if kind == "hellp" else rng.randint(150, 220)
    p.labs = [_lab("platelets", plt, "x10^9/L", 150, 400), _lab("creatinine", cr, "mg/dL", 0.4, 0.9), _lab("AST", ast, "U/L", 0, 40),
              _lab("ALT", alt, "U/L", 0, 40), _lab("LDH", ldh, "U/L", 100, 250)]
    p.orderable_results = {"urine protein/creatinine ratio": _lab("urine protein/creatinine ratio", upcr, "mg/mg", None, 0.3, 0)}
    if kind == "pe_severe_symptoms":
        p.symptoms = Symptoms(headache=True, visual_disturbance=True)
    if kind in ("chronic", "superimposed"):
        p.chronic_hypertension = True
        p.history = "Chronic hypertension diagnosed two years before pregnancy, on no medication since conception."
    days = (TODAY - date.fromisoformat(p.lmp_date)).days
    out = rules.hypertensive_disorder(days / 7, [b.model_dump() for b in bps],
                                      {**{l.name: l.value for l in p.labs}, "urine protein/creatinine ratio": upcr},
                                      p.symptoms.model_dump(), p.chronic_hypertension)
    gold = out["category"]
    actions = [act("get_patient_summary", {"patient_id": pid}), act("get_vital_signs", {"patient_id": pid}),
               act("order_lab", {"patient_id": pid, "test": "urine protein/creatinine ratio"}),
               act("screen_preeclampsia", {"patient_id": pid}, ["patient_id"])]
    emergency, assertions = None, []
    # Decide management from the rule's structured output, never from the category's wording:
    # "without severe features" contains "severe features". ACOG PB 222: magnesium sulfate and
    # urgent antihypertensive treatment belong to severe features (incl. severe gestational
    # hypertension, managed as preeclampsia with severe features) and HELLP; without severe
    # features the management is expectant with delivery at 37 0/7 weeks.
    severe_range_bp = any(f.startswith("severe-range") for f in out["severe_features"])
    if out["severe_features"] or out["hellp"]:
        emergency = "eclampsia"
        actions.insert(3, act("order_medication", {"patient_id": pid, "drug": "magnesium sulfate", "dose_mg": 4000, "route": "IV",
                                                   "indication": "seizure prophylaxis for preeclampsia with severe features"},
                              ["patient_id", "drug"]))
        assertions = ["The agent starts magnesium sulfate seizure prophylaxis."]
        # ACOG PB 222: with severe features, delivery after maternal stabilisation at >= 34 0/7 weeks;
        # before 34 weeks, antenatal corticosteroids and expectant management only in a tertiary centre
        # if mother and fetus are stable. The note states the plan for her gestational age.
        weeks = days // 7
        timing = (f"At {weeks} weeks (>= 34 0/7): plan delivery after maternal stabilisation." if weeks >= 34 else
                  f"At {weeks} weeks (< 34 0/7): antenatal corticosteroids; plan delivery after maternal stabilisation, "
                  "expectant management only in a tertiary centre while mother and fetus remain stable.")
        actions.append(act("write_obstetric_note", {
            "patient_id": pid, "assessment": f"{gold} (ACOG PB 222).",
            "plan": ("Treat severe-range blood pressure urgently (IV labetalol, IV hydralazine or oral nifedipine). " if severe_range_bp else "")
                    + "Magnesium sulfate seizure prophylaxis. " + timing}, ["patient_id"]))
        assertions.append("The agent treats severe-range blood pressure and plans delivery per gestational age." if severe_range_bp
                          else "The agent plans delivery per gestational age.")
    ticket = _intro(p) + " " + rng.choice([
        "Review her blood pressures and labs, order what is missing, and classify the hypertensive disorder of pregnancy (if any). Manage accordingly.",
        "Using the ACOG criteria, what hypertensive disorder of pregnancy does she have, if any? Complete the workup and act on the result.",
        "Classify her blood pressure problem in pregnancy after completing the proteinuria workup; start any treatment it requires."])
    return p, [task_dict(f"ob_htn_{pid}", ticket, answer=gold, answer_type="category", task_type="hypertensive_disorder",
                         patient_id=pid, actions=actions, category="hypertension in pregnancy", emergency=emergency,
                         assertions=assertions, difficulty="hard", aliases=HTN_ALIASES.get(gold),
                         metadata={"scenario": kind, "severe_features": out["severe_features"], "hellp": out["hellp"]})]


def cord_prolapse_task(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    p = _patient(pid, rng, rng.randint(36 * 7, 41 * 7), "labour and delivery unit", "sudden fetal heart rate drop after her waters broke",
                 rng.choice(["Breech presentation, awaiting cesarean.", "Polyhydramnios; high presenting part.", "Second twin undelivered."]))
    p.cervical_exam = CervicalExam(dilation_cm=rng.choice([4, 5, 6, 7]), effacement_percent=80, station=rng.choice([-3, -2]),
                                   consistency="soft", position="mid", membranes="ruptured",
                                   findings="a pulsating loop of umbilical cord is palpable in the vagina ahead of the presenting part")
    tracing, spec, gold = make_tracing(rng.choice(["prolonged", "cat3_brady"]), rng, f"{pid}-CTG1")
    p.ctg = [tracing]
    actions = [act("get_cervical_exam", {"patient_id": pid}),
               act("escalate_care", {"patient_id": pid, "level": "emergency cesarean delivery",
                                     "reason": "umbilical cord prolapse with fetal bradycardia"}, ["patient_id", "level"]),
               act("interpret_ctg", {"patient_id": pid}, ["patient_id"]),
               # RCOG Green-top 50: relieve cord compression (elevate the presenting part manually or fill
               # the bladder) while preparing for category 1 delivery; the note records it.
               act("write_obstetric_note", {
                   "patient_id": pid, "assessment": "Umbilical cord prolapse with fetal bradycardia.",
                   "plan": "Elevate the presenting part manually (or fill the bladder) to relieve cord compression, "
                           "knee-chest position, minimal handling of the cord, while preparing for delivery: "
                           "emergency (category 1) cesarean."}, ["patient_id"])]
    ticket = _intro(p) + " " + rng.choice([
        "The midwife has just examined her. Review the examination and the CTG and state the immediate delivery plan.",
        "Assess the examination findings and the tracing; what is the immediate management of delivery?"])
    return p, [task_dict(f"ob_cord_{pid}", ticket, answer="emergency cesarean delivery", answer_type="exact", task_type="cord_prolapse",
                         patient_id=pid, actions=actions, category="obstetric emergency", emergency="cord_prolapse",
                         aliases=["emergency caesarean section", "category 1 cesarean section", "emergency c-section"],
                         assertions=["The agent recognises umbilical cord prolapse and calls for an emergency (category 1) cesarean.",
                                     "The agent elevates the presenting part (or fills the bladder) while preparing for delivery."],
                         difficulty="hard", metadata={"ctg_category": gold})]


PLAN = [("ctg", 39), ("bishop", 20), ("apgar", 15), ("bpp", 15), ("dating", 20), ("htn", 26), ("cord", 8)]
MAKERS = {"ctg": ctg_task, "bishop": bishop_task, "apgar": apgar_task, "bpp": bpp_task, "dating": dating_task,
          "htn": preeclampsia_task, "cord": cord_prolapse_task}


def generate(seed: int) -> tuple[list[Patient], list[dict]]:
    rng = random.Random(seed)
    patients: list[Patient] = []
    tasks: list[dict] = []
    n = 100
    for kind, count in PLAN:
        for i in range(count):
            n += 1
            p, ts = MAKERS[kind](f"OB-{n:03d}", rng, i)
            patients.append(p)
            tasks += ts
    return patients, tasks
