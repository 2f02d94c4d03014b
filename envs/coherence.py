"""Coherence of the patients behind the tasks: fields that describe one person must agree.

A task generator that draws each field on its own makes patients no clinician would believe (a man
named Olga, a 24-year-old retired teacher, a post-dates induction at 39 weeks, a GCS of 14 on a
ventilator). Each relation is one named `Rule` below, with the guideline or label it follows; the
rules run over every task of a domain and the record the task is about (its patient, or its study),
by `hcgym tasks validate` (`envs.validate.validate_domain`), so a contradiction fails the build
naming the task, the rule and the fields. The domain READMEs list the rules that apply to them.

A rule sees a `Subject`: the task, the record it is about (a plain dict read from the domain's
built `db.json`, or the patient an imported task carries), and the database's top-level values
(the record clock, today's date). Rules read plain dicts, never a domain's models, so this module
imports no domain.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from datetime import date, datetime, timedelta
from pathlib import Path
from typing import Any

from envs.core.task import Task

# -- tables -----------------------------------------------------------------------------------------

# Given names by sex, as the task generators and the authored records use them. A patient's first name
# must be in the list of the patient's sex: a name in neither list is an error too, so a new name
# pool is added here (with its sex) rather than drawn unchecked.
FIRST_NAMES: dict[str, frozenset[str]] = {
    "female": frozenset("""
        Ada Adaeze Agnes Aisha Amara Amelia Angela Anya Ayesha Beatrice Beatriz Brenda Camila Carla Chloe
        Clara Dorothy Edith Eleanor Elena Eva Evelyn Fatima Fatou Freya Gloria Grace Greta Hana Hannah Imani
        Ines Ingrid Irene Isabel Janet Jasmine Julia Keira Kira Laura Leah Leila Linda Lorraine Lucia Margaret
        Maria Marta Martha Maya Mei Mia Mira Mona Nadia Naomi Nina Nora Olga Olivia Priya Priyanka Rachel Rosa
        Ruth Sana Sofia Susan Tara Teresa Thandi Vera Yasmin Yuki Zara""".split()),
    "male": frozenset("""
        Abel Ahmed Arjun Arthur Ben Cyrus Daniel David Dennis Derek Emil Ethan Farid Felix Frank George Gordon
        Harold Hassan Hugh Hugo Ivan James Javier Jonah Kenji Kevin Kofi Kwame Leonard Liam Lucas Luis Malik
        Marcus Mateo Nathan Noah Oliver Omar Oscar Patrick Pavel Peter Rafael Rashid Raymond Robert Samir
        Samuel Stanley Tobias Tomas Tomasz Victor Walter Wes William""".split()),
}

# Drugs labelled for one sex only, with the label section that says so.
SEX_SPECIFIC_DRUGS: dict[str, tuple[str, str]] = {
    # combined and progestin-only hormonal contraceptives: "indicated for use by females of
    # reproductive potential to prevent pregnancy" (US prescribing information, section 1, e.g.
    # ethinyl estradiol/levonorgestrel, ethinyl estradiol/drospirenone, norethindrone 0.35 mg)
    "ethinyl estradiol": ("female", "combined hormonal contraceptive labels, section 1 Indications"),
    "levonorgestrel": ("female", "hormonal contraceptive labels, section 1 Indications"),
    "norethindrone": ("female", "norethindrone labels, section 1 Indications (contraception, amenorrhoea, endometriosis)"),
    "drospirenone": ("female", "combined hormonal contraceptive labels, section 1 Indications"),
    "desogestrel": ("female", "combined hormonal contraceptive labels, section 1 Indications"),
    "norgestimate": ("female", "combined hormonal contraceptive labels, section 1 Indications"),
    # 5-alpha-reductase inhibitors: "not indicated for use in women" (Avodart PI section 1 and
    # section 4 contraindicated in pregnancy; Proscar PI section 1 men with BPH, section 4 pregnancy)
    "dutasteride": ("male", "Avodart (dutasteride) PI, sections 1 and 4"),
    "finasteride": ("male", "Proscar (finasteride) PI, sections 1 and 4"),
}

# Conditions only one sex can have (anatomy), as words that name them in a record.
SEX_SPECIFIC_CONDITIONS: dict[str, re.Pattern[str]] = {
    "female": re.compile(r"\b(pregnan\w*|pre-?eclampsia|eclampsia|ovar(?:y|ian)|uter(?:us|ine)|endometri\w*|"
                         r"cervix|postpartum|gestational)\b", re.I),
    "male": re.compile(r"\b(prostat\w*|testic\w*|testis|scrot\w*)\b", re.I),
}

# Occupations that fix an age band: plausibility bounds, not a guideline (retirement before 55 and
# full-time study past 35 are rare enough that a task generator must not draw them by chance).
OCCUPATION_AGE: dict[str, tuple[int, int]] = {"retired": (55, 120), "student": (16, 35), "unemployed": (16, 66)}

# Living arrangements that fix an age band (plausibility): at 51 and over, a patient's parents are
# mostly in their late seventies or dead, so "lives with parents" is not drawn by chance.
LIVING_AGE: dict[str, tuple[int, int]] = {"lives with parents": (16, 50)}

# Indications that fix an age band (plausibility): a pre-employment examination past the usual
# retirement age (US full retirement age 66-67, Social Security Administration) is not drawn by chance.
INDICATION_AGE: dict[str, tuple[int, int]] = {"pre-employment": (16, 66)}

# Visit reasons and the settings they cannot be seen in: a scheduled (annual, routine) review is an
# outpatient, primary-care or telehealth visit, not an emergency or inpatient presentation, and a
# medication review is no reason to come to the emergency department; a patient "brought in" by others
# is seen in person (ESI Implementation Handbook v4: the emergency department sees unscheduled,
# acute presentations).
REASON_EXCLUDED_SETTINGS: list[tuple[re.Pattern[str], tuple[str, ...]]] = [
    (re.compile(r"\b(annual|routine)\b[^;]*\breview\b|\broutine (visit|check)", re.I), ("emergency department", "inpatient")),
    (re.compile(r"\bmedication review\b", re.I), ("emergency department",)),
    (re.compile(r"\bbrought in\b", re.I), ("telehealth",)),
]

# Life events that fix the occupation (a task generator draws them together).
STRESSOR_OCCUPATION: dict[str, Callable[[str], bool]] = {
    "exams": lambda occupation: "student" in occupation,
    "job loss": lambda occupation: not any(w in occupation for w in ("retired", "student")),
}


def occupation_fits_age(occupation: str, age: int) -> bool:
    """Whether an occupation (free text, e.g. "retired teacher") is plausible at an age."""
    text = occupation.lower()
    return all(lo <= age <= hi for word, (lo, hi) in OCCUPATION_AGE.items() if word in text)


def _fits(table: dict[str, tuple[int, int]], text: str, age: int) -> bool:
    text = text.lower()
    return all(lo <= age <= hi for word, (lo, hi) in table.items() if word in text)


def living_fits_age(living: str, age: int) -> bool:
    return _fits(LIVING_AGE, living, age)


def indication_fits_age(indication: str, age: int) -> bool:
    return _fits(INDICATION_AGE, indication, age)


def setting_fits_reason(setting: str, reason: str) -> bool:
    """Whether a visit reason (chief complaint) can be seen in a setting."""
    where = setting.lower()
    return not any(pattern.search(reason) and any(w in where for w in settings)
                   for pattern, settings in REASON_EXCLUDED_SETTINGS)


def stressor_fits_occupation(stressor: str, occupation: str) -> bool:
    check = STRESSOR_OCCUPATION.get(stressor.lower())
    return check is None or check(occupation.lower())


# Gestational-age words and the completed days they need: ACOG Practice Bulletin 146 (2014, reaffirmed
# 2022), Management of Late-term and Postterm Pregnancies: late-term 41 0/7-41 6/7 weeks, postterm from
# 42 0/7 weeks; "post-dates" (beyond the due date, used for the late-term induction and surveillance
# ACOG PB 146 recommends from 41 0/7) is held to the late-term threshold.
GESTATION_WORDS: list[tuple[re.Pattern[str], int, str]] = [
    (re.compile(r"\bpost-?term\b", re.I), 42 * 7, "postterm (>= 42 0/7 weeks)"),
    (re.compile(r"\bpost-?dates\b|\blate-?term\b", re.I), 41 * 7, "late-term/post-dates (>= 41 0/7 weeks)"),
]

# Symptom words in a complaint and the structured symptom flag that must then be set.
SYMPTOM_WORDS: dict[str, re.Pattern[str]] = {
    "reduced_fetal_movements": re.compile(r"reduced fetal movements?", re.I),
    "vaginal_bleeding": re.compile(r"vaginal bleeding", re.I),
    "headache": re.compile(r"\bheadache\b", re.I),
    "visual_disturbance": re.compile(r"visual disturbance|blurred vision", re.I),
    "seizure": re.compile(r"\bseizure", re.I),
}

# Highest GCS total with the verbal response not testable: E4 + V"T" (charted as 1, the EHR
# convention, e.g. MIMIC-III "No Response-ETT") + M6.
GCS_MAX_INTUBATED = 11

BIRADS_SCREENING = {"0", "1", "2"}
# Average-risk screening mammography starts at 40 (ACR 2023 recommendations; USPSTF 2024: biennial 40-74).
SCREENING_FROM_AGE = 40

_FMT = "%Y-%m-%dT%H:%M"
# "a 62-year-old man": the one person a vignette ticket describes
_VIGNETTE = re.compile(r"\b(\d{1,3})-year-old (man|woman|male|female|boy|girl)\b", re.I)
_SEX_WORD = {"man": "male", "boy": "male", "male": "male", "woman": "female", "girl": "female", "female": "female"}


# -- rule machinery ---------------------------------------------------------------------------------

@dataclass
class Subject:
    """What one rule looks at: a task, the record it is about, and the database's top-level values."""

    domain: str
    task: Task
    record: dict[str, Any] | None = None
    context: dict[str, Any] = field(default_factory=dict)

    @property
    def sex(self) -> str | None:
        rec = self.record or {}
        sex = rec.get("sex") or (rec.get("patient") or {}).get("sex")
        if sex is None and self.domain == "obstetrics" and rec:
            return "female"  # an obstetric patient
        return str(sex).lower() if sex else None


