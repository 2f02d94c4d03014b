"""The EHR domain's generated tasks, with exact oracles: `generate(db, scenarios, icd)` returns them by group.

- ICU-record tasks over the authored ICU patients (`icu_tasks`): lab trends, SOFA per ICU day, APACHE II,
  NEWS2 at a charted time, admission ICD-10-CM coding, vasopressor hours; the oracle is the tool's result
  on a fresh copy of the patient's chart.
- The authored order-management workflows (`authored/workflows.json`, `workflow_tasks`), with the final
  database hash of a gold replay where every write is determined.
- Questions over the Synthea timelines (`timeline_tasks`), below.

Each timeline generator picks a patient and a question deterministically (sorted candidates, seeded RNG,
no patient used twice), states the gold tool call, runs it on that patient's built record and reads
the gold answer from the result, so the oracle is exactly what the tool returns to the agent:

| kind | question | tool | answer |
|---|---|---|---|
| condition_count | distinct conditions with onset in a window | get_condition_history | numeric, exact |
| first_diagnosis | date a (recurrent) condition was first recorded | get_condition_history | date |
| active_med_count | distinct ingredients active on a date | get_medications_on_date | numeric, exact |
| active_med_choice | which drug was active on a date (3 drugs of the record that were not) | get_medications_on_date | option |
| exposure_count | exposures to an ingredient in a window | get_drug_exposures | numeric, exact |
| visit_count / inpatient_days | inpatient visits in a window / total length of stay | get_visit_history | numeric, exact |
| procedure_count / last_procedure | procedures of a kind in a window / most recent date | get_procedure_history | numeric / date |
| measurement_count | how often a measurement was taken in a year (no values exist) | get_measurement_history | numeric, exact |
"""

from __future__ import annotations

import json
import random
from collections import Counter
from datetime import date, timedelta
from pathlib import Path
from typing import Callable

from envs.core.icd10 import ICD10Index
from envs.core.task import Task

from .data_model import EHRDB, EHRPatient

AUTHORED = Path(__file__).parent / "authored"
LETTERS = "ABCD"
ICU_LETTERS = "ABCDE"
COUNTS = {"condition_count": 60, "first_diagnosis": 60, "active_med_count": 30, "active_med_choice": 30,
          "exposure_count": 30, "visits": 40, "procedures": 40, "measurement_count": 20}
MONTHS = ("January", "February", "March", "April", "May", "June", "July", "August", "September", "October",
          "November", "December")


def _tools(patient: EHRPatient, clock: str):
    from .tools import EHRTools

    return EHRTools(EHRDB(patients={patient.patient_id: patient}, clock=clock))


def _act(name: str, args: dict, compare: list[str]) -> dict:
    return {"action_id": name, "name": name, "arguments": args, "compare_args": compare}


def date_aliases(day: str) -> list[str]:
    d = date.fromisoformat(day)
    return [f"{MONTHS[d.month - 1]} {d.day}, {d.year}", f"{d.day} {MONTHS[d.month - 1]} {d.year}"]


def _task(tid: str, kind: str, pid: str, ticket: str, answer: str, answer_type: str, action: dict,
          provenance: dict[str, str], **extra) -> Task:
    if answer_type == "numeric":
        extra.setdefault("answer_tolerance", 0.0)
    return Task(id=tid, ticket=ticket, correct_answer=answer, answer_type=answer_type, patient_id=pid,
                description={"purpose": f"longitudinal record: {kind.replace('_', ' ')}", "difficulty": "medium",
                             "source": "synthea_omop", "category": "ehr_timeline", "task_type": f"timeline_{kind}",
                             "provenance": {**provenance, "oracle": action["name"],
                                            "guideline": "OMOP CDM v5.4 record conventions (OHDSI); counts and dates computed from the "
                                                         "Synthea-generated record"}},
                evaluation_criteria={"actions": [action], "reward_basis": ["ACTION", "ANSWER"]}, **extra)


