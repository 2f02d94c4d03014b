"""Synthetic psychiatry patients (written by our code, seeded) and their generated tasks.

Each generated patient carries one assessment scenario: a completed form on file or an interview
in which the clinician asks the instrument's questions verbatim and the patient answers with the
instrument's own response options, so the item scores are unambiguous. The gold answer of every
task is computed by the instrument (`envs.calculators`, MDQ rule in `instruments.py`) or by
`interactions.pair_findings`, which the interaction tool also uses.
"""

from __future__ import annotations

import random
from typing import Any

from envs.calculators import CALCULATORS
from envs.coherence import (
    SEX_SPECIFIC_DRUGS, living_fits_age, occupation_fits_age, setting_fits_reason, stressor_fits_occupation,
)
from envs.domains.psychiatry import instruments as I
from envs.domains.psychiatry import interactions as IX
from envs.domains.psychiatry.data_model import (
    CAGEAnswers, CIWAObservation, CSSRSAnswers, InteractionRule, LabelGradedPair, LabResult, Medication, MDQAnswers,
    Patient, PsychHistory, SocialHistory, SymptomReports, Utterance,
)

FIRST_F = ["Maria", "Aisha", "Hannah", "Chloe", "Priya", "Lucia", "Grace", "Mei", "Fatima", "Olivia", "Sofia", "Amara",
           "Nadia", "Rachel", "Elena", "Yuki", "Zara", "Ingrid", "Leah", "Rosa"]
FIRST_M = ["James", "Omar", "Daniel", "Kenji", "Mateo", "Samuel", "Arjun", "Lucas", "Tomas", "David", "Kwame", "Ivan",
           "Noah", "Hassan", "Ethan", "Rafael", "Liam", "Victor", "Ben", "Malik"]
LAST = ["Okafor", "Lindqvist", "Haddad", "Nguyen", "Morales", "Kowalski", "Patel", "Brennan", "Rossi", "Tanaka", "Mensah",
        "Schultz", "Dubois", "Farouk", "Ivanova", "Costa", "Reyes", "Andersson", "Clarke", "Ali", "Novak", "Osei"]
SETTINGS = ["outpatient psychiatry clinic", "primary care behavioural health visit", "emergency department",
            "inpatient psychiatric unit", "telehealth follow-up"]
LIVING = ["lives alone", "lives with partner", "lives with parents", "lives with partner and two children", "shared flat"]
ANSWERS = {
    0: ["Not at all.", "No, not at all.", "Not at all, really."],
    1: ["Several days.", "I'd say several days.", "Maybe several days."],
    2: ["More than half the days.", "Honestly, more than half the days.", "More than half the days, yes."],
    3: ["Nearly every day.", "Nearly every day, to be honest.", "Pretty much nearly every day."],
}
PROVENANCE = {"source": "authored", "generator": "envs.domains.psychiatry.generate", "license": "project (ours)"}
# The instrument publication or labelling each generated task type's gold follows.
GUIDELINES = {
    "phq9_total": "PHQ-9 (Kroenke, Spitzer & Williams, J Gen Intern Med 2001;16:606-613)",
    "phq9_band": "PHQ-9 severity bands (Kroenke, Spitzer & Williams, J Gen Intern Med 2001;16:606-613)",
    "gad7_band": "GAD-7 (Spitzer et al., Arch Intern Med 2006;166:1092-1097)",
    "cssrs_triage": "Columbia-Suicide Severity Rating Scale screener with triage (Posner et al., Am J Psychiatry 2011; Columbia "
                    "Lighthouse Project C-SSRS Screen Version)",
    "audit_c_screen": "AUDIT-C (Bush et al., Arch Intern Med 1998;158:1789-1795)",
    "mdq_screen": "Mood Disorder Questionnaire (Hirschfeld et al., Am J Psychiatry 2000;157:1873-1875)",
    "epds_band": "Edinburgh Postnatal Depression Scale (Cox, Holden & Sagovsky, Br J Psychiatry 1987;150:782-786)",
    "ciwa_band": "CIWA-Ar (Sullivan et al., Br J Addict 1989;84:1353-1357)",
    "psych_med_interaction": "the drug_interaction domain's grade of the pair (US label overlay rule naming its label section, "
                             "else the ANSM thesaurus); for pairs it does not grade, the label section or guideline each "
                             "rule of interaction_rules.json cites",
}