@dataclass(frozen=True)
class Violation:
    domain: str
    task_id: str
    rule: str
    fields: tuple[str, ...]
    message: str

    def __str__(self) -> str:
        return f"coherence rule {self.rule!r} ({', '.join(self.fields)}): {self.message}"


Check = Callable[[Subject], Iterable[tuple[tuple[str, ...], str]]]


@dataclass(frozen=True)
class Rule:
    name: str
    relation: str          # the linked fields, in words
    source: str            # the guideline, label or convention the relation follows
    domains: tuple[str, ...] | None  # None: every domain
    check: Check


RULES: dict[str, Rule] = {}


def rule(name: str, relation: str, source: str, domains: tuple[str, ...] | None = None) -> Callable[[Check], Check]:
    def register(fn: Check) -> Check:
        if name in RULES:
            raise ValueError(f"coherence rule {name!r} is defined twice")
        RULES[name] = Rule(name, relation, source, domains, fn)
        return fn
    return register


def rules_for(domain: str) -> list[Rule]:
    return [r for r in RULES.values() if r.domains is None or domain in r.domains]


def _text(value: Any) -> str:
    return json.dumps(value, ensure_ascii=False).lower() if not isinstance(value, str) else value.lower()


def _action_args(task: Task, tool: str | None = None) -> list[dict[str, Any]]:
    return [a.arguments for a in task.evaluation_criteria.actions if tool is None or a.name == tool]