def _provenance(p: EHRPatient) -> dict[str, str]:
    keep = ("package", "version", "license", "dataset", "person_id")
    return {k: v for k, v in p.provenance.items() if k in keep}


def timeline_tasks(patients: list[EHRPatient], clock: str, seed: int = 71,
                   counts: dict[str, int] | None = None) -> dict[str, list[Task]]:
    rng = random.Random(seed)
    counts = counts or COUNTS
    pool = sorted(patients, key=lambda p: p.patient_id)
    used: set[str] = set()
    all_ingredients = sorted({i for p in pool for x in p.drug_exposures if x.vocabulary != "CVX" for i in x.ingredients})
    groups: dict[str, list[Task]] = {}

    def pick(kind: str, eligible: Callable[[EHRPatient], bool], make: Callable[[EHRPatient], Task | None]) -> None:
        candidates = [p for p in pool if p.patient_id not in used and eligible(p)]
        rng.shuffle(candidates)
        out: list[Task] = []
        for p in candidates:
            if len(out) >= counts.get(kind, 0):
                break
            task = make(p)
            if task is not None:
                out.append(task)
                used.add(p.patient_id)
        groups[kind] = out

    def condition_count(p: EHRPatient) -> Task | None:
        onsets = sorted({c.start[:10] for c in p.conditions})
        kit = _tools(p, clock)
        for _ in range(6):  # prefer a window with more than one condition
            year = int(rng.choice(onsets[1:])[:4])
            span = rng.choice([2, 3, 5, 10, 15])
            start, end = f"{year - span + 1:04d}-01-01", f"{year:04d}-12-31"
            out = kit.get_condition_history(p.patient_id, start, end)
            if out["distinct_conditions"] >= 2:
                break
        return _task(f"ehr_syn_condcount_{p.patient_id}", "condition_count", p.patient_id,
                     f"In patient {p.patient_id}'s longitudinal record, how many distinct conditions had an onset "
                     f"(condition start date) between {start} and {end} inclusive? Count a condition once even if it "
                     f"was recorded several times.", str(out["distinct_conditions"]), "numeric",
                     _act("get_condition_history", {"patient_id": p.patient_id, "start_date": start, "end_date": end},
                          ["patient_id", "start_date", "end_date"]), _provenance(p), answer_unit="conditions")

    def first_diagnosis(p: EHRPatient) -> Task | None:
        by_name = Counter(c.name for c in p.conditions)
        recurrent = sorted(n for n, k in by_name.items() if k >= 2)
        name = rng.choice(recurrent)
        out = _tools(p, clock).get_condition_history(p.patient_id)
        first = next(c["first_onset"] for c in out["conditions"] if c["name"] == name)
        return _task(f"ehr_syn_firstdx_{p.patient_id}", "first_diagnosis", p.patient_id,
                     f"Patient {p.patient_id}'s record has several occurrences of \"{name}\". On what date was it first "
                     f"recorded? Answer with the date as YYYY-MM-DD.", first, "exact",
                     _act("get_condition_history", {"patient_id": p.patient_id}, ["patient_id"]), _provenance(p),
                     answer_aliases=date_aliases(first))

    def _active_day(p: EHRPatient) -> str | None:
        """A day inside a drug exposure of 7+ days, preferring one with 2+ active ingredients."""
        longer = [x for x in p.drug_exposures if x.vocabulary != "CVX" and x.end
                  and (date.fromisoformat(x.end[:10]) - date.fromisoformat(x.start[:10])).days >= 7]
        if not longer:
            return None
        kit = _tools(p, clock)
        for _ in range(8):
            x = rng.choice(longer)
            span = (date.fromisoformat(x.end[:10]) - date.fromisoformat(x.start[:10])).days
            day = (date.fromisoformat(x.start[:10]) + timedelta(days=rng.randint(0, span))).isoformat()
            if kit.get_medications_on_date(p.patient_id, day)["n_active_ingredients"] >= 2:
                break
        return day

    def active_med_count(p: EHRPatient) -> Task | None:
        day = _active_day(p)
        if day is None:
            return None
        out = _tools(p, clock).get_medications_on_date(p.patient_id, day)
        return _task(f"ehr_syn_medcount_{p.patient_id}", "active_med_count", p.patient_id,
                     f"On {day}, how many distinct drug ingredients was patient {p.patient_id} exposed to (drug "
                     f"exposures active that day: start <= date <= end; vaccines excluded)?",
                     str(out["n_active_ingredients"]), "numeric",
                     _act("get_medications_on_date", {"patient_id": p.patient_id, "date": day}, ["patient_id", "date"]),
                     _provenance(p), answer_unit="ingredients")

    def active_med_choice(p: EHRPatient) -> Task | None:
        day = _active_day(p)
        if day is None:
            return None
        out = _tools(p, clock).get_medications_on_date(p.patient_id, day)
        active = out["active_ingredients"]
        own = sorted({i for x in p.drug_exposures if x.vocabulary != "CVX" for i in x.ingredients} - set(active))
        others = sorted(set(all_ingredients) - set(active) - set(own))
        distractors = rng.sample(own, min(3, len(own)))
        distractors += rng.sample(others, 3 - len(distractors))
        correct = rng.choice(active)
        options = distractors + [correct]
        rng.shuffle(options)
        letters = {LETTERS[i]: o for i, o in enumerate(options)}
        answer = LETTERS[options.index(correct)]
        return _task(f"ehr_syn_medchoice_{p.patient_id}", "active_med_choice", p.patient_id,
                     f"Which of these drugs was patient {p.patient_id} taking on {day} (a drug exposure active that "
                     f"day)? Answer with the option letter.", answer, "choice",
                     _act("get_medications_on_date", {"patient_id": p.patient_id, "date": day}, ["patient_id", "date"]),
                     _provenance(p), options=letters)

    def exposure_count(p: EHRPatient) -> Task | None:
        counted = Counter(i for x in p.drug_exposures if x.vocabulary != "CVX" for i in x.ingredients)
        repeated = sorted(i for i, k in counted.items() if k >= 3)
        if not repeated:
            return None
        ingredient = rng.choice(repeated)
        starts = sorted(x.start[:10] for x in p.drug_exposures if ingredient in x.ingredients)
        start = f"{starts[0][:4]}-01-01"
        end = f"{rng.choice(starts[1:])[:4]}-12-31"
        out = _tools(p, clock).get_drug_exposures(p.patient_id, start, end, ingredient)
        return _task(f"ehr_syn_exposures_{p.patient_id}", "exposure_count", p.patient_id,
                     f"How many separate drug exposures containing {ingredient} were recorded for patient "
                     f"{p.patient_id} with a start date between {start} and {end} inclusive?",
                     str(out["n_exposures"]), "numeric",
                     _act("get_drug_exposures", {"patient_id": p.patient_id, "start_date": start, "end_date": end,
                                                 "ingredient": ingredient}, ["patient_id", "ingredient"]),
                     _provenance(p), answer_unit="exposures")

    def visits(p: EHRPatient) -> Task | None:
        kit = _tools(p, clock)
        if rng.random() < 0.5:
            first = p.visits[0].start[:10]
            start = f"{int(first[:4]) - rng.randint(0, 3):04d}-01-01"
            end = f"{int(rng.choice(p.visits).start[:4]) + rng.randint(0, 3):04d}-12-31"
            out = kit.get_visit_history(p.patient_id, start, end)
            return _task(f"ehr_syn_visits_{p.patient_id}", "visit_count", p.patient_id,
                         f"How many inpatient visits did patient {p.patient_id} have with an admission date between "
                         f"{start} and {end} inclusive?", str(out["n_visits"]), "numeric",
                         _act("get_visit_history", {"patient_id": p.patient_id, "start_date": start, "end_date": end},
                              ["patient_id", "start_date", "end_date"]), _provenance(p), answer_unit="visits")
        out = kit.get_visit_history(p.patient_id)
        return _task(f"ehr_syn_inpatient_days_{p.patient_id}", "inpatient_days", p.patient_id,
                     f"Over patient {p.patient_id}'s whole record, how many inpatient days in total (the sum over "
                     f"inpatient visits of discharge date minus admission date, in days)?",
                     str(out["total_inpatient_days"]), "numeric",
                     _act("get_visit_history", {"patient_id": p.patient_id}, ["patient_id"]), _provenance(p),
                     answer_unit="days")

    def procedures(p: EHRPatient) -> Task | None:
        names = sorted({x.name for x in p.procedures})
        name = rng.choice(names)
        kit = _tools(p, clock)
        dates = sorted(x.date[:10] for x in p.procedures if x.name == name)
        if len(dates) >= 2 and rng.random() < 0.7:
            start, end = f"{dates[0][:4]}-01-01", f"{rng.choice(dates[1:])[:4]}-12-31"
            out = kit.get_procedure_history(p.patient_id, start, end, name)
            if out["n_procedures"] != sum(start <= d <= end for d in dates):  # the name is a substring of another
                return None
            return _task(f"ehr_syn_proccount_{p.patient_id}", "procedure_count", p.patient_id,
                         f"How many times was \"{name}\" performed for patient {p.patient_id} between {start} and "
                         f"{end} inclusive?", str(out["n_procedures"]), "numeric",
                         _act("get_procedure_history", {"patient_id": p.patient_id, "start_date": start,
                                                        "end_date": end, "procedure": name},
                              ["patient_id", "procedure"]), _provenance(p), answer_unit="procedures")
        out = kit.get_procedure_history(p.patient_id, procedure=name)
        if out["most_recent"] != dates[-1]:
            return None
        return _task(f"ehr_syn_lastproc_{p.patient_id}", "last_procedure", p.patient_id,
                     f"When did patient {p.patient_id} most recently undergo \"{name}\"? Answer with the date as "
                     f"YYYY-MM-DD.", out["most_recent"], "exact",
                     _act("get_procedure_history", {"patient_id": p.patient_id, "procedure": name},
                          ["patient_id", "procedure"]), _provenance(p), answer_aliases=date_aliases(out["most_recent"]))

    def measurement_count(p: EHRPatient) -> Task | None:
        names = sorted({m.name for m in p.measurements})
        per_year = Counter((m.name, m.date[:4]) for m in p.measurements)
        pairs = sorted(k for k, n in per_year.items() if n >= 2
                       and not any(k[0].lower() in other.lower() and other != k[0] for other in names))
        if not pairs:
            return None
        name, year = rng.choice(pairs)
        start, end = f"{year}-01-01", f"{year}-12-31"
        out = _tools(p, clock).get_measurement_history(p.patient_id, name, start, end)
        return _task(f"ehr_syn_meascount_{p.patient_id}", "measurement_count", p.patient_id,
                     f"How many \"{name}\" measurements were recorded for patient {p.patient_id} in {year}? (The record "
                     f"has the measurement events, not their values.)", str(out["n_measurements"]), "numeric",
                     _act("get_measurement_history", {"patient_id": p.patient_id, "measurement": name,
                                                      "start_date": start, "end_date": end},
                          ["patient_id", "measurement", "start_date"]), _provenance(p), answer_unit="measurements")

    pick("condition_count", lambda p: len({c.start[:10] for c in p.conditions}) >= 4, condition_count)
    pick("first_diagnosis", lambda p: any(k >= 2 for k in Counter(c.name for c in p.conditions).values()),
         first_diagnosis)
    pick("active_med_count", lambda p: len(p.drug_exposures) >= 3, active_med_count)
    pick("active_med_choice", lambda p: len(p.drug_exposures) >= 3, active_med_choice)
    pick("exposure_count", lambda p: len(p.drug_exposures) >= 3, exposure_count)
    pick("visits", lambda p: len(p.visits) >= 2, visits)
    pick("procedures", lambda p: bool(p.procedures), procedures)
    pick("measurement_count", lambda p: bool(p.measurements), measurement_count)
    return groups


