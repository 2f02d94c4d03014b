"""MIMIC-III v1.4 and eICU-CRD v2.0 CSV extracts -> gradeable tasks of the `ehr_management` domain.

Users bring the files (credentialed PhysioNet data never ships with this project); each converter
reads a folder holding the tables exactly as the release distributes them (`.csv` or `.csv.gz`):

| format | files (column names as released) |
|---|---|
| mimic3 | PATIENTS, ADMISSIONS, ICUSTAYS, LABEVENTS, D_LABITEMS, DIAGNOSES_ICD, D_ICD_DIAGNOSES (upper case) |
| eicu | patient, lab, diagnosis (lower case) |

How imported patients become EHR patients: every task carries its patient in
`task.metadata["ehr_patient"]` (an `EHRPatient` record with the one admission the task is about:
demographics, ICU stays, all numeric lab results of the admission (eICU: of the unit stay) with
the source row of each, coded diagnoses). The EHR environment's `on_reset`
(`envs.domains.ehr_management.environment.open_chart`) validates that record and opens it as the
episode's chart, so every imported task replays in a fresh environment and passes
`hcgym tasks validate`. Records are self-contained (a task file can be large: one admission's
labs per task); `max_stays` limits how many ICU stays are converted.

Tasks per ICU stay, each with the EHR tool that answers it as the expected action and the gold
computed by that tool on the imported record:
* the last serum creatinine charted during the ICU stay (`get_lab_events`, stay window);
* the trend direction of creatinine over the ICU stay, else the first of potassium, hemoglobin,
  lactate, sodium with two results in the stay (`get_lab_trend`: rising / falling / stable);
* the ICU length of stay in days from the in/out times (`summarize_admission`; MIMIC-III's LOS
  column must agree within 0.01 day, else the row is reported and no LOS task is made);
* per admission, the code of the primary diagnosis (`get_admission_diagnoses`): MIMIC-III
  DIAGNOSES_ICD sequence 1 (ICD-9-CM, answered with the dot, "038.9"; the undotted "0389" is an
  alias); eICU the diagnosis row with diagnosispriority "Primary" that is active upon discharge
  (else the latest primary), its first listed code, the other listed codes (often the ICD-10-CM
  equivalent) as aliases; an ambiguous primary (two rows tie with different codes) makes no task.

Dates: MIMIC-III dates are the release's shifted dates, kept as they are. eICU has no calendar
dates (offsets in minutes from unit admission): the unit admission is placed on 1 January of
`hospitaldischargeyear` at `unitadmittime24`, and every other time keeps its offset. Ages above
89 (MIMIC-III shifts those dates of birth by 300 years; eICU writes "> 89") become 90.

Malformed rows (wrong number of fields, bad numbers or times, unknown references) are reported
with file and line in `ConversionResult.errors` and skipped; results without a numeric value
(e.g. MIMIC-III "HEMOLYZED") and lab rows outside any converted admission are skipped silently,
as the release intends.
"""

from __future__ import annotations

import re
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from envs.converters.base import ConversionResult, SourceFileError, csv_rows
from envs.core.task import Task

DOMAIN = "ehr_management"
PATIENT_KEY = "ehr_patient"  # = envs.domains.ehr_management.environment.IMPORTED_PATIENT_KEY