def _t(value: str) -> datetime:
    return datetime.strptime(value[:16], _FMT)


def _invasive_periods(admission: dict) -> list[tuple[datetime, datetime | None]]:
    return [(_t(v["start"]), _t(v["end"]) if v.get("end") else None)
            for v in admission.get("ventilation") or [] if v.get("mode", "invasive") == "invasive"]


def _during(at: datetime, periods: list[tuple[datetime, datetime | None]]) -> bool:
    return any(start <= at and (end is None or at < end) for start, end in periods)


# -- rules ------------------------------------------------------------------------------------------

@rule("name_matches_sex", "a patient's first name and recorded sex",
      "record consistency (no guideline): the first name is in FIRST_NAMES of the patient's sex")
def _name_matches_sex(s: Subject):
    rec = s.record or {}
    name, sex = rec.get("name"), s.sex
    # a label carrying an identifier ("Synthea person 123", "MIMIC-III subject 4711") is not a person's name
    if not name or not sex or sex not in FIRST_NAMES or any(ch.isdigit() for ch in str(name)):
        return
    first = str(name).split()[0]
    other = next((o for o in FIRST_NAMES if o != sex and first in FIRST_NAMES[o]), None)
    if other:
        yield ("name", "sex"), f"{name!r} has a {other} first name but the record's sex is {sex}"
    elif first not in FIRST_NAMES[sex]:
        yield ("name",), f"first name {first!r} is in neither list of envs.coherence.FIRST_NAMES (add it to its sex)"


def _drug_text(s: Subject) -> str:
    rec = s.record or {}
    parts: list[Any] = [rec.get(k) for k in ("medications", "prescriptions", "drug_exposures")]
    parts += [a.get("medication_orders") for a in rec.get("admissions") or []]
    meta = s.task.metadata or {}
    parts += [meta.get(k) for k in ("current", "proposed", "drugs")]
    parts += [{k: v for k, v in args.items() if "drug" in k} for args in _action_args(s.task)]
    return _text(parts)


@rule("sex_specific_drug", "the patient's sex and the drugs on the record, proposed or prescribed",
      "US prescribing information: SEX_SPECIFIC_DRUGS names the label section for each drug")
def _sex_specific_drug(s: Subject):
    sex = s.sex
    if not sex:
        return
    text = _drug_text(s)
    for drug, (only, label) in SEX_SPECIFIC_DRUGS.items():
        if only != sex and re.search(rf"\b{re.escape(drug)}\b", text):
            yield ("sex", "medications"), f"{drug} is labelled for {only} patients only ({label}); the patient is {sex}"


@rule("sex_specific_condition", "the patient's sex and the conditions, complaint and pregnancy status on the record",
      "anatomy: SEX_SPECIFIC_CONDITIONS (pregnancy and uterine/ovarian disease in women; prostate/testicular in men)")