def generate(db: EHRDB, scenarios: dict[str, dict], icd: ICD10Index) -> dict[str, list[Task]]:
    """Every generated task of the domain by group: the ICU-record tasks, the authored workflows and the
    Synthea timeline questions."""
    groups = icu_tasks(db, scenarios, icd)
    groups["workflow"] = workflow_tasks(db)
    groups.update(timeline_tasks([p for p in db.patients.values() if p.source == "synthea"], db.clock))
    return groups


def _chart_tools(db: EHRDB, pid: str):
    """Tools over a fresh copy of one patient's chart (what an episode of that patient sees)."""
    from .tools import EHRTools

    one = EHRDB(patients={pid: db.patients[pid]}, clock=db.clock, next_order_number=db.next_order_number)
    return EHRTools(EHRDB.model_validate_json(one.model_dump_json()))


def _icu_act(aid: str, name: str, args: dict, compare: list[str]) -> dict:
    return {"action_id": aid, "name": name, "arguments": args, "compare_args": compare}


# The score definition or coding standard each generated task type's gold follows.
GUIDELINES = {
    "news2_from_record": "National Early Warning Score 2 (Royal College of Physicians, London 2017)",
    "sofa_from_record": "SOFA score (Vincent et al., Intensive Care Med 1996;22:707-710)",
    "apache_from_record": "APACHE II (Knaus et al., Crit Care Med 1985;13:818-829)",
    "lab_trend": "arithmetic from the charted results (first, last, delta, extremes, least-squares slope); no clinical guideline",
    "icd10_admission_coding": "ICD-10-CM tabular list and Official Guidelines for Coding and Reporting (CMS/NCHS), principal diagnosis",
    "admission_summary": "the admission's charted record (diagnoses, stays, results); no clinical guideline",
}