MIMIC3_COLUMNS: dict[str, list[str]] = {
    "PATIENTS": ["ROW_ID", "SUBJECT_ID", "GENDER", "DOB", "DOD", "DOD_HOSP", "DOD_SSN", "EXPIRE_FLAG"],
    "ADMISSIONS": ["ROW_ID", "SUBJECT_ID", "HADM_ID", "ADMITTIME", "DISCHTIME", "DEATHTIME", "ADMISSION_TYPE",
                   "ADMISSION_LOCATION", "DISCHARGE_LOCATION", "INSURANCE", "LANGUAGE", "RELIGION", "MARITAL_STATUS",
                   "ETHNICITY", "EDREGTIME", "EDOUTTIME", "DIAGNOSIS", "HOSPITAL_EXPIRE_FLAG", "HAS_CHARTEVENTS_DATA"],
    "ICUSTAYS": ["ROW_ID", "SUBJECT_ID", "HADM_ID", "ICUSTAY_ID", "DBSOURCE", "FIRST_CAREUNIT", "LAST_CAREUNIT",
                 "FIRST_WARDID", "LAST_WARDID", "INTIME", "OUTTIME", "LOS"],
    "LABEVENTS": ["ROW_ID", "SUBJECT_ID", "HADM_ID", "ITEMID", "CHARTTIME", "VALUE", "VALUENUM", "VALUEUOM", "FLAG"],
    "D_LABITEMS": ["ROW_ID", "ITEMID", "LABEL", "FLUID", "CATEGORY", "LOINC_CODE"],
    "DIAGNOSES_ICD": ["ROW_ID", "SUBJECT_ID", "HADM_ID", "SEQ_NUM", "ICD9_CODE"],
    "D_ICD_DIAGNOSES": ["ROW_ID", "ICD9_CODE", "SHORT_TITLE", "LONG_TITLE"],
}
EICU_COLUMNS: dict[str, list[str]] = {
    "patient": ["patientunitstayid", "patienthealthsystemstayid", "gender", "age", "ethnicity", "hospitalid", "wardid",
                "apacheadmissiondx", "admissionheight", "hospitaladmittime24", "hospitaladmitoffset",
                "hospitaladmitsource", "hospitaldischargeyear", "hospitaldischargetime24", "hospitaldischargeoffset",
                "hospitaldischargelocation", "hospitaldischargestatus", "unittype", "unitadmittime24",
                "unitadmitsource", "unitvisitnumber", "unitstaytype", "admissionweight", "dischargeweight",
                "unitdischargetime24", "unitdischargeoffset", "unitdischargelocation", "unitdischargestatus",
                "uniquepid"],
    "lab": ["labid", "patientunitstayid", "labresultoffset", "labtypeid", "labname", "labresult", "labresulttext",
            "labmeasurenamesystem", "labmeasurenameinterface", "labresultrevisedoffset"],
    "diagnosis": ["diagnosisid", "patientunitstayid", "activeupondischarge", "diagnosisoffset", "diagnosisstring",
                  "icd9code", "diagnosispriority"],
}

# Lab names -> the EHR domain's test names (blood tests; everything else keeps its normalised name).
MIMIC3_BLOOD_TESTS = {
    "creatinine": "creatinine", "potassium": "potassium", "sodium": "sodium", "chloride": "chloride",
    "bicarbonate": "bicarbonate", "urea nitrogen": "bun", "glucose": "glucose", "hemoglobin": "hemoglobin",
    "hematocrit": "hematocrit", "platelet count": "platelets", "white blood cells": "wbc", "lactate": "lactate",
    "bilirubin, total": "total_bilirubin", "albumin": "albumin", "inr(pt)": "inr", "po2": "pao2", "pco2": "paco2",
    "ph": "ph_arterial", "troponin t": "troponin_t", "magnesium": "magnesium", "calcium, total": "calcium",
}
EICU_TESTS = {
    "creatinine": "creatinine", "potassium": "potassium", "sodium": "sodium", "chloride": "chloride",
    "bicarbonate": "bicarbonate", "bun": "bun", "glucose": "glucose", "bedside glucose": "bedside_glucose",
    "hgb": "hemoglobin", "hct": "hematocrit", "platelets x 1000": "platelets", "wbc x 1000": "wbc",
    "lactate": "lactate", "total bilirubin": "total_bilirubin", "albumin": "albumin", "pt - inr": "inr",
    "pao2": "pao2", "paco2": "paco2", "ph": "ph_arterial", "troponin - i": "troponin_i", "magnesium": "magnesium",
    "calcium": "calcium",
}
TREND_TESTS = ("creatinine", "potassium", "hemoglobin", "lactate", "sodium")
MIMIC_TYPES = {"EMERGENCY": "emergency", "ELECTIVE": "elective", "URGENT": "urgent", "NEWBORN": "newborn"}
LOS_AGREEMENT_DAYS = 0.01


# -- reading the tables ------------------------------------------------------------------------------
def _table(folder: Path, name: str) -> Path:
    for candidate in (folder / f"{name}.csv", folder / f"{name}.csv.gz"):
        if candidate.is_file():
            return candidate
    raise SourceFileError(f"{folder}: {name}.csv (or {name}.csv.gz) not found")


