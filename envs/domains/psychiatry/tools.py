"""Psychiatry tools: chart and interview review, validated instruments, interaction checks, and the
clinical records a psychiatrist writes (MSE, safety plan, escalation, diagnosis, labs, follow-up).

Instruments come from `envs.calculators` (the MDQ from `instruments.score_mdq`). Each accepts a
`patient_id` and fills its inputs from the completed form on file; inputs given explicitly (for
example answers taken from the interview transcript) win.
"""

from __future__ import annotations

import itertools
import re
from typing import Literal

from envs.calculators import CALCULATORS
from envs.core.common_tools import BaseDomainTools
from envs.core.tools import ToolError, ToolType, is_tool
from envs.domains.psychiatry import instruments as I
from envs.domains.psychiatry import interactions as IX
from envs.domains.psychiatry.data_model import (
    DiagnosisRecord, Escalation, FollowUp, LabOrder, MSERecord, Patient, PsychiatryDB, SafetyPlan,
)

SEVERITY_ORDER = IX.SEVERITY_ORDER
ESCALATION_LEVELS = ("emergency psychiatric evaluation", "inpatient psychiatric admission", "crisis team",
                     "1:1 constant observation", "emergency medical evaluation", "urgent outpatient psychiatry")
INSTRUMENTS = ("phq9", "gad7", "epds", "audit_c", "mdq", "cage", "cssrs", "ciwa")


def _key(text: str) -> str:
    return " ".join(re.findall(r"[a-z0-9]+", text.lower()))