def _sex_specific_condition(s: Subject):
    rec, sex = s.record or {}, s.sex
    if not rec:  # a vignette task: the person the ticket describes
        people = _VIGNETTE.findall(s.task.ticket or "")
        if len(people) == 1:
            sex = _SEX_WORD[people[0][1].lower()]
            for other, pattern in SEX_SPECIFIC_CONDITIONS.items():
                hit = pattern.search(s.task.ticket) if other != sex else None
                if hit:
                    yield ("ticket",), f"the ticket describes a {people[0][1]} with {hit.group(0)!r}"
        return
    if not sex or sex not in SEX_SPECIFIC_CONDITIONS:
        return
    if sex == "male" and (rec.get("pregnant") or rec.get("gestational_age_weeks")):
        yield ("sex", "pregnant"), "a male patient is recorded as pregnant"
    fields = {k: rec.get(k) for k in ("conditions", "past_medical_history", "diagnoses", "chief_complaint",
                                       "presenting_complaint") if rec.get(k)}
    fields["admission_diagnosis"] = [a.get("admission_diagnosis") for a in rec.get("admissions") or []]
    for other, pattern in SEX_SPECIFIC_CONDITIONS.items():
        if other == sex:
            continue
        for key, value in fields.items():
            hit = pattern.search(_text(value))
            if hit:
                yield ("sex", key), f"{key} names {hit.group(0)!r}, which only a {other} patient can have; the patient is {sex}"


@rule("occupation_matches_age", "the patient's age, occupation and recent stressors",
      "plausibility bounds (no guideline): OCCUPATION_AGE (retired >= 55, student <= 35) and STRESSOR_OCCUPATION")
def _occupation_matches_age(s: Subject):
    rec = s.record or {}
    age = rec.get("age")
    social = rec.get("social") if isinstance(rec.get("social"), dict) else {}
    occupation = social.get("employment") or (rec.get("social_history") if isinstance(rec.get("social_history"), str) else None)
    if not occupation or age is None:
        return
    if not occupation_fits_age(occupation, int(age)):
        yield ("age", "occupation"), f"a {age}-year-old is recorded as {occupation!r}"
    employment = social.get("employment") or ""
    for stressor in social.get("recent_stressors") or []:
        if employment and not stressor_fits_occupation(stressor, employment):
            yield ("recent_stressors", "employment"), f"stressor {stressor!r} does not fit occupation {employment!r}"


@rule("living_matches_age", "the patient's age and living arrangement",
      "plausibility bounds (no guideline): LIVING_AGE (lives with parents <= 50)")
def _living_matches_age(s: Subject):
    rec = s.record or {}
    social = rec.get("social") if isinstance(rec.get("social"), dict) else {}
    living, age = social.get("living"), rec.get("age")
    if living and age is not None and not living_fits_age(living, int(age)):
        yield ("age", "social.living"), f"a {age}-year-old is recorded as {living!r}"


@rule("visit_reason_matches_setting", "the setting of the visit and its reason (chief complaint)",
      "ESI Implementation Handbook v4 (the emergency department sees unscheduled presentations): a scheduled "
      "annual/routine review is not an emergency or inpatient visit, a medication review not an emergency one; a "
      "patient brought in by others is seen in person")
def _visit_reason_matches_setting(s: Subject):
    rec = s.record or {}
    setting, reason = rec.get("setting"), rec.get("chief_complaint")
    if isinstance(setting, str) and isinstance(reason, str) and not setting_fits_reason(setting, reason):
        yield ("setting", "chief_complaint"), f"{reason!r} is not a reason for a visit in the {setting}"


@rule("indication_matches_age", "a study's indication and the patient's age",
      "plausibility bounds (no guideline): INDICATION_AGE (pre-employment examination <= 66, the US full "
      "retirement age)")
def _indication_matches_age(s: Subject):
    rec = s.record or {}
    patient = rec.get("patient") if isinstance(rec.get("patient"), dict) else {}
    indication, age = rec.get("indication"), patient.get("age")
    if isinstance(indication, str) and isinstance(age, int | float) and not indication_fits_age(indication, int(age)):
        yield ("indication", "patient.age"), f"a {age}-year-old is imaged for {indication!r}"


@rule("post_dates_gestation", "the gestational age (from the LMP and the database's date) and the words "
      "'post-dates', 'late-term', 'post-term' in the history or complaint",
      "ACOG Practice Bulletin 146 (2014): late-term 41 0/7-41 6/7 weeks, postterm >= 42 0/7 weeks", ("obstetrics",))
def _post_dates_gestation(s: Subject):
    rec = s.record or {}
    today, lmp = s.context.get("today"), rec.get("lmp_date")
    if not today or not lmp:
        return
    days = (date.fromisoformat(today) - date.fromisoformat(lmp)).days
    text = " ".join(str(rec.get(k) or "") for k in ("history", "presenting_complaint"))
    for pattern, need, label in GESTATION_WORDS:
        hit = pattern.search(text)
        if hit:
            if days < need:
                yield (("history", "lmp_date"),
                       f"{hit.group(0)!r} needs {label} but the gestation is {days // 7}+{days % 7} weeks")
            break