def _name(rng: random.Random, sex: str) -> str:
    return f"{rng.choice(FIRST_F if sex == 'female' else FIRST_M)} {rng.choice(LAST)}"


OCCUPATIONS = ["works in retail", "nurse", "software developer", "unemployed", "student", "retired teacher",
               "warehouse worker", "accountant"]
STRESSORS = ["relationship breakup", "job loss", "bereavement", "financial strain", "exams", "none reported"]


def _base_patient(pid: str, rng: random.Random, *, sex: str | None = None, age: tuple[int, int] = (19, 78),
                  setting: str | None = None, complaint: str, history: str) -> Patient:
    sex = sex or rng.choice(["female", "male"])
    name, years = _name(rng, sex), rng.randint(*age)
    # Occupation and life events are drawn with the age they need (envs.coherence: a retired teacher is
    # not 24, exams come with study, a job loss with a job).
    employment = rng.choice([o for o in OCCUPATIONS if occupation_fits_age(o, years)])
    stressors = [s for s in STRESSORS if stressor_fits_occupation(s, employment)]
    # the setting is drawn among those where the visit's reason is seen (envs.coherence: no annual review
    # in the emergency department, no patient "brought in" to a telehealth call), the living arrangement
    # with the age it needs
    setting = setting or rng.choice([x for x in SETTINGS if setting_fits_reason(x, complaint)])
    return Patient(
        patient_id=pid, name=name, age=years, sex=sex, setting=setting,
        chief_complaint=complaint, presenting_history=history,
        history=PsychHistory(diagnoses=rng.sample(["major depressive disorder", "generalized anxiety disorder",
                                                   "post-traumatic stress disorder", "alcohol use disorder",
                                                   "panic disorder", "no prior psychiatric diagnosis"], 1),
                             hospitalizations=rng.choice([0, 0, 0, 1, 2]),
                             family_history=rng.sample(["depression in mother", "bipolar disorder in uncle",
                                                        "alcohol use disorder in father", "no known family psychiatric history"], 1),
                             substance_use=rng.sample(["social alcohol use", "no illicit drugs", "cannabis weekly",
                                                       "former smoker"], 2)),
        social=SocialHistory(living=rng.choice([x for x in LIVING if living_fits_age(x, years)]),
                             supports=rng.sample(["sister", "partner", "close friend", "church group", "parents"], 2),
                             employment=employment,
                             firearms_access=rng.random() < 0.15,
                             recent_stressors=rng.sample(stressors, 1)),
        allergies=rng.choice([[], [], ["penicillin"], ["sulfa drugs"]]),
        provenance=PROVENANCE,
    )


def _intro(p: Patient) -> str:
    """A patient-specific opening for a ticket (who, where, why, context)."""
    who = "woman" if p.sex == "female" else "man"
    stress = [x for x in p.social.recent_stressors if x != "none reported"]
    context = f"; recent stressor: {stress[0]}" if stress else ""
    return (f"{p.name} ({p.patient_id}) is a {p.age}-year-old {who} ({p.social.employment}, {p.social.living}) seen in the "
            f"{p.setting} for {p.chief_complaint}{context}.")


def _pick(rng: random.Random, options: list[str]) -> str:
    return rng.choice(options)


def _qa_transcript(rng: random.Random, intro: str, items: list[str], scores: list[int], stem: str) -> list[Utterance]:
    out = [Utterance(speaker="clinician", text=intro)]
    for item, score in zip(items, scores):
        out.append(Utterance(speaker="clinician", text=f"{stem} {item[0].lower() + item[1:]}?"))
        out.append(Utterance(speaker="patient", text=rng.choice(ANSWERS[score])))
    return out