def _rows(path: Path, needed: list[str], result: ConversionResult) -> Iterator[tuple[int, dict[str, str]]]:
    """(line, row) for each data row, streamed; a missing column stops with SourceFileError, a bad row is reported.

    Read through `envs.converters.base.csv_rows`: UTF-8 with or without a BOM (files re-saved on Windows),
    CRLF, `.csv.gz`; another encoding or a truncated gzip stops with the file and line."""
    records = csv_rows(path)
    first = next(records, None)
    if first is None or first[1] is None:
        raise SourceFileError(f"{path}: empty file (no header)" if first is None else f"{path}:1: {first[2]}")
    # column names match case-insensitively: the MIMIC-III demo v1.4 writes `row_id,subject_id,...`
    # where the full release writes `ROW_ID,SUBJECT_ID,...`; rows are keyed by the names in `needed`
    spelling = {c.lower(): c for c in needed}
    header = [spelling.get(h.strip().lower(), h.strip()) for h in first[1]]
    missing = [c for c in needed if c not in header]
    if missing:
        raise SourceFileError(f"{path}: missing column(s) {', '.join(missing)} (header: {', '.join(header[:12])})")
    width = len(header)
    for line, row, problem in records:
        if row is None:
            result.add_error(path, line, problem)
            continue
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != width:
            result.add_error(path, line, f"expected {width} fields, got {len(row)}")
            continue
        yield line, dict(zip(header, (c.strip() for c in row)))


class RowProblem(ValueError):
    pass


def _int(row: dict[str, str], key: str, *, optional: bool = False) -> int | None:
    value = row.get(key, "")
    if value == "":
        if optional:
            return None
        raise RowProblem(f"{key} is empty")
    try:
        number = float(value)
    except ValueError:
        raise RowProblem(f"{key} {value!r} is not an integer") from None
    if number != int(number):
        raise RowProblem(f"{key} {value!r} is not an integer")
    return int(number)


def _float(row: dict[str, str], key: str, *, optional: bool = False) -> float | None:
    value = row.get(key, "")
    if value == "":
        if optional:
            return None
        raise RowProblem(f"{key} is empty")
    try:
        return float(value)
    except ValueError:
        raise RowProblem(f"{key} {value!r} is not a number") from None


def _time(row: dict[str, str], key: str, *, optional: bool = False) -> datetime | None:
    value = row.get(key, "")
    if value == "":
        if optional:
            return None
        raise RowProblem(f"{key} is empty")
    for fmt in ("%Y-%m-%d %H:%M:%S", "%Y-%m-%d %H:%M", "%Y-%m-%d"):
        try:
            return datetime.strptime(value, fmt)
        except ValueError:
            continue
    raise RowProblem(f"{key} {value!r} is not a time YYYY-MM-DD HH:MM:SS")


def _fmt(t: datetime) -> str:
    return t.strftime("%Y-%m-%dT%H:%M")


def _fmt_seconds(t: datetime) -> str:
    return t.strftime("%Y-%m-%dT%H:%M:%S")