@rule("complaint_matches_symptom_flags", "the presenting complaint/history and the structured symptom flags",
      "record consistency (no guideline): a symptom the complaint names is set in `symptoms`", ("obstetrics",))
def _complaint_matches_symptom_flags(s: Subject):
    rec = s.record or {}
    symptoms = rec.get("symptoms") or {}
    text = " ".join(str(rec.get(k) or "") for k in ("presenting_complaint", "history"))
    for flag, pattern in SYMPTOM_WORDS.items():
        if flag in symptoms and pattern.search(text) and not symptoms.get(flag):
            yield ("presenting_complaint", f"symptoms.{flag}"), f"the complaint/history names {flag.replace('_', ' ')} but the flag is false"
    if symptoms.get("reduced_fetal_movements") and not SYMPTOM_WORDS["reduced_fetal_movements"].search(text):
        yield (("presenting_complaint", "symptoms.reduced_fetal_movements"),
               "reduced fetal movements flagged but neither the complaint nor the history names them")


def breast_category(study: dict) -> str:
    """The BI-RADS category of a breast study's recorded findings (as the domain's calculate_birads tool reads them)."""
    from envs.calculators import CALCULATORS

    findings = study.get("findings") or []
    mass = next((f for f in findings if f.get("kind") == "breast_mass"), None)
    calc = next((f for f in findings if f.get("kind") == "breast_calcifications"), None)
    result = CALCULATORS["calculate_birads"](
        mass_shape=(mass or {}).get("mass_shape") or "none", mass_margin=(mass or {}).get("mass_margin") or "none",
        mass_typically_benign=bool(mass and mass.get("mass_typically_benign")),
        mass_stable_2_years=bool(mass and mass.get("stable_2_years")),
        calcification_morphology=(calc or {}).get("calcification_morphology") or "none",
        architectural_distortion=any(f.get("kind") == "breast_distortion" for f in findings),
        exam_complete=bool(study.get("exam_complete", True)),
        known_biopsy_proven_malignancy=bool(study.get("known_biopsy_proven_malignancy")))
    return result.category.replace("BI-RADS ", "")


@rule("breast_indication_matches_finding", "a breast study's indication, exam, prior films and the BI-RADS category "
      "of its findings",
      "ACR BI-RADS Atlas 5th ed. (2013): screening assessments are 0, 1 or 2; category 3 is for a non-palpable finding "
      "at diagnostic work-up (a palpable mass at >= 40 years gets diagnostic mammography and ultrasound, ACR "
      "Appropriateness Criteria Palpable Breast Masses 2022), category 6 for a biopsy-proven cancer; a follow-up of a "
      "prior finding needs the prior films; screening from 40 years (ACR 2023, USPSTF 2024)", ("radiology_report",))
def _breast_indication_matches_finding(s: Subject):
    study = s.record or {}
    if study.get("region") != "breast":
        return
    indication, exam = str(study.get("indication") or "").lower(), str(study.get("exam") or "").lower()
    descriptions = " ".join(str(f.get("description") or "") for f in study.get("findings") or []).lower()
    category = breast_category(study)
    has_prior = bool(study.get("prior")) or bool(re.search(r"unchanged|stable|since \d{4}", descriptions))
    if ("follow-up" in indication or "prior finding" in indication) and (not has_prior or "no prior films" in descriptions):
        yield ("indication", "prior", "findings"), f"indication {indication!r} but the study has no prior films"
    if category == "3" and "palpable" in indication:
        yield ("indication", "category"), "BI-RADS 3 (probably benign, short-interval follow-up) for a palpable mass"
    screening = "screening" in indication and "recall" not in indication
    if screening and category not in BIRADS_SCREENING:
        yield ("indication", "category"), f"a screening examination assessed BI-RADS {category} (screening allows 0, 1, 2)"
    if screening != ("screening" in exam):
        yield ("indication", "exam"), f"indication {indication!r} with exam {exam!r}"
    age = (study.get("patient") or {}).get("age")
    if "screening" in indication and age is not None and age < SCREENING_FROM_AGE:
        yield ("indication", "patient.age"), f"{indication!r} at {age} years (screening mammography starts at {SCREENING_FROM_AGE})"
    if (category == "6") != ("biopsy-proven" in indication):
        yield ("indication", "category"), f"BI-RADS {category} with indication {indication!r} (6 exactly for a biopsy-proven cancer)"


def _icu_admissions(s: Subject) -> list[dict]:
    rec = s.record or {}
    return [a for a in rec.get("admissions") or [] if a.get("vital_events") is not None]