class PsychiatryTools(BaseDomainTools):
    db: PsychiatryDB

    # -- helpers -------------------------------------------------------------------------------
    def _patient(self, patient_id: str) -> Patient:
        pid = (patient_id or "").strip().upper()
        if pid not in self.db.patients:
            known = sorted(self.db.patients)
            raise ToolError(f"patient {patient_id!r} not found; ids look like {known[0]} ({len(known)} patients)")
        return self.db.patients[pid]

    def _form(self, patient: Patient, instrument: str, explicit_given: bool):
        value = getattr(patient.reports, instrument)
        if value is None and not explicit_given:
            raise ToolError(f"no completed {instrument.upper()} form on file for {patient.patient_id}; take the answers "
                            f"from the interview transcript and pass them explicitly")
        return value

    def _resolve_drug(self, name: str) -> str | None:
        key = _key(name)
        for drug, rec in self.db.formulary.items():
            if key == _key(drug) or key in {_key(b) for b in rec.brands}:
                return drug
        stripped = " ".join(w for w in key.split() if w not in ("er", "xr", "sr", "cr", "carbonate", "hydrochloride",
                                                                 "sodium", "tablet", "extended", "release"))
        return stripped if stripped in self.db.formulary else None

    @staticmethod
    def _result(result) -> dict:
        return result.model_dump(mode="json")

    # -- chart and interview --------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def get_patient_summary(self, patient_id: str) -> dict:
        """Return demographics, setting, chief complaint, presenting history, medications and allergies.

        Args:
            patient_id: Patient identifier, e.g. "PSY-007".
        """
        p = self._patient(patient_id)
        return {"patient_id": p.patient_id, "name": p.name, "age": p.age, "sex": p.sex, "setting": p.setting,
                "chief_complaint": p.chief_complaint, "presenting_history": p.presenting_history,
                "pregnant": p.pregnant, "weeks_postpartum": p.weeks_postpartum,
                "medications": [m.model_dump() for m in p.medications], "allergies": p.allergies or ["no known drug allergies"],
                "forms_on_file": [i for i in INSTRUMENTS if getattr(p.reports, i) is not None],
                "interview_available": bool(p.transcript)}

    @is_tool(ToolType.READ)
    def get_psychiatric_history(self, patient_id: str) -> dict:
        """Return past psychiatric diagnoses, admissions, suicide attempts, self-harm, family, substance and social history.

        Args:
            patient_id: Patient identifier.
        """
        p = self._patient(patient_id)
        return {"patient_id": p.patient_id, **p.history.model_dump(), "social": p.social.model_dump()}

    @is_tool(ToolType.READ)
    def get_interview_transcript(self, patient_id: str, contains: str | None = None) -> dict:
        """Return today's interview transcript, optionally only the exchanges containing a word.

        Args:
            patient_id: Patient identifier.
            contains: Optional word or phrase; only utterances containing it (and the answer that
                follows a matching question) are returned.
        """
        p = self._patient(patient_id)
        if not p.transcript:
            raise ToolError(f"no interview transcript for {p.patient_id}; see get_symptom_report for completed forms")
        lines = [{"turn": i + 1, "speaker": u.speaker, "text": u.text} for i, u in enumerate(p.transcript)]
        if contains:
            needle = contains.lower()
            keep = set()
            for i, u in enumerate(p.transcript):
                if needle in u.text.lower():
                    keep.add(i)
                    if u.speaker == "clinician" and i + 1 < len(p.transcript):
                        keep.add(i + 1)
            lines = [lines[i] for i in sorted(keep)]
        return {"patient_id": p.patient_id, "utterances": lines, "total_turns": len(p.transcript)}

    @is_tool(ToolType.READ)
    def get_symptom_report(self, patient_id: str, instrument: Literal["phq9", "gad7", "epds", "audit_c", "mdq", "cage", "cssrs", "ciwa"]) -> dict:
        """Return a completed questionnaire or observation form on file, item by item with the recorded answer.

        Args:
            patient_id: Patient identifier.
            instrument: Which form: phq9, gad7, epds, audit_c, mdq, cage, cssrs or ciwa.
        """
        p = self._patient(patient_id)
        form = getattr(p.reports, instrument)
        if form is None:
            have = [i for i in INSTRUMENTS if getattr(p.reports, i) is not None]
            raise ToolError(f"no {instrument} form on file for {p.patient_id}; forms on file: {have or 'none'}")
        if instrument in ("phq9", "gad7"):
            labels = I.PHQ9_ITEMS if instrument == "phq9" else I.GAD7_ITEMS
            items = [{"item": k + 1, "text": labels[k], "answer": I.FREQUENCY[v], "score": v} for k, v in enumerate(form)]
        elif instrument == "epds":
            items = [{"item": k + 1, "text": I.EPDS_ITEMS[k], "score": v} for k, v in enumerate(form)]
        elif instrument == "audit_c":
            items = [{"item": k + 1, "text": q, "answer": opts[v], "score": v} for k, ((q, opts), v) in enumerate(zip(I.AUDIT_C_ITEMS, form))]
        elif instrument == "mdq":
            items = [{"item": k + 1, "text": I.MDQ_ITEMS[k], "answer": "yes" if v else "no"} for k, v in enumerate(form.items)]
            items.append({"item": "2", "text": "several of these during the same period", "answer": "yes" if form.same_period else "no"})
            items.append({"item": "3", "text": "how much of a problem", "answer": form.problem_level})
        else:
            items = [{"item": k, "answer": v} for k, v in form.model_dump().items()]
        return {"patient_id": p.patient_id, "instrument": instrument, "items": items}

    @is_tool(ToolType.READ)
    def get_lab_results(self, patient_id: str) -> dict:
        """Return resulted laboratory tests (including tests ordered this episode) flagged against their reference ranges.

        Args:
            patient_id: Patient identifier.
        """
        p = self._patient(patient_id)
        results = list(p.labs) + [p.orderable_results[o.test] for o in self.db.lab_orders
                                  if o.patient_id == p.patient_id and o.status == "resulted"]
        out = []
        for lab in results:
            flag = "normal"
            if lab.ref_high is not None and lab.value > lab.ref_high:
                flag = "high"
            elif lab.ref_low is not None and lab.value < lab.ref_low:
                flag = "low"
            out.append({**lab.model_dump(), "flag": flag})
        return {"patient_id": p.patient_id, "results": out}

    # -- instruments -----------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def administer_phq9(self, patient_id: str | None = None, responses: list[int] | None = None) -> dict:
        """Score the PHQ-9 (0-27) with severity band; item 9 (thoughts of death or self-harm) is flagged.

        Args:
            patient_id: Patient whose completed PHQ-9 on file is scored when responses are not given.
            responses: The nine item scores 0-3 in form order (explicit answers win over the form on file).
        """
        if responses is None:
            if patient_id is None:
                raise ToolError("give 'responses' (nine scores 0-3) or a 'patient_id' with a PHQ-9 on file")
            responses = self._form(self._patient(patient_id), "phq9", False)
        return self._result(CALCULATORS["administer_phq9"](responses=responses))

    @is_tool(ToolType.READ)
    def administer_gad7(self, patient_id: str | None = None, responses: list[int] | None = None) -> dict:
        """Score the GAD-7 (0-21) with severity band.

        Args:
            patient_id: Patient whose completed GAD-7 on file is scored when responses are not given.
            responses: The seven item scores 0-3 in form order (explicit answers win).
        """
        if responses is None:
            if patient_id is None:
                raise ToolError("give 'responses' (seven scores 0-3) or a 'patient_id' with a GAD-7 on file")
            responses = self._form(self._patient(patient_id), "gad7", False)
        return self._result(CALCULATORS["administer_gad7"](responses=responses))

    @is_tool(ToolType.READ)
    def administer_epds(self, patient_id: str | None = None, responses: list[int] | None = None) -> dict:
        """Score the Edinburgh Postnatal Depression Scale (0-30); item 10 (self-harm thoughts) is flagged.

        Args:
            patient_id: Patient whose completed EPDS on file is scored when responses are not given.
            responses: The ten scored item values 0-3 in form order (explicit answers win).
        """
        if responses is None:
            if patient_id is None:
                raise ToolError("give 'responses' (ten scores 0-3) or a 'patient_id' with an EPDS on file")
            responses = self._form(self._patient(patient_id), "epds", False)
        return self._result(CALCULATORS["administer_epds"](responses=responses))

    @is_tool(ToolType.READ)
    def administer_audit_c(self, patient_id: str | None = None, responses: list[int] | None = None,
                           sex: Literal["male", "female"] | None = None) -> dict:
        """Score the AUDIT-C alcohol screen (0-12) with the sex-specific threshold (men >= 4, women >= 3).

        Args:
            patient_id: Patient whose AUDIT-C on file (and recorded sex) are used for missing inputs.
            responses: The three item scores 0-4 (explicit answers win).
            sex: "male" or "female" (explicit value wins over the chart).
        """
        patient = self._patient(patient_id) if patient_id else None
        if responses is None:
            if patient is None:
                raise ToolError("give 'responses' (three scores 0-4) or a 'patient_id' with an AUDIT-C on file")
            responses = self._form(patient, "audit_c", False)
        if sex is None:
            if patient is None:
                raise ToolError("give 'sex' or a 'patient_id'")
            sex = patient.sex
        return self._result(CALCULATORS["administer_audit_c"](responses=responses, sex=sex))

    @is_tool(ToolType.READ)
    def administer_cage(self, patient_id: str | None = None, cut_down: bool | None = None, annoyed: bool | None = None,
                        guilty: bool | None = None, eye_opener: bool | None = None) -> dict:
        """Score the CAGE alcohol questionnaire (0-4; >= 2 clinically significant).

        Args:
            patient_id: Patient whose CAGE answers on file fill any answer not given.
            cut_down: Felt you should cut down on drinking.
            annoyed: Annoyed by criticism of your drinking.
            guilty: Felt guilty about drinking.
            eye_opener: Drink first thing in the morning.
        """
        given = {"cut_down": cut_down, "annoyed": annoyed, "guilty": guilty, "eye_opener": eye_opener}
        if any(v is None for v in given.values()):
            if patient_id is None:
                raise ToolError("give all four answers or a 'patient_id' with a CAGE on file")
            form = self._form(self._patient(patient_id), "cage", False).model_dump()
            given = {k: (v if v is not None else form[k]) for k, v in given.items()}
        return self._result(CALCULATORS["administer_cage"](**given))

    @is_tool(ToolType.READ)
    def assess_suicide_risk(self, patient_id: str | None = None, wish_to_be_dead: bool | None = None,
                            suicidal_thoughts: bool | None = None, thoughts_with_method: bool | None = None,
                            intent: bool | None = None, plan_with_intent: bool | None = None,
                            suicidal_behavior: Literal["never", "over_3_months_ago", "past_3_months"] | None = None) -> dict:
        """C-SSRS screener triage (none, low, moderate, high risk) from the six screener answers.

        Args:
            patient_id: Patient whose C-SSRS answers on file fill any answer not given.
            wish_to_be_dead: Q1, past month: wished to be dead or not wake up.
            suicidal_thoughts: Q2, past month: thoughts of killing yourself.
            thoughts_with_method: Q3: thought about how (only when Q2 is yes).
            intent: Q4: some intention of acting on the thoughts.
            plan_with_intent: Q5: worked out details of a plan and intends to carry it out.
            suicidal_behavior: Q6: "never", "over_3_months_ago" or "past_3_months".
        """
        given = {"wish_to_be_dead": wish_to_be_dead, "suicidal_thoughts": suicidal_thoughts,
                 "thoughts_with_method": thoughts_with_method, "intent": intent, "plan_with_intent": plan_with_intent,
                 "suicidal_behavior": suicidal_behavior}
        if given["wish_to_be_dead"] is None or given["suicidal_thoughts"] is None:
            if patient_id is None:
                raise ToolError("give at least 'wish_to_be_dead' and 'suicidal_thoughts', or a 'patient_id' with a C-SSRS on file")
            form = self._form(self._patient(patient_id), "cssrs", False).model_dump()
            given = {k: (v if v is not None else form[k]) for k, v in given.items()}
        given = {k: v for k, v in given.items() if v is not None}
        return self._result(CALCULATORS["assess_suicide_risk"](**given))

    @is_tool(ToolType.READ)
    def screen_bipolar(self, patient_id: str | None = None, items: list[bool] | None = None,
                       same_period: bool | None = None,
                       problem_level: Literal["no problem", "minor problem", "moderate problem", "serious problem"] | None = None) -> dict:
        """Mood Disorder Questionnaire (MDQ) bipolar screen: positive with >= 7 of 13 items, same period, moderate/serious problem.

        Args:
            patient_id: Patient whose MDQ on file fills any input not given.
            items: The 13 yes/no answers of question 1 in form order.
            same_period: Question 2: several symptoms during the same period.
            problem_level: Question 3: "no problem", "minor problem", "moderate problem" or "serious problem".
        """
        if items is None or same_period is None or problem_level is None:
            if patient_id is None:
                raise ToolError("give 'items', 'same_period' and 'problem_level', or a 'patient_id' with an MDQ on file")
            form = self._form(self._patient(patient_id), "mdq", False)
            items = form.items if items is None else items
            same_period = form.same_period if same_period is None else same_period
            problem_level = form.problem_level if problem_level is None else problem_level
        return self._result(I.score_mdq(items, same_period, problem_level))

    @is_tool(ToolType.READ)
    def calculate_ciwa_ar(self, patient_id: str | None = None, nausea_vomiting: int | None = None, tremor: int | None = None,
                          paroxysmal_sweats: int | None = None, anxiety: int | None = None, agitation: int | None = None,
                          tactile_disturbances: int | None = None, auditory_disturbances: int | None = None,
                          visual_disturbances: int | None = None, headache: int | None = None,
                          orientation: int | None = None) -> dict:
        """CIWA-Ar alcohol-withdrawal severity (0-67) from the ten observed items.

        Args:
            patient_id: Patient whose latest CIWA-Ar observation on file fills any item not given.
            nausea_vomiting: 0-7.
            tremor: 0-7.
            paroxysmal_sweats: 0-7.
            anxiety: 0-7.
            agitation: 0-7.
            tactile_disturbances: 0-7.
            auditory_disturbances: 0-7.
            visual_disturbances: 0-7.
            headache: 0-7.
            orientation: 0-4.
        """
        given = {"nausea_vomiting": nausea_vomiting, "tremor": tremor, "paroxysmal_sweats": paroxysmal_sweats,
                 "anxiety": anxiety, "agitation": agitation, "tactile_disturbances": tactile_disturbances,
                 "auditory_disturbances": auditory_disturbances, "visual_disturbances": visual_disturbances,
                 "headache": headache, "orientation": orientation}
        if any(v is None for v in given.values()):
            if patient_id is None:
                raise ToolError("give all ten CIWA-Ar items or a 'patient_id' with a CIWA-Ar observation on file")
            form = self._form(self._patient(patient_id), "ciwa", False).model_dump()
            given = {k: (v if v is not None else form[k]) for k, v in given.items()}
        return self._result(CALCULATORS["calculate_ciwa_ar"](**given))

    # -- medications -----------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def check_psych_med_interactions(self, patient_id: str | None = None, medications: list[str] | None = None,
                                     proposed_drug: str | None = None) -> dict:
        """Check psychotropic interactions (serotonin syndrome, lithium toxicity, QT, CNS depression, ...) among drugs.

        A pair the drug_interaction reference grades (US label overlay, else ANSM thesaurus) gets that grade;
        other pairs get the psychiatry rules (PIR-xx) between the drugs' groups.

        Args:
            patient_id: Patient whose current medications are included.
            medications: Drug names (generic or brand) to check; added to the patient's list if both are given.
            proposed_drug: A drug being considered; every interaction it would create is reported.
        """
        names: list[str] = []
        if patient_id:
            names += [m.name for m in self._patient(patient_id).medications]
        names += medications or []
        if proposed_drug:
            names.append(proposed_drug)
        if len(names) < 2:
            raise ToolError("need at least two drugs: give a 'patient_id' with medications, 'medications', and/or 'proposed_drug'")
        resolved: dict[str, str] = {}
        unknown: list[str] = []
        for n in names:
            drug = self._resolve_drug(n)
            if drug is None:
                unknown.append(n)
            else:
                resolved.setdefault(drug, n)
        proposed = self._resolve_drug(proposed_drug) if proposed_drug else None
        if proposed_drug and proposed is None:
            raise ToolError(f"proposed_drug {proposed_drug!r} is not in the psychiatry formulary")
        groups = {name: drug.groups for name, drug in self.db.formulary.items()}
        label_pairs = IX.label_index(self.db.label_graded_pairs)
        found = []
        for a, b in itertools.combinations(sorted(resolved), 2):
            if proposed and proposed not in (a, b):
                continue
            found += IX.pair_findings(a, b, groups, self.db.interaction_rules, label_pairs)
        worst = max((SEVERITY_ORDER[f["severity"]] for f in found), default=0)
        return {"checked": sorted(resolved), "proposed_drug": proposed, "not_in_formulary": unknown,
                "interactions": found, "highest_severity": next(k for k, v in SEVERITY_ORDER.items() if v == worst)}

    # -- records (WRITE) ------------------------------------------------------------------------
    @is_tool(ToolType.WRITE)
    def mental_status_exam(self, patient_id: str, appearance: str, behavior: str, speech: str, mood: str,
                           affect: Literal["euthymic", "constricted", "blunted", "flat", "labile", "anxious", "dysphoric", "euphoric", "irritable"],
                           thought_process: Literal["linear", "circumstantial", "tangential", "flight of ideas", "loose associations", "thought blocking"],
                           thought_content: str, suicidal_ideation: bool, homicidal_ideation: bool, perception: str,
                           cognition: str, insight: Literal["good", "fair", "limited", "poor", "absent"],
                           judgment: Literal["good", "fair", "limited", "poor"]) -> dict:
        """Record a structured mental status examination in the chart; risk flags are derived from the entries.

        Args:
            patient_id: Patient identifier.
            appearance: Appearance and grooming.
            behavior: Behaviour, eye contact, psychomotor activity.
            speech: Rate, volume, rhythm.
            mood: The patient's stated mood, in their words.
            affect: Observed affect.
            thought_process: Form of thought.
            thought_content: Content (preoccupations, delusions, obsessions); "unremarkable" if none.
            suicidal_ideation: Suicidal ideation present today.
            homicidal_ideation: Homicidal ideation present today.
            perception: Hallucinations or "no perceptual disturbance".
            cognition: Orientation, attention, memory.
            insight: Insight.
            judgment: Judgment.
        """
        p = self._patient(patient_id)
        for name, value in (("appearance", appearance), ("behavior", behavior), ("speech", speech), ("mood", mood),
                            ("thought_content", thought_content), ("perception", perception), ("cognition", cognition)):
            if not value.strip():
                raise ToolError(f"argument {name!r} is empty: describe the finding (or 'unremarkable')")
        flags = []
        if suicidal_ideation:
            flags.append("suicidal ideation: complete C-SSRS and safety assessment")
        if homicidal_ideation:
            flags.append("homicidal ideation: assess target, plan, duty to protect")
        if re.search(r"hallucinat|voices|visual (?:phenomena|disturbance)", perception, re.I) and not re.search(r"\bno\b|denies|without", perception, re.I):
            flags.append("perceptual disturbance")
        if thought_process in ("flight of ideas", "loose associations", "thought blocking"):
            flags.append(f"formal thought disorder ({thought_process})")
        if re.search(r"disorient|confus|inattent", cognition, re.I):
            flags.append("cognitive impairment: consider delirium or intoxication")
        if insight in ("poor", "absent") or judgment == "poor":
            flags.append("impaired insight/judgment: capacity and safety need review")
        record = MSERecord(patient_id=p.patient_id, appearance=appearance.strip(), behavior=behavior.strip(),
                           speech=speech.strip(), mood=mood.strip(), affect=affect, thought_process=thought_process,
                           thought_content=thought_content.strip(), suicidal_ideation=suicidal_ideation,
                           homicidal_ideation=homicidal_ideation, perception=perception.strip(), cognition=cognition.strip(),
                           insight=insight, judgment=judgment, risk_flags=flags)
        self.db.mse_records.append(record)
        return {"recorded": True, "patient_id": p.patient_id, "risk_flags": flags, "mse_count": len(self.db.mse_records)}

    @is_tool(ToolType.WRITE)
    def create_safety_plan(self, patient_id: str, warning_signs: list[str], coping_strategies: list[str],
                           social_contacts: list[str], professional_contacts: list[str], means_restriction: str,
                           crisis_line: str = "988 Suicide & Crisis Lifeline", reasons_for_living: list[str] | None = None) -> dict:
        """Record a Stanley-Brown safety plan; every core section must be filled.

        Args:
            patient_id: Patient identifier.
            warning_signs: Personal warning signs of a crisis.
            coping_strategies: Internal coping strategies.
            social_contacts: People and places that provide distraction or help.
            professional_contacts: Clinicians or services to contact.
            means_restriction: How access to lethal means (firearms, medication stock) is limited.
            crisis_line: Crisis line to call.
            reasons_for_living: Optional reasons for living in the patient's words.
        """
        p = self._patient(patient_id)
        for name, value in (("warning_signs", warning_signs), ("coping_strategies", coping_strategies),
                            ("social_contacts", social_contacts), ("professional_contacts", professional_contacts)):
            if not [v for v in value if v.strip()]:
                raise ToolError(f"argument {name!r} is empty: a safety plan needs at least one entry in every section")
        if not means_restriction.strip():
            raise ToolError("argument 'means_restriction' is empty: state how lethal means are restricted")
        warnings = []
        if p.social.firearms_access and "firearm" not in means_restriction.lower() and "gun" not in means_restriction.lower():
            warnings.append("the patient has firearm access; the means-restriction step does not mention firearms")
        self.db.safety_plans.append(SafetyPlan(patient_id=p.patient_id, warning_signs=warning_signs,
                                               coping_strategies=coping_strategies, social_contacts=social_contacts,
                                               professional_contacts=professional_contacts, crisis_line=crisis_line,
                                               means_restriction=means_restriction, reasons_for_living=reasons_for_living or []))
        return {"recorded": True, "patient_id": p.patient_id, "warnings": warnings}

    @is_tool(ToolType.WRITE)
    def escalate_care(self, patient_id: str,
                      level: Literal["emergency psychiatric evaluation", "inpatient psychiatric admission", "crisis team",
                                     "1:1 constant observation", "emergency medical evaluation", "urgent outpatient psychiatry"],
                      reason: str) -> dict:
        """Escalate care for a patient at risk (psychiatric or medical emergency evaluation, admission, crisis team, 1:1, urgent review).

        Args:
            patient_id: Patient identifier.
            level: The level of care requested.
            reason: The clinical reason, e.g. the C-SSRS result.
        """
        p = self._patient(patient_id)
        if not reason.strip():
            raise ToolError("argument 'reason' is empty: state why care is escalated")
        self.db.escalations.append(Escalation(patient_id=p.patient_id, level=level, reason=reason.strip()))
        return {"escalated": True, "patient_id": p.patient_id, "level": level,
                "instruction": "do not leave the patient alone until the receiving team takes over"
                if level in ESCALATION_LEVELS[:5] else "urgent review booked"}

    @is_tool(ToolType.WRITE)
    def record_diagnosis(self, patient_id: str, icd10_code: str) -> dict:
        """Record a working diagnosis as a billable ICD-10-CM chapter 5 (mental and behavioural) code.

        Args:
            patient_id: Patient identifier.
            icd10_code: ICD-10-CM code, e.g. "F32.1".
        """
        p = self._patient(patient_id)
        code = icd10_code.strip().upper()
        if code not in self.db.icd10_mental:
            near = sorted(c for c in self.db.icd10_mental if c.startswith(code[:3]))[:10]
            raise ToolError(f"{icd10_code!r} is not a billable ICD-10-CM chapter 5 code" +
                            (f"; codes in {code[:3]}: {', '.join(near)}" if near else ""))
        self.db.diagnoses.append(DiagnosisRecord(patient_id=p.patient_id, icd10_code=code, description=self.db.icd10_mental[code]))
        return {"recorded": True, "patient_id": p.patient_id, "icd10_code": code, "description": self.db.icd10_mental[code]}

    @is_tool(ToolType.WRITE)
    def order_lab(self, patient_id: str, test: str) -> dict:
        """Order a laboratory test (e.g. lithium level, TSH, CBC); an available result appears in get_lab_results.

        Args:
            patient_id: Patient identifier.
            test: Test name, e.g. "lithium level".
        """
        p = self._patient(patient_id)
        key = _key(test)
        match = next((name for name in p.orderable_results if _key(name) == key), None)
        status = "resulted" if match else "not available"
        self.db.lab_orders.append(LabOrder(patient_id=p.patient_id, test=match or test.strip(), status=status))
        return {"ordered": test, "patient_id": p.patient_id, "status": status,
                "note": "result available in get_lab_results" if match else "no result will be available in this episode"}

    @is_tool(ToolType.WRITE)
    def schedule_follow_up(self, patient_id: str, within_days: int, with_whom: str, purpose: str) -> dict:
        """Book a follow-up appointment.

        Args:
            patient_id: Patient identifier.
            within_days: Days until the appointment, 0-90.
            with_whom: Clinician or service, e.g. "outpatient psychiatrist".
            purpose: What the visit is for.
        """
        p = self._patient(patient_id)
        if not 0 <= within_days <= 90:
            raise ToolError("argument 'within_days' must be between 0 and 90")
        self.db.follow_ups.append(FollowUp(patient_id=p.patient_id, within_days=within_days, with_whom=with_whom.strip(),
                                           purpose=purpose.strip()))
        return {"booked": True, "patient_id": p.patient_id, "within_days": within_days}