def _scores(rng: random.Random, n: int, target: int, top: int = 3) -> list[int]:
    """n item scores 0..top summing to target (uniform over random allocations)."""
    target = max(0, min(target, n * top))
    scores = [0] * n
    for _ in range(target):
        open_items = [i for i in range(n) if scores[i] < top]
        scores[rng.choice(open_items)] += 1
    return scores


def task_dict(task_id: str, ticket: str, *, answer: str, answer_type: str, task_type: str, patient_id: str,
              actions: list[dict], category: str, unit: str | None = None, tolerance: float | None = None,
              emergency: str | None = None, assertions: list[str] | None = None, difficulty: str = "medium",
              metadata: dict | None = None) -> dict:
    t: dict[str, Any] = {
        "id": task_id, "ticket": ticket, "correct_answer": answer, "answer_type": answer_type, "patient_id": patient_id,
        "description": {"purpose": f"Psychiatric assessment: {category}.", "difficulty": difficulty, "source": "generated",
                        "category": category, "task_type": task_type, "provenance": {**PROVENANCE, "guideline": GUIDELINES[task_type]}},
        "evaluation_criteria": {"actions": actions, "nl_assertions": assertions or [],
                                "reward_basis": ["ACTION", "ANSWER"] + (["NL_ASSERTION"] if assertions else [])},
        "metadata": metadata or {},
    }
    if unit:
        t["answer_unit"] = unit
    if tolerance is not None:
        t["answer_tolerance"] = tolerance
    if emergency:
        t["emergency"] = emergency
    return t


def act(name: str, arguments: dict, compare: list[str] | None = None) -> dict:
    return {"name": name, "arguments": arguments, "compare_args": list(arguments) if compare is None else compare}