@rule("intubated_gcs_verbal", "invasive ventilation and the charted GCS (verbal response not testable)",
      "Teasdale et al., Lancet Neurol 2014;13:844-854 and the GCS aid (glasgowcomascale.org): the verbal response of an "
      f"intubated patient is not testable ('T'); charted as 1, the total is at most {GCS_MAX_INTUBATED}",
      ("ehr_management",))
def _intubated_gcs_verbal(s: Subject):
    for adm in _icu_admissions(s):
        periods = _invasive_periods(adm)
        for v in adm.get("vital_events") or []:
            if v.get("gcs") is not None and v["gcs"] > GCS_MAX_INTUBATED and _during(_t(v["time"]), periods):
                yield (("vital_events.gcs", "ventilation"),
                       f"GCS {v['gcs']} charted at {v['time']} on invasive ventilation (verbal not testable: at most "
                       f"{GCS_MAX_INTUBATED})")


@rule("news2_not_on_ventilator", "a NEWS2 task's charted time and invasive ventilation",
      "RCP NEWS2 (2017): scores spontaneous breathing rate, SpO2 on air or oxygen and ACVPU consciousness, none "
      "assessable on invasive ventilation; a ventilated patient is monitored in critical care, not by NEWS2",
      ("ehr_management",))
def _news2_not_on_ventilator(s: Subject):
    calls = _action_args(s.task, "calculate_news2")
    if not calls:
        return
    for adm in _icu_admissions(s):
        periods = _invasive_periods(adm)
        times = sorted(v["time"] for v in adm.get("vital_events") or [])
        for args in calls:
            at = args.get("at_time")
            charted = [t for t in times if at is None or t <= at]
            if charted and _during(_t(charted[-1]), periods):
                yield ("at_time", "ventilation"), f"NEWS2 asked for the vital set at {charted[-1]}, charted on invasive ventilation"


# The GCS eye responses each ACVPU level allows: RCP NEWS2 (2017) chart 4 and its ACVPU definitions: Alert is
# fully awake with spontaneous eye opening (GCS eye 4); Voice responds (eyes, words or movement) only when
# spoken to; Pain only to a painful stimulus; Unresponsive to neither (eye 1). New confusion allows any.
AVPU_GCS_EYE: dict[str, tuple[int, ...]] = {"alert": (4,), "voice": (1, 2, 3), "pain": (1, 2), "unresponsive": (1,)}


@rule("avpu_matches_gcs_eye", "a vital set's ACVPU level and its GCS eye response",
      "RCP NEWS2 (2017), ACVPU: Alert = fully awake, eyes open spontaneously (GCS eye 4); a patient who opens the eyes "
      "only to voice or pain is V or P; Teasdale et al., Lancet Neurol 2014;13:844-854 (eye 3 = to sound)",
      ("triage_emergency",))
def _avpu_matches_gcs_eye(s: Subject):
    for v in (s.record or {}).get("vitals") or []:
        if not isinstance(v, dict) or v.get("avpu") is None or v.get("gcs_eye") is None:
            continue
        allowed = AVPU_GCS_EYE.get(str(v["avpu"]))
        if allowed is not None and int(v["gcs_eye"]) not in allowed:
            yield (("vitals.avpu", "vitals.gcs_eye"),
                   f"ACVPU {v['avpu']!r} with GCS eye {v['gcs_eye']} at {v.get('time')} (allowed: {list(allowed)})")


def _admissions_at_clock(s: Subject) -> Iterator[tuple[str, datetime, dict]]:
    """(the record clock as written, as a time, an admission) for each admission of a record that has a clock."""
    clock = s.context.get("clock")
    if not clock:
        return
    now = _t(clock)
    for adm in (s.record or {}).get("admissions") or []:
        yield clock, now, adm


@rule("order_status_matches_clock", "a medication order's status, start and stop and the record clock",
      "HL7 FHIR R4 MedicationRequest.status: 'active' while the order is in force, 'completed' once all its actions are "
      "done; an order stopped before the record clock is not active", ("ehr_management",))
def _order_status_matches_clock(s: Subject):
    for clock, now, adm in _admissions_at_clock(s):
        for m in adm.get("medication_orders") or []:
            if _t(m["start"]) > now:
                yield ("medication_orders.start", "clock"), f"order {m['order_id']} starts at {m['start']}, after the record clock {clock}"
            if m.get("status") == "active" and m.get("stop") and _t(m["stop"]) <= now:
                yield (("medication_orders.status", "medication_orders.stop", "clock"),
                       f"order {m['order_id']} is 'active' but stopped at {m['stop']}, before the record clock {clock}")


# JBDS-IP, The Management of Diabetic Ketoacidosis in Adults (revised June 2021; Dhatariya, Diabet Med 2022;39:e14788):
# DKA is bicarbonate below 15 mmol/L and/or venous pH below 7.3; the fixed-rate IV insulin infusion continues until it
# has resolved, and subcutaneous insulin is started (with a meal) before the infusion stops. A day after the charted
# resolution covers the wait for a meal and the overlap; an infusion still running then contradicts the chart.
DKA_RESOLVED_PH = 7.3
DKA_RESOLVED_BICARBONATE = 15.0
DKA_TRANSFER_WINDOW = timedelta(hours=24)