def _key(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", text.lower()).strip("_")


def dotted_icd9(code: str) -> str:
    """MIMIC-III writes ICD-9-CM codes without the dot: "0389" -> "038.9", "V4581" -> "V45.81", "E8798" -> "E879.8"."""
    code = code.strip().upper()
    head = 4 if code.startswith("E") else 3
    return code if len(code) <= head else f"{code[:head]}.{code[head:]}"


def icd_system(code: str) -> str:
    """ICD-9-CM for numeric codes, E-codes with four characters before the dot ("E879.8") and V-codes of the
    ICD-9 shape ("V45.81"); ICD-10-CM otherwise ("R65.20", "I50.9", "V43.52XA")."""
    code = code.strip().upper()
    if code[:1].isdigit() or re.fullmatch(r"E\d{3}(?:\.\d)?", code) or re.fullmatch(r"V\d{2}(?:\.\d{1,2})?", code):
        return "ICD-9-CM"
    return "ICD-10-CM"


# -- records and tasks -----------------------------------------------------------------------------
@dataclass
class _Stay:
    stay_id: str
    unit: str
    intime: datetime
    outtime: datetime | None
    source: str
    los_checked: bool = True  # MIMIC-III: the LOS column agrees with the times


@dataclass
class _Admission:
    patient_id: str
    name: str
    age: int
    sex: str
    hadm_id: str
    admit: datetime
    discharge: datetime | None
    admission_type: str
    diagnosis: str
    stays: list[_Stay] = field(default_factory=list)
    labs: list[dict[str, Any]] = field(default_factory=list)
    diagnoses: list[dict[str, Any]] = field(default_factory=list)
    primary: tuple[str, list[str]] | None = None  # (gold code, alias codes)
    weight_kg: float | None = None
    provenance: dict[str, str] = field(default_factory=dict)

    def record(self, stays: list[_Stay] | None = None) -> dict[str, Any]:
        stays = self.stays if stays is None else stays
        admission = {
            "hadm_id": self.hadm_id, "admit_time": _fmt(self.admit),
            "discharge_time": _fmt(self.discharge) if self.discharge else None,
            "admission_type": self.admission_type, "admission_diagnosis": self.diagnosis,
            # ICU times keep their seconds: the length of stay is computed from them and must match the
            # source's LOS column (MIMIC-III ICUSTAYS.LOS, fractional days from the full timestamps)
            "icu_stays": [{"stay_id": s.stay_id, "unit": s.unit, "intime": _fmt_seconds(s.intime),
                           "outtime": _fmt_seconds(s.outtime) if s.outtime else None} for s in stays],
            "lab_events": sorted(self.labs, key=lambda e: (e["time"], e["test"], e["source_id"])),
            "coded_diagnoses": self.diagnoses,
        }
        return {"patient_id": self.patient_id, "name": self.name, "age": self.age, "sex": self.sex,
                "weight_kg": self.weight_kg, "admissions": [admission], "source": self.provenance.get("dataset", ""),
                "provenance": self.provenance}


def _tools_for(record: dict[str, Any]):
    from envs.domains.ehr_management.data_model import EHRDB, EHRPatient
    from envs.domains.ehr_management.tools import EHRTools

    patient = EHRPatient.model_validate(record)
    return EHRTools(EHRDB(patients={patient.patient_id: patient})), patient


def _make_tasks(fmt: str, adm: _Admission, stays: list[_Stay], record: dict[str, Any], with_primary: bool,
                domain: str, result: ConversionResult, where: tuple[Path, int]) -> None:
    """The tasks of one record (one admission, `stays` its ICU stays in the record)."""
    from envs.core.tools import ToolError

    try:
        kit, patient = _tools_for(record)
    except ValidationError as exc:
        result.add_error(where[0], where[1], f"record of {adm.patient_id}/{adm.hadm_id} is invalid: "
                                             f"{exc.errors()[0]['loc']}: {exc.errors()[0]['msg']}")
        return
    pid, hadm = patient.patient_id, adm.hadm_id
    payload = patient.model_dump(mode="json", exclude_defaults=True)
    label = {"mimic3": "MIMIC-III", "eicu": "eICU"}[fmt]

    def add(kind: str, key: str, ticket: str, answer: str, answer_type: str, action: dict, **extra) -> None:
        extra.setdefault("answer_tolerance", None)
        data = {
            "id": f"{fmt}_{kind}_{key}", "domain": domain, "ticket": ticket, "patient_id": pid,
            "correct_answer": answer, "answer_type": answer_type,
            "description": {"purpose": f"{label} ICU record: {kind.replace('_', ' ')}", "difficulty": "medium",
                            "source": fmt, "category": "ehr_import", "task_type": f"{fmt}_{kind}",
                            "provenance": {**adm.provenance, "oracle": action["name"]}},
            "evaluation_criteria": {"actions": [action], "reward_basis": ["ACTION", "ANSWER"]},
            "metadata": {PATIENT_KEY: payload, "task_kind": "management"}, **extra,
        }
        try:
            result.tasks.append(Task.model_validate(data))
        except ValidationError as exc:
            result.add_error(where[0], where[1], f"task {data['id']}: {exc.errors()[0]['msg']}")

    def act(name: str, args: dict, compare: list[str]) -> dict:
        return {"action_id": name, "name": name, "arguments": args, "compare_args": compare}

    for stay in stays:
        sid = stay.stay_id
        where_text = f"ICU stay {sid} (admission {hadm})"
        try:
            events = kit.get_lab_events(pid, "creatinine", hadm, sid)["events"]
        except ToolError:
            events = []
        if events:
            last_time = events[-1]["time"]
            values = {e["value"] for e in events if e["time"] == last_time}
            if len(values) == 1:  # two different results at the same time: no single "last" value
                add("last_creatinine", sid,
                    f"Patient {pid}, {where_text}: what was the last serum creatinine charted during this ICU stay "
                    f"({events[-1]['unit'] or 'as recorded'})? Answer with the value.", f"{events[-1]['value']:g}",
                    "numeric", act("get_lab_events", {"patient_id": pid, "test": "creatinine", "hadm_id": hadm,
                                                      "stay_id": sid}, ["patient_id", "test", "stay_id"]),
                    answer_tolerance=1e-6, answer_unit=events[-1]["unit"] or None)
        for test in TREND_TESTS:
            try:
                tr = kit.get_lab_trend(pid, test, hadm, sid)
            except ToolError:
                continue
            add("lab_trend", f"{sid}_{test}",
                f"Patient {pid}, {where_text}: over this ICU stay, is the {test} rising, falling or stable "
                f"(least-squares slope, and a change of more than 10% from the first value)?", tr["direction"],
                "category", act("get_lab_trend", {"patient_id": pid, "test": test, "hadm_id": hadm, "stay_id": sid},
                                ["patient_id", "test", "stay_id"]))
            break
        if stay.outtime is not None and stay.los_checked:
            summary = kit.summarize_admission(pid, hadm)
            los = next(s["los_days"] for s in summary["icu_stays"] if s["stay_id"] == sid)
            add("icu_los", sid,
                f"Patient {pid}, {where_text}: what was the ICU length of stay in days (ICU discharge time minus ICU "
                f"admission time)? Answer to 2 decimal places.", f"{los:.2f}", "numeric",
                act("summarize_admission", {"patient_id": pid, "hadm_id": hadm}, ["patient_id", "hadm_id"]),
                answer_tolerance=0.01, answer_unit="days")
    if with_primary and adm.primary is not None:
        out = kit.get_admission_diagnoses(pid, hadm)
        code, aliases = adm.primary
        if out["primary"] and out["primary"]["code"] in (code, *aliases):
            system = out["primary"]["system"]
            add("primary_diagnosis", hadm,
                f"Patient {pid}, admission {hadm}: what is the {system} code of the primary diagnosis? Answer with the "
                f"code.", code, "exact",
                act("get_admission_diagnoses", {"patient_id": pid, "hadm_id": hadm}, ["patient_id", "hadm_id"]),
                answer_aliases=list(dict.fromkeys(a for a in aliases if a != code)))


# -- MIMIC-III -------------------------------------------------------------------------------------
def convert_mimic3(path: str | Path, domain: str = DOMAIN, max_stays: int | None = None, **_: Any) -> ConversionResult:
    """A folder of MIMIC-III v1.4 CSVs -> EHR tasks (see the module docstring)."""
    folder = Path(path)
    if not folder.is_dir():
        raise SourceFileError(f"{folder}: not a folder of MIMIC-III CSV files")
    result = ConversionResult()
    files = {name: _table(folder, name) for name in MIMIC3_COLUMNS}
    cols = MIMIC3_COLUMNS

    patients: dict[int, tuple[str, datetime]] = {}
    for line, row in _rows(files["PATIENTS"], cols["PATIENTS"], result):
        try:
            sid, dob = _int(row, "SUBJECT_ID"), _time(row, "DOB")
            gender = {"M": "male", "F": "female"}.get(row["GENDER"].upper())
            if gender is None:
                raise RowProblem(f"GENDER {row['GENDER']!r} is not M or F")
        except RowProblem as exc:
            result.add_error(files["PATIENTS"], line, str(exc))
            continue
        patients[sid] = (gender, dob)  # type: ignore[index]

    admissions: dict[int, _Admission] = {}
    adm_line: dict[int, int] = {}
    for line, row in _rows(files["ADMISSIONS"], cols["ADMISSIONS"], result):
        try:
            sid, hadm = _int(row, "SUBJECT_ID"), _int(row, "HADM_ID")
            if sid not in patients:
                raise RowProblem(f"SUBJECT_ID {sid} is not in PATIENTS")
            admit, discharge = _time(row, "ADMITTIME"), _time(row, "DISCHTIME", optional=True)
            kind = MIMIC_TYPES.get(row["ADMISSION_TYPE"].upper())
            if kind is None:
                raise RowProblem(f"ADMISSION_TYPE {row['ADMISSION_TYPE']!r} is not one of {', '.join(MIMIC_TYPES)}")
        except RowProblem as exc:
            result.add_error(files["ADMISSIONS"], line, str(exc))
            continue
        gender, dob = patients[sid]
        age = admit.year - dob.year - ((admit.month, admit.day) < (dob.month, dob.day))  # type: ignore[union-attr]
        admissions[hadm] = _Admission(  # type: ignore[index]
            patient_id=f"MIMIC3-{sid}", name=f"MIMIC-III subject {sid}", age=90 if age > 89 else max(age, 0),
            sex=gender, hadm_id=str(hadm), admit=admit, discharge=discharge, admission_type=kind,  # type: ignore[arg-type]
            diagnosis=row["DIAGNOSIS"] or "not recorded",
            provenance={"dataset": "MIMIC-III v1.4", "subject_id": str(sid), "hadm_id": str(hadm),
                        "files": "PATIENTS, ADMISSIONS, ICUSTAYS, LABEVENTS, D_LABITEMS, DIAGNOSES_ICD, D_ICD_DIAGNOSES",
                        "age_note": "age above 89 is obscured in MIMIC-III; recorded as 90" if age > 89 else ""})
        adm_line[hadm] = line  # type: ignore[index]

    stays_line: dict[str, int] = {}
    for line, row in _rows(files["ICUSTAYS"], cols["ICUSTAYS"], result):
        result.rows_read += 1  # "read" in the import table: ICU stays
        try:
            hadm, stay_id = _int(row, "HADM_ID"), _int(row, "ICUSTAY_ID")
            if hadm not in admissions:
                raise RowProblem(f"HADM_ID {hadm} is not in ADMISSIONS")
            if _int(row, "SUBJECT_ID") != int(admissions[hadm].provenance["subject_id"]):  # type: ignore[index]
                raise RowProblem(f"SUBJECT_ID does not match admission {hadm}")
            intime, outtime = _time(row, "INTIME"), _time(row, "OUTTIME", optional=True)
            los = _float(row, "LOS", optional=True)
        except RowProblem as exc:
            result.add_error(files["ICUSTAYS"], line, str(exc))
            continue
        stay = _Stay(str(stay_id), row["FIRST_CAREUNIT"] or "ICU", intime, outtime,  # type: ignore[arg-type]
                     f"ICUSTAYS.csv:ROW_ID={row['ROW_ID']}")
        if outtime is not None and los is not None:
            computed = (outtime - intime).total_seconds() / 86400  # type: ignore[operator]
            if abs(computed - los) > LOS_AGREEMENT_DAYS:
                stay.los_checked = False
                result.add_error(files["ICUSTAYS"], line, f"LOS {los:g} disagrees with OUTTIME - INTIME = "
                                                          f"{computed:.4f} days; no length-of-stay task for this stay")
        admissions[hadm].stays.append(stay)  # type: ignore[index]
        stays_line[str(stay_id)] = line

    # The admissions (and ICU stays) to convert are chosen before LABEVENTS is read, so the stream keeps
    # only their results: LABEVENTS is ~27.9 million rows in the full release and is never held whole.
    selected: dict[int, list[_Stay]] = {}
    converted = 0
    for hadm in sorted(admissions):
        chosen = sorted(admissions[hadm].stays, key=lambda s: s.intime)
        if not chosen:
            continue
        if max_stays is not None:
            chosen = chosen[: max(0, max_stays - converted)]
            if not chosen:
                break
        converted += len(chosen)
        selected[hadm] = chosen

    items: dict[int, tuple[str, str, str]] = {}
    for line, row in _rows(files["D_LABITEMS"], cols["D_LABITEMS"], result):
        try:
            items[_int(row, "ITEMID")] = (row["LABEL"], row["FLUID"], row["LOINC_CODE"])  # type: ignore[index]
        except RowProblem as exc:
            result.add_error(files["D_LABITEMS"], line, str(exc))

    for line, row in _rows(files["LABEVENTS"], cols["LABEVENTS"], result):
        if row["HADM_ID"] == "" or row["VALUENUM"] == "":
            continue  # outpatient result, or a text result ("HEMOLYZED"): nothing numeric to place on an admission
        try:
            hadm = _int(row, "HADM_ID")
            if hadm not in selected:
                continue  # an admission not in this extract (or not converted): nothing else is parsed
            item = _int(row, "ITEMID")
            if item not in items:
                raise RowProblem(f"ITEMID {item} is not in D_LABITEMS")
            value, when = _float(row, "VALUENUM"), _time(row, "CHARTTIME")
        except RowProblem as exc:
            result.add_error(files["LABEVENTS"], line, str(exc))
            continue
        label, fluid, _loinc = items[item]  # type: ignore[index]
        if fluid.lower() == "blood" and label.lower() in MIMIC3_BLOOD_TESTS:
            test = MIMIC3_BLOOD_TESTS[label.lower()]
        else:
            test = _key(label) if fluid.lower() in ("blood", "") or fluid.lower() in label.lower() else \
                f"{_key(fluid)}_{_key(label)}"
        admissions[hadm].labs.append({"time": _fmt(when), "test": test, "value": value,  # type: ignore[index, arg-type]
                                      "unit": row["VALUEUOM"], "source_id": f"LABEVENTS.csv:ROW_ID={row['ROW_ID']}"})

    titles: dict[str, str] = {}
    for line, row in _rows(files["D_ICD_DIAGNOSES"], cols["D_ICD_DIAGNOSES"], result):
        titles[row["ICD9_CODE"]] = row["LONG_TITLE"] or row["SHORT_TITLE"]
    for line, row in _rows(files["DIAGNOSES_ICD"], cols["DIAGNOSES_ICD"], result):
        if row["SEQ_NUM"] == "" and row["ICD9_CODE"] == "":
            continue  # the release has rows with neither (admissions without coded diagnoses)
        try:
            hadm, seq = _int(row, "HADM_ID"), _int(row, "SEQ_NUM")
            code = row["ICD9_CODE"]
            if not re.fullmatch(r"[0-9VE]\d{2,4}", code):
                raise RowProblem(f"ICD9_CODE {code!r} is not an ICD-9-CM diagnosis code")
        except RowProblem as exc:
            result.add_error(files["DIAGNOSES_ICD"], line, str(exc))
            continue
        if hadm not in admissions:
            continue
        admissions[hadm].diagnoses.append({  # type: ignore[index]
            "seq": seq, "code": code, "system": "ICD-9-CM", "title": titles.get(code, ""), "primary": seq == 1,
            "source_id": f"DIAGNOSES_ICD.csv:ROW_ID={row['ROW_ID']}"})
    for adm in admissions.values():
        adm.diagnoses.sort(key=lambda d: d["seq"])
        first = [d for d in adm.diagnoses if d["seq"] == 1]
        if len(first) == 1:
            adm.primary = (dotted_icd9(first[0]["code"]), [first[0]["code"]])

    for hadm, stays in selected.items():
        adm = admissions[hadm]
        _make_tasks("mimic3", adm, stays, adm.record(sorted(adm.stays, key=lambda s: s.intime)), True, domain, result,
                    (files["ADMISSIONS"], adm_line[hadm]))
    return result


# -- eICU-CRD --------------------------------------------------------------------------------------
_PRIORITY = {"primary": 1, "major": 2, "other": 3}


def _codes(text: str) -> list[str]:
    return [c.strip() for c in text.split(",") if c.strip()]


def convert_eicu(path: str | Path, domain: str = DOMAIN, max_stays: int | None = None, **_: Any) -> ConversionResult:
    """A folder of eICU-CRD v2.0 CSVs (patient, lab, diagnosis) -> EHR tasks (see the module docstring)."""
    folder = Path(path)
    if not folder.is_dir():
        raise SourceFileError(f"{folder}: not a folder of eICU-CRD CSV files")
    result = ConversionResult()
    files = {name: _table(folder, name) for name in EICU_COLUMNS}
    cols = EICU_COLUMNS

    stays: dict[int, _Admission] = {}
    lines: dict[int, int] = {}
    anchors: dict[int, datetime] = {}
    for line, row in _rows(files["patient"], cols["patient"], result):
        result.rows_read += 1  # "read" in the import table: ICU (unit) stays
        try:
            uid = _int(row, "patientunitstayid")
            gender = {"male": "male", "female": "female"}.get(row["gender"].lower())
            if gender is None:
                raise RowProblem(f"gender {row['gender']!r} is not Male or Female")
            if row["age"] == "":
                raise RowProblem("age is empty")
            age = 90 if row["age"].replace(" ", "") == ">89" else _int(row, "age")
            year = _int(row, "hospitaldischargeyear")
            clock = datetime.strptime(row["unitadmittime24"], "%H:%M:%S") if row["unitadmittime24"] else None
            if clock is None:
                raise RowProblem("unitadmittime24 is empty")
            anchor = datetime(year, 1, 1, clock.hour, clock.minute)  # type: ignore[arg-type]
            admit_off, disch_off = _int(row, "hospitaladmitoffset"), _int(row, "hospitaldischargeoffset", optional=True)
            unit_out = _int(row, "unitdischargeoffset", optional=True)
            health = _int(row, "patienthealthsystemstayid")
            weight = _float(row, "admissionweight", optional=True)
            if not row["uniquepid"]:
                raise RowProblem("uniquepid is empty")
        except (RowProblem, ValueError) as exc:
            result.add_error(files["patient"], line, str(exc))
            continue
        adm = _Admission(
            patient_id=f"EICU-{row['uniquepid']}", name=f"eICU patient {row['uniquepid']}", age=min(age, 90),  # type: ignore[type-var]
            sex=gender, hadm_id=str(health), admit=anchor + timedelta(minutes=admit_off),  # type: ignore[operator]
            discharge=anchor + timedelta(minutes=disch_off) if disch_off is not None else None,
            admission_type="unknown", diagnosis=row["apacheadmissiondx"] or "not recorded", weight_kg=weight,
            provenance={"dataset": "eICU-CRD v2.0", "uniquepid": row["uniquepid"], "patientunitstayid": str(uid),
                        "patienthealthsystemstayid": str(health), "files": "patient, lab, diagnosis",
                        "dates": "no calendar dates in eICU: unit admission placed on 1 January of hospitaldischargeyear "
                                 "at unitadmittime24; offsets kept"})
        adm.stays.append(_Stay(str(uid), row["unittype"] or "ICU", anchor,
                               anchor + timedelta(minutes=unit_out) if unit_out is not None else None,
                               f"patient.csv:patientunitstayid={uid}"))
        stays[uid] = adm  # type: ignore[index]
        lines[uid] = line  # type: ignore[index]
        anchors[uid] = anchor  # type: ignore[index]

    for line, row in _rows(files["lab"], cols["lab"], result):
        if row["labresult"] == "":
            continue  # text-only result
        try:
            uid, offset = _int(row, "patientunitstayid"), _int(row, "labresultoffset")
            value = _float(row, "labresult")
            if uid not in stays:
                raise RowProblem(f"patientunitstayid {uid} is not in patient.csv")
            if not row["labname"]:
                raise RowProblem("labname is empty")
        except RowProblem as exc:
            result.add_error(files["lab"], line, str(exc))
            continue
        name = row["labname"].lower()
        stays[uid].labs.append({  # type: ignore[index]
            "time": _fmt(anchors[uid] + timedelta(minutes=offset)),  # type: ignore[index, operator]
            "test": EICU_TESTS.get(name, _key(name)), "value": value,
            "unit": row["labmeasurenamesystem"] or row["labmeasurenameinterface"],
            "source_id": f"lab.csv:labid={row['labid']}"})

    rows_by_stay: dict[int, list[tuple[int, int, dict[str, str]]]] = defaultdict(list)
    for line, row in _rows(files["diagnosis"], cols["diagnosis"], result):
        try:
            uid, offset = _int(row, "patientunitstayid"), _int(row, "diagnosisoffset")
            if uid not in stays:
                raise RowProblem(f"patientunitstayid {uid} is not in patient.csv")
            if row["diagnosispriority"].lower() not in _PRIORITY:
                raise RowProblem(f"diagnosispriority {row['diagnosispriority']!r} is not Primary, Major or Other")
            if row["activeupondischarge"].lower() not in ("true", "false"):
                raise RowProblem(f"activeupondischarge {row['activeupondischarge']!r} is not True or False")
        except RowProblem as exc:
            result.add_error(files["diagnosis"], line, str(exc))
            continue
        rows_by_stay[uid].append((line, offset, row))  # type: ignore[index, arg-type]
    for uid, rows in rows_by_stay.items():
        adm = stays[uid]
        primaries = [r for r in rows if r[2]["diagnosispriority"].lower() == "primary"]
        active = [r for r in primaries if r[2]["activeupondischarge"].lower() == "true"] or primaries
        chosen = None
        if active:
            latest = max(r[1] for r in active)
            candidates = {tuple(_codes(r[2]["icd9code"])) for r in active if r[1] == latest}
            if len(candidates) == 1:
                chosen = next(r for r in active if r[1] == latest)
        ordered = sorted(rows, key=lambda r: (_PRIORITY[r[2]["diagnosispriority"].lower()], r[1], r[2]["diagnosisid"]))
        for seq, (line, offset, row) in enumerate(ordered, start=1):
            for code in _codes(row["icd9code"]):
                adm.diagnoses.append({"seq": seq, "code": code, "system": icd_system(code),
                                      "title": row["diagnosisstring"], "primary": chosen is not None and row is chosen[2],
                                      "source_id": f"diagnosis.csv:diagnosisid={row['diagnosisid']}"})
        if chosen is not None and _codes(chosen[2]["icd9code"]):
            codes = _codes(chosen[2]["icd9code"])
            adm.primary = (codes[0], codes[1:])

    for n, uid in enumerate(sorted(stays)):
        if max_stays is not None and n >= max_stays:
            break
        adm = stays[uid]
        _make_tasks("eicu", adm, adm.stays, adm.record(), True, domain, result, (files["patient"], lines[uid]))
    return result


__all__ = ["EICU_COLUMNS", "MIMIC3_COLUMNS", "convert_eicu", "convert_mimic3", "dotted_icd9", "icd_system"]
