"""Tasks over the Synthea timelines, with exact oracles.

Each generator picks a patient and a question deterministically (sorted candidates, seeded RNG,
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

import random
from collections import Counter
from datetime import date, timedelta
from typing import Callable

from envs.core.task import Task

from .data_model import EHRDB, EHRPatient

LETTERS = "ABCD"
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