def _icu_task(tid: str, kind: str, ticket: str, answer: str, answer_type: str, actions: list[dict], pid: str,
              tol: float | None = None, unit: str | None = None, options: dict | None = None, **extra) -> Task:
    return Task(id=tid, ticket=ticket, correct_answer=answer, answer_type=answer_type, answer_tolerance=tol,
                answer_unit=unit, options=options, patient_id=pid,
                description={"purpose": kind.replace("_", " "), "difficulty": "medium", "source": "ehr_authored_icu",
                             "category": kind, "task_type": kind,
                             "provenance": {"patients": "authored synthetic ICU scenarios", "oracle": "computed from the record",
                                            "guideline": GUIDELINES[kind]}},
                evaluation_criteria={"actions": actions, "reward_basis": ["ACTION", "ANSWER"]}, **extra)


def _searchable(icd, text: str, code: str) -> str:
    """The longest leading part of the diagnosis text that ICD-10-CM search matches (else the
    code's category title, e.g. British spellings such as "necrotising")."""
    words = text.replace(",", " ").split()
    for n in range(len(words), 0, -1):
        query = " ".join(words[:n])
        if icd.search(query, 1):
            return query
    return icd.items[code[:3]]["desc"]


def icu_tasks(db: EHRDB, scenarios: dict[str, dict], icd: ICD10Index, seed: int = 53) -> dict[str, list[Task]]:
    """Tasks over the authored ICU patients: lab trends, SOFA per ICU day, APACHE II, NEWS2, admission coding, vasopressor hours."""
    rng = random.Random(seed)
    groups: dict[str, list[Task]] = {k: [] for k in ("trend", "sofa", "apache", "news2", "icd", "summary")}
    for pid in sorted(scenarios):
        patient = db.patients[pid]
        kit = _chart_tools(db, pid)
        adm = patient.admissions[0]
        tests = sorted({e.test for e in adm.lab_events})
        for test in rng.sample(tests, 6):
            tr = kit.get_lab_trend(pid, test)
            q = rng.choice(["delta", "direction", "max"])
            act = [_icu_act("trend", "get_lab_trend", {"patient_id": pid, "test": test}, ["patient_id", "test"])]
            if q == "delta":
                groups["trend"].append(_icu_task(f"ehr_trend_{pid}_{test}_delta", "lab_trend",
                    f"For patient {pid}'s current admission, what is the change in {test.replace('_', ' ')} from the first to "
                    f"the last result ({tr['unit']})? Give last minus first.", f"{tr['delta']:g}", "numeric", act, pid,
                    tol=max(0.011, abs(tr['delta']) * 0.005), unit=tr["unit"]))
            elif q == "direction":
                groups["trend"].append(_icu_task(f"ehr_trend_{pid}_{test}_dir", "lab_trend",
                    f"Over patient {pid}'s current admission, is the {test.replace('_', ' ')} rising, falling or stable "
                    f"(least-squares slope, and a change of more than 10% from the first value)?", tr["direction"],
                    "category", act, pid))
            else:
                groups["trend"].append(_icu_task(f"ehr_trend_{pid}_{test}_max", "lab_trend",
                    f"What was the highest {test.replace('_', ' ')} recorded during patient {pid}'s current admission "
                    f"({tr['unit']})?", f"{tr['max']:g}", "numeric", act, pid, tol=1e-6, unit=tr["unit"]))
        icu_in = adm.icu_stays[0].intime
        from datetime import datetime, timedelta

        for day in range(3):
            start = (datetime.strptime(icu_in, "%Y-%m-%dT%H:%M") + timedelta(hours=24 * day)).strftime("%Y-%m-%dT%H:%M")
            sofa = kit.calculate_sofa(pid, window_start=start, window_hours=24)
            groups["sofa"].append(_icu_task(f"ehr_sofa_{pid}_d{day + 1}", "sofa_from_record",
                f"Compute patient {pid}'s SOFA score for ICU day {day + 1} (the 24 hours from {start}), using the worst "
                f"recorded value of each organ system in that window. Answer with the total.", str(sofa["score"]),
                "numeric", [_icu_act("sofa", "calculate_sofa", {"patient_id": pid, "window_start": start, "window_hours": 24},
                                 ["patient_id", "window_start"])], pid, tol=0, unit="points"))
        ap = kit.calculate_apache2(pid)
        groups["apache"].append(_icu_task(f"ehr_apache_{pid}", "apache_from_record",
            f"Compute patient {pid}'s APACHE II score from the first 24 hours of the ICU stay (worst values). "
            f"Answer with the total.", str(ap["score"]), "numeric",
            [_icu_act("apache", "calculate_apache2", {"patient_id": pid}, ["patient_id"])], pid, tol=0, unit="points"))
        # NEWS2 scores spontaneous breathing and ACVPU consciousness (RCP 2017): not a score for a patient on
        # invasive ventilation, so only vital sets charted off the ventilator are asked about (envs.coherence).
        times = [v.time for v in adm.vital_events
                 if not any(w.start <= v.time and (w.end is None or v.time < w.end) for w in adm.ventilation if w.mode == "invasive")]
        for at in rng.sample(times, min(3, len(times))):
            news = kit.calculate_news2(pid, at_time=at)
            groups["news2"].append(_icu_task(f"ehr_news2_{pid}_{at.replace(':', '').replace('-', '')}", "news2_from_record",
                f"What was patient {pid}'s NEWS2 score from the vital signs charted at {at}?", str(news["score"]),
                "numeric", [_icu_act("news2", "calculate_news2", {"patient_id": pid, "at_time": at}, ["patient_id", "at_time"])],
                pid, tol=0, unit="points"))
        code = scenarios[pid]["icd10"]
        sibs = [c for c in icd.siblings(code) if icd.items[c]["billable"]]
        if len(sibs) < 3:
            block = icd.items[code]["block"]
            sibs = [c for c, it in icd.items.items() if it["billable"] and it["block"] == block and c != code]
        opts = rng.sample(sorted(sibs), 3) + [code]
        rng.shuffle(opts)
        groups["icd"].append(_icu_task(f"ehr_icd_{pid}", "icd10_admission_coding",
            f"Patient {pid}'s current admission is for \"{adm.admission_diagnosis}\". Which ICD-10-CM code is the "
            f"principal diagnosis? Record it with assign_icd10_code and answer with the option letter.",
            ICU_LETTERS[opts.index(code)], "choice",
            [_icu_act("lookup", "lookup_icd10", {"query": _searchable(icd, adm.admission_diagnosis, code)}, []),
             _icu_act("assign", "assign_icd10_code", {"patient_id": pid, "icd10_code": code}, ["patient_id", "icd10_code"])],
            pid, options={ICU_LETTERS[i]: f"{c} {icd.items[c]['desc']}" for i, c in enumerate(opts)}))
        summ = kit.summarize_admission(pid)
        groups["summary"].append(_icu_task(f"ehr_summary_{pid}", "admission_summary",
            f"From patient {pid}'s record, how many hours of vasopressor or inotrope infusion has the patient received "
            f"so far in this admission (record clock {db.clock})?", f"{summ['vasopressor_hours']:g}", "numeric",
            [_icu_act("summary", "summarize_admission", {"patient_id": pid}, ["patient_id"])], pid, tol=0.1, unit="hours"))
    return groups