def _dka_resolved_at(adm: dict) -> datetime | None:
    """The first charted time with pH above 7.3 and bicarbonate at least 15 in a DKA admission, else None."""
    if "ketoacidosis" not in str(adm.get("admission_diagnosis", "")).lower():
        return None
    by_time: dict[str, dict[str, Any]] = {}
    for lab in adm.get("lab_events") or []:
        by_time.setdefault(lab["time"], {})[lab.get("test")] = lab.get("value")
    resolved = sorted(t for t, v in by_time.items() if (v.get("ph_arterial") or 0) > DKA_RESOLVED_PH
                      and (v.get("bicarbonate") or 0) >= DKA_RESOLVED_BICARBONATE)
    return _t(resolved[0]) if resolved else None


@rule("dka_insulin_infusion_stops_after_resolution",
      "a DKA admission's IV insulin infusion, the labs that show the ketoacidosis resolved, subcutaneous insulin and "
      "the record clock",
      "JBDS-IP DKA in adults (2021): DKA is bicarbonate < 15 mmol/L and/or venous pH < 7.3; the fixed-rate IV insulin "
      "infusion continues until DKA has resolved and stops once subcutaneous insulin has been given with a meal",
      ("ehr_management",))
def _dka_insulin_infusion(s: Subject):
    clock = s.context.get("clock")
    for adm in (s.record or {}).get("admissions") or []:
        resolved = _dka_resolved_at(adm)
        if resolved is None:
            continue
        orders = adm.get("medication_orders") or []
        subcutaneous = [_t(m["start"]) for m in orders if "insulin" in m["drug"].lower() and m.get("route") == "subcutaneous"]
        for m in orders:
            if "insulin" not in m["drug"].lower() or m.get("route") != "iv":
                continue
            stop = _t(m["stop"]) if m.get("stop") else None
            if clock and (stop is None or stop > _t(clock)) and _t(clock) - resolved > DKA_TRANSFER_WINDOW:
                yield (("medication_orders.status", "lab_events", "clock"),
                       f"order {m['order_id']} ({m['drug']}) runs at the record clock {clock}, over a day after the "
                       f"ketoacidosis resolved at {resolved:{_FMT}}")
            if stop is not None and not any(start <= stop for start in subcutaneous):
                yield (("medication_orders.stop", "medication_orders.route"),
                       f"order {m['order_id']} ({m['drug']}) stopped at {m['stop']} with no subcutaneous insulin started")


def _last_charted(adm: dict) -> datetime | None:
    """The admission's last charted observation (vital signs or a lab result), else None."""
    times = [_t(e["time"]) for key in ("vital_events", "lab_events") for e in adm.get(key) or [] if e.get("time")]
    return max(times) if times else None


# A continuous infusion is charted on the ICU flowsheet with the observations (the authored scenarios chart vital
# signs every 4 hours and labs at least daily); a one-off dose is given when it is ordered. A full day with no
# charted observation (or since a one-off dose) is more than any charting gap in the records, so an order still
# 'active' then has no administration behind it: FHIR's status would be 'completed'.
UNCHARTED_ACTIVE_WINDOW = timedelta(hours=24)


@rule("infusion_active_only_while_charted",
      "a continuous infusion's or one-off dose's status, the admission's last charted observation and the record clock",
      "HL7 FHIR R4 MedicationRequest.status: 'active' while the order is in force, 'completed' once all its actions are "
      "done; a one-off dose is done once given, an infusion once the chart stops recording it", ("ehr_management",))
def _infusion_active_only_while_charted(s: Subject):
    for clock, now, adm in _admissions_at_clock(s):
        last = _last_charted(adm)
        for m in adm.get("medication_orders") or []:
            if m.get("status") != "active" or (m.get("stop") and _t(m["stop"]) <= now):
                continue
            if m.get("frequency") == "once":
                given = _t(m["start"])
            elif m.get("frequency") == "continuous":
                given = max(last, _t(m["start"])) if last else _t(m["start"])
            else:
                continue
            if now - given > UNCHARTED_ACTIVE_WINDOW:
                what = "one-off dose given at" if m.get("frequency") == "once" else "infusion last charted at"
                yield (("medication_orders.status", "medication_orders.stop", "clock"),
                       f"order {m['order_id']} ({m['drug']}) is 'active' at the record clock {clock}, {what} "
                       f"{given:{_FMT}}, over {UNCHARTED_ACTIVE_WINDOW.total_seconds() / 3600:g} h before")


@rule("sex_factor_matches_sex", "a creatinine-clearance task's stated sex factor and the patient's sex",
      "Cockcroft & Gault, Nephron 1976;16:31-41: the 0.85 factor applies to women only")