# -- scenario generators: each returns (patient, [task dicts]) -----------------------------------
def phq9_form(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    total = [3, 6, 8, 11, 13, 16, 18, 21, 24][i % 9]
    scores = _scores(rng, 9, total)
    p = _base_patient(pid, rng, complaint="low mood and poor sleep", history=(
        f"Reports {rng.choice(['two months', 'six weeks', 'several months'])} of low mood, reduced interest and "
        f"{rng.choice(['early waking', 'poor concentration at work', 'withdrawal from friends'])}. Completed a PHQ-9 in the waiting room."))
    p.reports = SymptomReports(phq9=scores)
    actions = [act("get_symptom_report", {"patient_id": pid, "instrument": "phq9"}), act("administer_phq9", {"patient_id": pid}, ["patient_id"])]
    if scores[8] > 0:
        p.reports.cssrs = CSSRSAnswers(wish_to_be_dead=True, suicidal_thoughts=rng.random() < 0.5,
                                       suicidal_behavior="never")
        actions.append(act("assess_suicide_risk", {"patient_id": pid}, ["patient_id"]))
    total_value = CALCULATORS["administer_phq9"](responses=scores).score
    ticket = _intro(p) + " " + _pick(rng, [
        "The patient completed a PHQ-9 form today. Score it and report the PHQ-9 total (0-27); act on any safety item first.",
        "A PHQ-9 was filled in before the visit. What is the total score (0-27)? Follow up any positive safety item before answering.",
        "Score the PHQ-9 on file and give the total out of 27, handling any item that needs same-day action."])
    return p, [task_dict(f"psy_phq9_total_{pid}", ticket, answer=str(total_value), answer_type="numeric", unit="points",
                         tolerance=0, task_type="phq9_total", patient_id=pid, actions=actions, category="depression screening",
                         metadata={"responses": scores})]


def phq9_interview(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    total = [2, 7, 9, 12, 14, 15, 17, 19, 20, 23, 26][i % 11]
    scores = _scores(rng, 9, total)
    scores[8] = 0 if rng.random() < 0.7 else scores[8]
    p = _base_patient(pid, rng, complaint="feeling depressed", history="Referred by the GP for assessment of depressive symptoms.")
    p.transcript = _qa_transcript(rng, "I'm going to ask you the nine PHQ-9 questions. For each, tell me how often it bothered "
                                  "you over the last two weeks: not at all, several days, more than half the days, or nearly every day.",
                                  I.PHQ9_ITEMS, scores, "Over the last two weeks, how often have you been bothered by")
    result = CALCULATORS["administer_phq9"](responses=scores)
    actions = [act("get_interview_transcript", {"patient_id": pid}, ["patient_id"]),
               act("administer_phq9", {"responses": scores}, ["responses"])]
    if scores[8] > 0:
        p.reports.cssrs = CSSRSAnswers(wish_to_be_dead=True, suicidal_thoughts=False)
        actions.append(act("assess_suicide_risk", {"patient_id": pid}, ["patient_id"]))
    ticket = _intro(p) + " " + _pick(rng, [
        "The PHQ-9 questions were asked aloud in today's interview (no form on file). Score them from the transcript and give the severity band.",
        "No PHQ-9 form exists; the clinician read the nine items during the interview. Which PHQ-9 severity band do the answers give?",
        "Use the interview transcript, where each PHQ-9 item was asked, to score the PHQ-9 and report its depression severity category."])
    return p, [task_dict(f"psy_phq9_band_{pid}", ticket, answer=result.category, answer_type="category",
                         task_type="phq9_band", patient_id=pid, actions=actions, category="depression screening",
                         metadata={"responses": scores, "total": result.score})]


def gad7(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    total = [2, 4, 6, 8, 10, 12, 14, 15, 17, 20][i % 10]
    scores = _scores(rng, 7, total)
    p = _base_patient(pid, rng, complaint="constant worry", history="Describes months of worry about work, health and family, "
                      "with muscle tension and poor sleep.")
    interview = rng.random() < 0.5
    if interview:
        p.transcript = _qa_transcript(rng, "Let's go through the GAD-7. Over the last two weeks, how often have these bothered you?",
                                      I.GAD7_ITEMS, scores, "Over the last two weeks, how often have you been bothered by")
        actions = [act("get_interview_transcript", {"patient_id": pid}, ["patient_id"]),
                   act("administer_gad7", {"responses": scores}, ["responses"])]
        source = "asked the GAD-7 questions in today's interview"
    else:
        p.reports = SymptomReports(gad7=scores)
        actions = [act("get_symptom_report", {"patient_id": pid, "instrument": "gad7"}),
                   act("administer_gad7", {"patient_id": pid}, ["patient_id"])]
        source = "completed a GAD-7 form before the visit"
    result = CALCULATORS["administer_gad7"](responses=scores)
    ticket = _intro(p) + f" The patient {source}. " + _pick(rng, [
        "Score it and report the GAD-7 anxiety severity band.", "Which GAD-7 severity category applies?",
        "What is the anxiety severity band on the GAD-7?"])
    return p, [task_dict(f"psy_gad7_{pid}", ticket, answer=result.category, answer_type="category", task_type="gad7_band",
                         patient_id=pid, actions=actions, category="anxiety screening",
                         metadata={"responses": scores, "total": result.score, "interview": interview})]


_BEHAVIOR_TEXT = {
    "never": ["No, never.", "No. I've never done anything like that."],
    "over_3_months_ago": ["Yes. About two years ago I took an overdose of my tablets.",
                          "Once, around a year ago, I cut my wrists. Not since then."],
    "past_3_months": ["Yes. Last week I took a handful of my sleeping pills.",
                      "Three weeks ago I stood on the bridge and got ready to jump before my brother pulled me back."],
}


def cssrs(pid: str, rng: random.Random, level: int) -> tuple[Patient, list[dict]]:
    if level == 0:
        ans = CSSRSAnswers(wish_to_be_dead=False, suicidal_thoughts=False)
    elif level == 1:
        ans = CSSRSAnswers(wish_to_be_dead=True, suicidal_thoughts=rng.random() < 0.5)
    elif level == 2:
        if rng.random() < 0.5:
            ans = CSSRSAnswers(wish_to_be_dead=True, suicidal_thoughts=True, thoughts_with_method=True)
        else:
            ans = CSSRSAnswers(wish_to_be_dead=True, suicidal_thoughts=rng.random() < 0.5, suicidal_behavior="over_3_months_ago")
    else:
        kind = rng.choice(["intent", "plan", "behavior"])
        ans = CSSRSAnswers(wish_to_be_dead=True, suicidal_thoughts=True, thoughts_with_method=True,
                           intent=kind in ("intent", "plan"), plan_with_intent=kind == "plan",
                           suicidal_behavior="past_3_months" if kind == "behavior" else rng.choice(["never", "over_3_months_ago"]))
    complaint = rng.choice(["worsening depression", "brought in by family after a crisis", "hopelessness after a breakup"])
    p = _base_patient(pid, rng, setting=rng.choice([x for x in ("emergency department", "outpatient psychiatry clinic",
                                                                "telehealth follow-up") if setting_fits_reason(x, complaint)]),
                      complaint=complaint,
                      history="Depressive symptoms for several weeks; the clinician completed the C-SSRS screener during the interview.")
    lines = [Utterance(speaker="clinician", text="I'd like to ask you some questions from the Columbia screener. Please answer honestly.")]

    def qa(key: str, answer: str) -> None:
        lines.append(Utterance(speaker="clinician", text=I.CSSRS_QUESTIONS[key]))
        lines.append(Utterance(speaker="patient", text=answer))

    qa("wish_to_be_dead", "Yes. Most nights I wish I just wouldn't wake up." if ans.wish_to_be_dead else "No, I haven't felt that.")
    qa("suicidal_thoughts", "Yes, I have thought about killing myself." if ans.suicidal_thoughts else "No, not actually killing myself.")
    if ans.suicidal_thoughts:
        qa("thoughts_with_method", "Yes, I've thought about taking all my pills." if ans.thoughts_with_method else "No, I haven't thought about how.")
        qa("intent", "Yes, part of me means to do it." if ans.intent else "No, I don't intend to act on it.")
        qa("plan_with_intent", "Yes. I've worked out when and how, and I plan to go through with it." if ans.plan_with_intent
           else "No, I haven't worked out any details.")
    qa("suicidal_behavior", rng.choice(_BEHAVIOR_TEXT[ans.suicidal_behavior]))
    p.transcript = lines
    args = ans.model_dump()
    if not ans.suicidal_thoughts:
        args = {k: v for k, v in args.items() if k not in ("thoughts_with_method", "intent", "plan_with_intent")}
    result = CALCULATORS["assess_suicide_risk"](**args)
    actions = [act("get_interview_transcript", {"patient_id": pid}, ["patient_id"]), act("assess_suicide_risk", args)]
    emergency, assertions = None, []
    if level == 3:
        emergency = "suicidality"
        actions.append(act("escalate_care", {"patient_id": pid, "level": "emergency psychiatric evaluation",
                                             "reason": f"C-SSRS screen {result.category}"}, ["patient_id"]))
        assertions = ["The agent escalates to an emergency psychiatric evaluation and keeps the patient under observation.",
                      "The agent does not discharge the patient."]
    elif level == 2:
        actions.append(act("create_safety_plan", {
            "patient_id": pid, "warning_signs": ["hopeless thoughts at night"], "coping_strategies": ["walk", "music"],
            "social_contacts": ["sister"], "professional_contacts": ["outpatient psychiatrist"],
            "means_restriction": "family to hold medication supply; no firearms at home"}, ["patient_id"]))
        actions.append(act("schedule_follow_up", {"patient_id": pid, "within_days": 7, "with_whom": "outpatient psychiatrist",
                                                  "purpose": "review after moderate-risk C-SSRS screen"}, ["patient_id"]))
    elif level == 1:
        actions.append(act("schedule_follow_up", {"patient_id": pid, "within_days": 14, "with_whom": "outpatient psychiatrist",
                                                  "purpose": "review after low-risk C-SSRS screen"}, ["patient_id"]))
    ticket = _intro(p) + " " + _pick(rng, [
        "The clinician asked the C-SSRS screener questions during the interview. Complete the screener from the transcript, "
        "give the C-SSRS triage level, and take the action that level requires.",
        "Use the Columbia screener exchange in today's transcript to determine the C-SSRS triage level, then act on it.",
        "Work through the C-SSRS screener answers recorded in the interview, state the triage level, and carry out the "
        "disposition that level calls for."])
    return p, [task_dict(f"psy_cssrs_{pid}", ticket, answer=result.category, answer_type="category", task_type="cssrs_triage",
                         patient_id=pid, actions=actions, category="suicide risk screening", emergency=emergency,
                         assertions=assertions, difficulty="hard" if level >= 2 else "medium",
                         metadata={"answers": args, "level": result.score})]


def audit_c(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    total, sex = [(2, "female"), (3, "female"), (3, "male"), (4, "male"), (2, "male"), (5, "female"), (7, "male"),
                  (1, "female"), (4, "female"), (3, "male"), (9, "male"), (6, "female")][i % 12]
    scores = _scores(rng, 3, total, top=4)
    p = _base_patient(pid, rng, sex=sex, complaint="annual review; partner concerned about drinking",
                      history="Completed the AUDIT-C alcohol questions on the intake form.")
    p.reports = SymptomReports(audit_c=scores)
    result = CALCULATORS["administer_audit_c"](responses=scores, sex=sex)
    actions = [act("get_symptom_report", {"patient_id": pid, "instrument": "audit_c"}),
               act("administer_audit_c", {"patient_id": pid}, ["patient_id"])]
    ticket = _intro(p) + " " + _pick(rng, [
        "The AUDIT-C was completed on the intake form. Is the alcohol screen positive or negative for this patient?",
        "Score the AUDIT-C on file with the threshold that applies to this patient: positive or negative?",
        "Does the AUDIT-C on the intake form screen positive or negative for hazardous drinking?"])
    return p, [task_dict(f"psy_auditc_{pid}", ticket, answer=result.category, answer_type="category", task_type="audit_c_screen",
                         patient_id=pid, actions=actions, category="alcohol screening",
                         metadata={"responses": scores, "sex": sex, "total": result.score})]


def mdq(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    yes, same, problem = [(4, True, "serious problem"), (7, True, "moderate problem"), (9, False, "serious problem"),
                          (8, True, "minor problem"), (11, True, "serious problem"), (6, True, "moderate problem"),
                          (7, True, "serious problem"), (10, True, "no problem"), (8, True, "moderate problem"),
                          (12, False, "moderate problem"), (7, True, "minor problem"), (9, True, "serious problem")][i % 12]
    items = [True] * yes + [False] * (13 - yes)
    rng.shuffle(items)
    p = _base_patient(pid, rng, complaint="depression not responding to an SSRI",
                      history="Recurrent depressive episodes; screened for bipolarity before changing the antidepressant.")
    p.reports = SymptomReports(mdq=MDQAnswers(items=items, same_period=same, problem_level=problem))
    p.medications = [Medication(name="sertraline", dose_mg=100, frequency="daily")]
    result = I.score_mdq(items, same, problem)
    actions = [act("get_symptom_report", {"patient_id": pid, "instrument": "mdq"}), act("screen_bipolar", {"patient_id": pid}, ["patient_id"])]
    ticket = _intro(p) + " " + _pick(rng, [
        "Before the antidepressant is changed, the patient completed the Mood Disorder Questionnaire. Is the bipolar screen positive or negative?",
        "An MDQ is on file. Does it screen positive or negative for bipolar spectrum disorder?",
        "Score the Mood Disorder Questionnaire on file: positive or negative screen?"])
    return p, [task_dict(f"psy_mdq_{pid}", ticket, answer=result.category, answer_type="category", task_type="mdq_screen",
                         patient_id=pid, actions=actions, category="bipolar screening",
                         metadata={"items_yes": yes, "same_period": same, "problem_level": problem})]


def epds(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    total = [4, 7, 9, 10, 11, 12, 13, 15, 18, 22][i % 10]
    scores = _scores(rng, 10, total)
    p = _base_patient(pid, rng, sex="female", age=(19, 42), setting="perinatal mental health clinic",
                      complaint="tearfulness after the birth of her baby",
                      history="Delivered a healthy baby; reports tearfulness and poor sleep. Completed the EPDS at the postnatal visit.")
    p.weeks_postpartum = rng.choice([3, 5, 6, 8, 10])
    p.reports = SymptomReports(epds=scores)
    actions = [act("get_symptom_report", {"patient_id": pid, "instrument": "epds"}), act("administer_epds", {"patient_id": pid}, ["patient_id"])]
    if scores[9] > 0:
        p.reports.cssrs = CSSRSAnswers(wish_to_be_dead=True, suicidal_thoughts=False)
        actions.append(act("assess_suicide_risk", {"patient_id": pid}, ["patient_id"]))
    result = CALCULATORS["administer_epds"](responses=scores)
    ticket = _intro(p) + f" She is {p.weeks_postpartum} weeks postpartum. " + _pick(rng, [
        "She completed the Edinburgh Postnatal Depression Scale. Score it and give the EPDS interpretation band; act on any safety item first.",
        "An EPDS is on file from the postnatal visit. Which EPDS band applies? Follow up any positive safety item before answering.",
        "Score the EPDS on file and report its interpretation category, handling any item needing same-day action."])
    return p, [task_dict(f"psy_epds_{pid}", ticket, answer=result.category, answer_type="category", task_type="epds_band",
                         patient_id=pid, actions=actions, category="perinatal depression screening",
                         metadata={"responses": scores, "total": result.score})]


def ciwa(pid: str, rng: random.Random, i: int) -> tuple[Patient, list[dict]]:
    target = [4, 7, 10, 13, 15, 18, 24, 8, 16, 30][i % 10]
    vals = _scores(rng, 10, target, top=4)
    obs = CIWAObservation(**dict(zip(I.CIWA_FIELDS, vals)))
    p = _base_patient(pid, rng, setting="inpatient psychiatric unit", complaint="admitted for alcohol detoxification",
                      history="Drinks about a litre of vodka daily; last drink 30 hours ago. Nursing recorded a CIWA-Ar at 08:00.")
    p.history.substance_use = ["alcohol use disorder, severe", "no illicit drugs"]
    p.reports = SymptomReports(ciwa=obs)
    result = CALCULATORS["calculate_ciwa_ar"](**obs.model_dump())
    actions = [act("get_symptom_report", {"patient_id": pid, "instrument": "ciwa"}), act("calculate_ciwa_ar", {"patient_id": pid}, ["patient_id"])]
    ticket = _intro(p) + " " + _pick(rng, [
        "Nursing recorded a CIWA-Ar this morning. What is the withdrawal severity band?",
        "Score the CIWA-Ar observation on file and give the alcohol-withdrawal severity category.",
        "Which CIWA-Ar severity band does this morning's nursing observation give?"])
    return p, [task_dict(f"psy_ciwa_{pid}", ticket, answer=result.category, answer_type="category", task_type="ciwa_band",
                         patient_id=pid, actions=actions, category="alcohol withdrawal",
                         metadata={"total": result.score})]


INTERACTION_SCENARIOS = [
    (["phenelzine"], "sertraline"), (["sertraline"], "phenelzine"), (["clozapine"], "carbamazepine"),
    (["tranylcypromine"], "methylphenidate"), (["naltrexone"], "oxycodone"), (["lithium"], "ibuprofen"),
    (["lithium"], "lisinopril"), (["lithium"], "hydrochlorothiazide"), (["lithium"], "losartan"),
    (["sertraline"], "tramadol"), (["citalopram"], "ondansetron"), (["lorazepam"], "oxycodone"),
    (["valproic acid"], "lamotrigine"), (["bupropion"], "tramadol"), (["mirtazapine"], "linezolid"),
    (["quetiapine"], "carbamazepine"), (["disulfiram"], "metronidazole"), (["fluoxetine"], "aripiprazole"),
    (["paroxetine"], "aripiprazole"), (["sertraline"], "atorvastatin"), (["lithium"], "propranolol"),
    (["olanzapine"], "metformin"), (["lamotrigine"], "levothyroxine"), (["carbamazepine"], "ethinyl estradiol"),
    (["methadone"], "clonazepam"), (["duloxetine"], "sumatriptan"),
]


def med_interaction(pid: str, rng: random.Random, scenario: tuple[list[str], str], rules: list[InteractionRule], formulary: dict,
                    label_pairs: dict) -> tuple[Patient, list[dict]]:
    current, proposed = scenario
    # A drug labelled for one sex (a combined hormonal contraceptive) comes with a patient of that sex and, for a
    # contraceptive, of reproductive age (envs.coherence.SEX_SPECIFIC_DRUGS).
    only = {SEX_SPECIFIC_DRUGS[d][0] for d in [*current, proposed] if d in SEX_SPECIFIC_DRUGS}
    sex = only.pop() if only else None
    p = _base_patient(pid, rng, sex=sex, age=(19, 45) if sex == "female" else (19, 78), complaint="medication review", history=(
        f"Stable on {', '.join(current)}. A new prescription of {proposed} is being considered by another clinician."))
    p.medications = [Medication(name=d, dose_mg=rng.choice([10, 20, 50, 100, 300]), frequency="daily") for d in current]
    groups = {d: formulary[d]["groups"] for d in [*current, proposed]}
    findings = [f for d in current for f in IX.pair_findings(d, proposed, groups, rules, label_pairs)]
    worst = IX.pair_severity(findings)
    actions = [act("check_psych_med_interactions", {"patient_id": pid, "proposed_drug": proposed}, ["patient_id", "proposed_drug"])]
    ticket = _intro(p) + f" Current medication: {', '.join(current)}. " + _pick(rng, [
        f"Another clinician wants to start {proposed}. What is the highest interaction severity this would create "
        "(contraindicated, major, moderate, minor or none)?",
        f"Before {proposed} is added, check the combination: what is the worst interaction severity (contraindicated, major, "
        "moderate, minor or none)?",
        f"A prescription for {proposed} is proposed. Report the highest severity of any interaction it creates "
        "(contraindicated / major / moderate / minor / none)."])
    return p, [task_dict(f"psy_ddi_{pid}", ticket, answer=worst, answer_type="category", task_type="psych_med_interaction",
                         patient_id=pid, actions=actions, category="psychopharmacology",
                         metadata={"current": current, "proposed": proposed,
                                   "rules": sorted({f["rule"] for f in findings if f["severity"] == worst})})]


PLAN = [("phq9_form", 18), ("phq9_interview", 18), ("gad7", 16), ("cssrs3", 9), ("cssrs2", 8), ("cssrs1", 5), ("cssrs0", 3),
        ("audit_c", 12), ("mdq", 12), ("epds", 10), ("ciwa", 10), ("ddi", 26)]


def generate(seed: int, rules: list[InteractionRule], formulary: dict, label_pairs: list[LabelGradedPair]) -> tuple[list[Patient], list[dict]]:
    """Patients and tasks; interaction golds grade pairs as `interactions.pair_findings` does (the
    drug_interaction domain's level in `label_pairs` first, else the authored rules)."""
    label_index = IX.label_index(label_pairs)
    rng = random.Random(seed)
    patients: list[Patient] = []
    tasks: list[dict] = []
    n = 100
    makers = {"phq9_form": phq9_form, "phq9_interview": phq9_interview, "gad7": gad7, "audit_c": audit_c, "mdq": mdq,
              "epds": epds, "ciwa": ciwa}
    for kind, count in PLAN:
        for i in range(count):
            n += 1
            pid = f"PSY-{n:03d}"
            if kind.startswith("cssrs"):
                p, ts = cssrs(pid, rng, int(kind[-1]))
            elif kind == "ddi":
                p, ts = med_interaction(pid, rng, INTERACTION_SCENARIOS[i % len(INTERACTION_SCENARIOS)], rules, formulary,
                                        label_index)
            else:
                p, ts = makers[kind](pid, rng, i)
            patients.append(p)
            tasks += ts
    return patients, tasks