def workflow_tasks(db: EHRDB) -> list[Task]:
    """The authored order-management workflows, with the expected final database hash from a gold replay."""
    from .tools import EHRTools

    specs = json.loads((AUTHORED / "workflows.json").read_text(encoding="utf-8"))["workflows"]
    out = []
    for spec in specs:
        # The episode database holds the task's patient only (environment.open_chart).
        patient = db.patients[spec["patient_id"]]
        kit = EHRTools(EHRDB.model_validate_json(
            EHRDB(patients={spec["patient_id"]: patient}, clock=db.clock, next_order_number=db.next_order_number).model_dump_json()))
        for a in spec["actions"]:
            getattr(kit, a["name"])(**a["arguments"])
        answer = spec["answer"]
        if answer.startswith("="):  # a value read from the record by a tool call: "=tool:key"
            tool, key = answer[1:].split(":")
            call = next(a for a in spec["actions"] if a["name"] == tool)
            answer = f"{getattr(_chart_tools(db, spec['patient_id']), tool)(**call['arguments'])[key]:g}"
        writes_free_text = any(a["name"] in ("write_clinical_note", "place_order", "order_medication", "escalate_care")
                               for a in spec["actions"])
        crit = {"actions": spec["actions"], "nl_assertions": spec["nl_assertions"],
                "reward_basis": ["ACTION", "ANSWER", "NL_ASSERTION"] + ([] if writes_free_text else ["DB"])}
        if not writes_free_text:
            crit["expected_db_hash"] = kit.db.content_hash()
        out.append(Task(id=spec["id"], ticket=spec["ticket"], correct_answer=answer, answer_type=spec["answer_type"],
                        answer_tolerance=spec.get("tolerance"), answer_unit=spec.get("unit"), patient_id=spec["patient_id"],
                        emergency=spec.get("emergency"),
                        description={"purpose": "EHR order-management workflow", "difficulty": "hard", "source": "authored",
                                     "category": "workflow", "task_type": "order_workflow",
                                     "provenance": {"origin": "authored", "license": "project", "guideline": spec["guideline"]}},
                        evaluation_criteria=crit,
                        # what a complete gold submission states with its answer (envs.validate.gold_replay)
                        metadata={"gold_reasoning": spec["gold_reasoning"]} if spec.get("gold_reasoning") else {}))
    return out