def _sex_factor_matches_sex(s: Subject):
    sex = s.sex
    said = _text([s.task.description.key_challenges, s.task.metadata])
    if sex and sex != "female" and "female sex factor" in said:
        yield ("key_challenges", "sex"), f"the task applies the female sex factor 0.85 to a {sex} patient"




# A renal dosing task plans a drug for the patient; the generator states the reason it drew it with this prefix.
RENAL_INDICATION_PREFIX = "Indication on the record: "


@rule("renal_drug_has_indication", "a renal dosing task's planned drug and the patient's conditions or the "
      "indication of an active order for that drug",
      "each drug's US label, section 1 INDICATIONS AND USAGE (the generator's table, drug_interaction/generate.py "
      "RENAL_INDICATIONS): a drug is planned for a condition on the record, not drawn on its own",
      ("drug_interaction",))
def _renal_drug_has_indication(s: Subject):
    if s.task.description.task_type != "renal_adjustment_patient":
        return
    drug = next((a.get("drug") for a in _action_args(s.task, "get_renal_dose_adjustment") if a.get("drug")), None)
    rec = s.record or {}
    stated = next((c[len(RENAL_INDICATION_PREFIX):].rstrip(".") for c in s.task.description.key_challenges
                   if c.startswith(RENAL_INDICATION_PREFIX)), None)
    reasons = set(rec.get("conditions") or []) | {m.get("indication") for m in rec.get("medications") or []
                                                   if m.get("drug_id") == drug and m.get("status") == "active"}
    if stated is None or stated not in reasons:
        yield (("key_challenges", "conditions", "medications"),
               f"{drug} planned for {rec.get('patient_id', s.task.patient_id)} with no indication on the record "
               f"(stated: {stated!r})")


@rule("vignette_matches_arguments", "the age and sex a ticket states and the same values in the gold tool call",
      "record consistency (no guideline): the gold answer is computed from the person the ticket describes")
def _vignette_matches_arguments(s: Subject):
    people = _VIGNETTE.findall(s.task.ticket or "")
    if len(people) != 1:
        return
    age, word = int(people[0][0]), _SEX_WORD[people[0][1].lower()]
    for args in _action_args(s.task):
        if isinstance(args.get("sex"), str) and args["sex"].lower() in ("male", "female") and args["sex"].lower() != word:
            yield ("ticket", "arguments.sex"), f"the ticket describes a {people[0][1]} but the gold call uses sex={args['sex']!r}"
        if isinstance(args.get("age"), int | float) and not isinstance(args.get("age"), bool) and int(args["age"]) != age:
            yield ("ticket", "arguments.age"), f"the ticket says {age} years but the gold call uses age={args['age']}"


# -- running ----------------------------------------------------------------------------------------

def check_subject(subject: Subject, rules: Iterable[Rule] | None = None) -> list[Violation]:
    out = []
    for r in rules if rules is not None else rules_for(subject.domain):
        for fields, message in r.check(subject):
            out.append(Violation(subject.domain, subject.task.id, r.name, tuple(fields), message))
    return out


def _record_key(task: Task) -> str | None:
    if task.patient_id:
        return task.patient_id
    for args in _action_args(task):
        for key in ("patient_id", "study_id"):
            if isinstance(args.get(key), str):
                return args[key]
    return None


def load_database(domain: str) -> dict[str, Any]:
    """The domain's built `db.json` as plain JSON ({} when the domain has none)."""
    from envs.core.paths import domain_build_dir

    path: Path = domain_build_dir(domain) / "db.json"
    if not path.exists():
        return {}
    with path.open(encoding="utf-8") as fh:
        return json.load(fh)


def subjects(domain: str, tasks: Iterable[Task], db: dict[str, Any]) -> Iterable[Subject]:
    records: dict[str, Any] = {**(db.get("patients") or {}), **(db.get("studies") or {})}
    context = {k: v for k, v in db.items() if isinstance(v, str | int | float)}
    for task in tasks:
        carried = (task.metadata or {}).get("ehr_patient")
        key = _record_key(task)
        record = carried if isinstance(carried, dict) else records.get(key) if key else None
        yield Subject(domain, task, record, context)


def check_tasks(domain: str, tasks: Iterable[Task], db: dict[str, Any] | None = None) -> list[Violation]:
    """Every rule that applies to the domain over its tasks and their records. A domain whose tasks carry
    records of other domains (cross_domain's pathways) exposes `coherence_records(task) -> {domain: record}`
    in its environment module; each record is checked against the rules of its own domain."""
    from envs import registry

    tasks = list(tasks)
    db = load_database(domain) if db is None else db
    rules = rules_for(domain)
    out = [v for subject in subjects(domain, tasks, db) for v in check_subject(subject, rules)]
    carried = getattr(registry.domain_module(domain), "coherence_records", None)
    for task in tasks if carried else []:
        for inner, record in carried(task).items():
            out += check_subject(Subject(inner, task, record), rules_for(inner))
    return out
