"""Stroke code: ED triage (glucose to exclude a mimic, GCS, stroke code, ESI) -> pre-thrombolysis work-up
(the stroke-code CT, coagulation, platelets, coded diagnosis) -> thrombolysis decision in the pharmacy
tools (interactions with the patient's anticoagulant, weight-based alteplase dose capped at 90 mg)."""

from __future__ import annotations

from .records import (
    Med,
    Person,
    act,
    clinical_record,
    finding,
    pathway,
    pharmacy_record,
    phase,
    triage_record,
    vitals,
)

TITLE = "Stroke code"
PROTOCOL = (
    "Stroke protocol: IV alteplase 0.9 mg/kg (maximum 90 mg) within 4.5 hours of last known well when the "
    "CT shows no haemorrhage, glucose is above 50 mg/dL, INR is 1.7 or less, platelets are at least "
    "100 x10^3/uL and blood pressure is below 185/110 mmHg."
)

HEMIPARESIS = finding("HP:0001269", "Hemiparesis", "exam")
APHASIA = finding("HP:0002381", "Aphasia", "exam")
FACIAL_PALSY = finding("HP:0010628", "Facial palsy", "exam")
DYSARTHRIA = finding("HP:0001260", "Dysarthria", "exam")
HEMIANOPIA = finding("HP:0012377", "Hemianopia", "exam")


def _triage(pid: str, deficits: str, esi: int = 2) -> dict:
    return phase(
        "stroke code",
        "triage_emergency",
        "A suspected acute stroke within the thrombolysis window: check glucose, document the GCS, activate the "
        "stroke code without delay and assign the ESI level.",
        [
            act("get_patient_presentation", patient_id=pid),
            act("get_vital_signs", patient_id=pid),
            act("order_point_of_care_test", ["patient_id", "test"], patient_id=pid, test="glucose"),
            act("calculate_gcs", patient_id=pid),
            act("activate_stroke_code", patient_id=pid, deficits=deficits),
            act(
                "assign_triage_level",
                ["patient_id", "esi_level"],
                patient_id=pid,
                esi_level=esi,
                rationale="acute stroke within the treatment window",
            ),
        ],
        [
            "Checks the capillary glucose to exclude hypoglycaemia as a stroke mimic",
            "Activates the stroke code with the deficits and the last-known-well time",
            f"Assigns ESI level {esi}",
        ],
        max_calls=7,
    )


def _workup(pid: str, extra: list | None = None, assertion: str | None = None) -> dict:
    return phase(
        "pre-thrombolysis work-up",
        "clinical_diagnosis",
        "Review the stroke-code CT, check INR and platelets, and record the diagnosis.",
        [
            act("get_lab_results", patient_id=pid),
            act("order_lab", ["patient_id", "test"], patient_id=pid, test="inr", priority="stat"),
            act("order_lab", ["patient_id", "test"], patient_id=pid, test="platelets", priority="stat"),
            *(extra or []),
            act("record_diagnosis", patient_id=pid, icd10_code="I63.512", certainty="confirmed"),
        ],
        [
            "Confirms that the CT shows no intracranial haemorrhage before considering thrombolysis",
            "Checks INR and platelets against the thrombolysis limits",
            assertion or "Records an acute ischaemic stroke (cerebral infarction) as the diagnosis",
        ],
    )


def _lysis(pid: str, dose: float, before: list | None = None) -> dict:
    return phase(
        "thrombolysis",
        "drug_interaction",
        "Decide on IV alteplase: check the medication list for interactions and give the weight-based dose.",
        [
            act("check_allergy", ["patient_id", "drug"], patient_id=pid, drug="alteplase"),
            act("check_patient_interactions", ["patient_id", "drug"], patient_id=pid, drug="alteplase"),
            *(before or []),
            act("get_dose_range", ["drug", "patient_id"], drug="alteplase", patient_id=pid),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=pid,
                drug="alteplase",
                dose=dose,
                unit="mg",
                route="IV",
                frequency="once: 10% bolus over 1 minute, the rest over 60 minutes",
                indication="acute ischaemic stroke within 4.5 hours; neuro observations and blood pressure monitoring "
                "every 15 minutes",
            ),
        ],
        [
            f"Gives alteplase {dose:g} mg (0.9 mg/kg, capped at 90 mg) as a 10% bolus and 60-minute infusion",
            "Plans neurological and blood-pressure monitoring after thrombolysis",
        ],
        max_calls=5,
    )


def _ct(text: str) -> tuple[str, str, str, str]:
    return ("ct_head", text, "text", "2025-03-01T14:18")


def left_mca() -> dict:
    p = Person(
        "PW-ST01",
        "George Adeyemi",
        67,
        "male",
        82.0,
        177.0,
        conditions=("hypertension", "hypercholesterolaemia"),
        meds=(
            Med("indapamide", 2.5, "mg", "PO", "once daily", "hypertension"),
            Med("atorvastatin", 40, "mg", "PO", "once daily", "hypercholesterolaemia"),
        ),
        creatinine_mg_dl=1.0,
    )
    v = [vitals("2025-03-01T13:57", 84, 168, 94, 16, 36.7, 97, gcs=(4, 1, 6))]
    deficits = "right face, arm and leg weakness with expressive aphasia"
    patients = {
        "triage_emergency": triage_record(
            p,
            arrival_mode="ambulance",
            chief_complaint="sudden right-sided weakness and loss of speech",
            history="Wife saw him well at 13:10; at 13:25 he dropped his cup, his right face drooped and he could not "
            "get his words out. Hypertension (indapamide) and high cholesterol (atorvastatin).",
            vitals_rows=v,
            held={"glucose": (128.0, "mg/dL")},
            last_known_well="13:10",
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Right-sided weakness and aphasia since 13:25",
            hpi="Last known well 13:10. Sudden right face, arm and leg weakness with expressive aphasia; stroke code "
            "activated at 14:05; non-contrast CT head at 14:18.",
            exam={
                "neurologic": "Expressive aphasia, right lower facial droop, right arm 1/5, right leg 3/5, right "
                "sensory inattention; NIHSS 14",
                "cardiovascular": "Regular rhythm",
            },
            vitals_rows=v,
            findings=[HEMIPARESIS, APHASIA, FACIAL_PALSY],
            labs=[
                _ct(
                    "non-contrast CT head: no intracranial haemorrhage; hyperdense left middle cerebral artery sign; "
                    "ASPECTS 9"
                )
            ],
            hidden={
                "inr": (1.0, "ratio", 20),
                "platelets": (234.0, "10^3/uL", 20),
                "glucose": (128.0, "mg/dL", 20),
                "creatinine": (1.0, "mg/dL", 30),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, notes="Acute left MCA ischaemic stroke, thrombolysis candidate."
        ),
    }
    return pathway(
        "stroke_code_left_mca",
        TITLE,
        p,
        "George Adeyemi (patient id PW-ST01), 67, arrives by ambulance at 14:00: sudden right-sided weakness and loss "
        "of speech, last known well at 13:10. " + PROTOCOL,
        patients,
        [_triage(p.patient_id, deficits), _workup(p.patient_id), _lysis(p.patient_id, 73.8)],
        "What total dose of alteplase did you prescribe, in mg?",
        "73.8 mg",
        ["73.8", "73.8 milligrams"],
        emergency="stroke",
    )


def heavy_patient() -> dict:
    p = Person(
        "PW-ST02",
        "Brenda Coleman",
        74,
        "female",
        112.0,
        165.0,
        conditions=("type 2 diabetes mellitus", "obesity", "hypertension"),
        meds=(
            Med("metformin", 1000, "mg", "PO", "twice daily", "type 2 diabetes"),
            Med("amlodipine", 10, "mg", "PO", "once daily", "hypertension"),
            Med("simvastatin", 20, "mg", "PO", "once daily", "cardiovascular prevention"),
        ),
        creatinine_mg_dl=0.9,
    )
    v = [vitals("2025-03-01T13:55", 90, 172, 88, 18, 36.9, 95, gcs=(4, 4, 6))]
    deficits = "left face and arm weakness, left visual field loss, dysarthria"
    patients = {
        "triage_emergency": triage_record(
            p,
            arrival_mode="ambulance",
            chief_complaint="left arm weakness and slurred speech",
            history="Collapsed in the supermarket at 13:20 with a weak left arm and slurred speech; was well at 13:15 "
            "talking to the cashier. Diabetic on metformin; amlodipine; simvastatin.",
            vitals_rows=v,
            held={"glucose": (176.0, "mg/dL")},
            last_known_well="13:15",
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Left arm weakness and dysarthria since 13:20",
            hpi="Last known well 13:15. Left face and arm weakness, dysarthria and left homonymous hemianopia; stroke "
            "code activated; CT head at 14:18.",
            exam={
                "neurologic": "Dysarthria, left facial droop, left arm 2/5, left leg 4/5, left homonymous "
                "hemianopia, left-sided neglect; NIHSS 11"
            },
            vitals_rows=v,
            findings=[HEMIPARESIS, DYSARTHRIA, FACIAL_PALSY, HEMIANOPIA],
            labs=[
                _ct(
                    "non-contrast CT head: no haemorrhage; subtle loss of grey-white differentiation in the right "
                    "insular cortex; ASPECTS 9"
                )
            ],
            hidden={
                "inr": (1.1, "ratio", 20),
                "platelets": (268.0, "10^3/uL", 20),
                "glucose": (176.0, "mg/dL", 20),
            },
        ),
        "drug_interaction": pharmacy_record(p, notes="Acute right MCA ischaemic stroke; weight 112 kg."),
    }
    workup = _workup(p.patient_id)
    workup["required_actions"][-1] = act(
        "record_diagnosis", patient_id=p.patient_id, icd10_code="I63.511", certainty="confirmed"
    )
    return pathway(
        "stroke_code_weight_cap",
        TITLE,
        p,
        "Brenda Coleman (patient id PW-ST02), 74, arrives by ambulance at 14:00 with left arm weakness and slurred "
        "speech since 13:20 (last known well 13:15). She weighs 112 kg. " + PROTOCOL,
        patients,
        [_triage(p.patient_id, deficits), workup, _lysis(p.patient_id, 90)],
        "What total dose of alteplase did you prescribe, in mg?",
        "90 mg",
        ["90", "90 milligrams"],
        emergency="stroke",
    )


def on_warfarin() -> dict:
    p = Person(
        "PW-ST03",
        "Arthur Lindqvist",
        81,
        "male",
        76.0,
        174.0,
        conditions=("atrial fibrillation", "hypertension", "heart failure with preserved ejection fraction"),
        meds=(
            Med("warfarin", 4, "mg", "PO", "once daily", "stroke prevention in atrial fibrillation"),
            Med("bisoprolol", 5, "mg", "PO", "once daily", "rate control"),
            Med("furosemide", 40, "mg", "PO", "once daily", "heart failure"),
        ),
        creatinine_mg_dl=1.2,
    )
    v = [vitals("2025-03-01T13:58", 96, 164, 90, 18, 36.8, 95, gcs=(4, 2, 6))]
    deficits = "right hemiplegia, global aphasia and left gaze deviation"
    patients = {
        "triage_emergency": triage_record(
            p,
            arrival_mode="ambulance",
            chief_complaint="sudden right-sided paralysis, unable to speak",
            history="Last seen well at 13:30 by his carer; found at 13:40 unable to speak or move his right side. "
            "Atrial fibrillation on warfarin; bisoprolol; furosemide.",
            vitals_rows=v,
            held={"glucose": (142.0, "mg/dL")},
            last_known_well="13:30",
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Right hemiplegia and global aphasia",
            hpi="Last known well 13:30; right hemiplegia, global aphasia, left gaze deviation. Takes warfarin for AF; "
            "CT head and CT angiography at 14:18.",
            exam={
                "neurologic": "Global aphasia, left gaze deviation, dense right hemiplegia; NIHSS 21",
                "cardiovascular": "Irregularly irregular pulse",
            },
            vitals_rows=v,
            findings=[HEMIPARESIS, APHASIA, FACIAL_PALSY],
            labs=[
                _ct(
                    "non-contrast CT head: no haemorrhage, ASPECTS 8; CT angiography: occlusion of the left M1 "
                    "middle cerebral artery"
                )
            ],
            hidden={
                "inr": (2.8, "ratio", 20),
                "platelets": (198.0, "10^3/uL", 20),
                "glucose": (142.0, "mg/dL", 20),
            },
        ),
        "drug_interaction": pharmacy_record(p, notes="Acute left MCA occlusion on warfarin."),
    }
    workup = _workup(
        p.patient_id,
        [
            act(
                "escalate_care",
                ["patient_id", "team"],
                patient_id=p.patient_id,
                team="other",
                reason="left M1 occlusion, INR 2.8 excludes alteplase: refer for mechanical thrombectomy",
            )
        ],
        "Refers for mechanical thrombectomy because the large-vessel occlusion is treatable without "
        "alteplase",
    )
    hold = phase(
        "thrombolysis",
        "drug_interaction",
        "Decide on IV alteplase given his anticoagulation, and manage the anticoagulant.",
        [
            act("get_patient_medications", patient_id=p.patient_id),
            act(
                "check_patient_interactions",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="alteplase",
            ),
            act(
                "discontinue_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="warfarin",
                reason="acute large-vessel ischaemic stroke: INR 2.8, anticoagulation held around thrombectomy",
            ),
        ],
        [
            "Does not give alteplase because the INR of 2.8 is above 1.7",
            "Holds warfarin while the thrombectomy is arranged",
        ],
        max_calls=5,
    )
    return pathway(
        "stroke_code_anticoagulated",
        TITLE,
        p,
        "Arthur Lindqvist (patient id PW-ST03), 81, arrives by ambulance at 14:00 unable to speak or move his right "
        "side, last known well at 13:30. He takes warfarin. " + PROTOCOL,
        patients,
        [_triage(p.patient_id, deficits), workup, hold],
        "Did you give IV alteplase? Answer yes or no.",
        "no",
        ["no alteplase", "not given"],
        emergency="stroke",
    )


def hypertensive_before_lysis() -> dict:
    p = Person(
        "PW-ST04",
        "Nadia Haddad",
        59,
        "female",
        64.0,
        162.0,
        conditions=("hypertension", "migraine"),
        meds=(
            Med("amlodipine", 5, "mg", "PO", "once daily", "hypertension"),
            Med("sumatriptan", 50, "mg", "PO", "as needed", "migraine"),
        ),
        creatinine_mg_dl=0.8,
    )
    v = [vitals("2025-03-01T13:56", 88, 198, 114, 16, 36.6, 98, gcs=(4, 4, 6))]
    deficits = "left arm and leg weakness with left facial droop and slurred speech"
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="left-sided weakness since lunchtime",
            history="Brought by her son: at 12:50 she suddenly could not lift her left arm and her speech slurred; she "
            "was well at 12:45. No headache. Hypertension on amlodipine; sumatriptan last taken 3 weeks ago.",
            vitals_rows=v,
            held={"glucose": (104.0, "mg/dL")},
            last_known_well="12:45",
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Left-sided weakness and dysarthria since 12:50",
            hpi="Last known well 12:45. Left arm and leg weakness, left facial droop, dysarthria. Blood pressure "
            "198/114 at triage. CT head at 14:18.",
            exam={"neurologic": "Dysarthria, left facial droop, left arm 2/5, left leg 3/5; NIHSS 9"},
            vitals_rows=v,
            findings=[HEMIPARESIS, DYSARTHRIA, FACIAL_PALSY],
            labs=[_ct("non-contrast CT head: no haemorrhage, no established infarct; ASPECTS 10")],
            hidden={
                "inr": (1.0, "ratio", 20),
                "platelets": (301.0, "10^3/uL", 20),
                "glucose": (104.0, "mg/dL", 20),
            },
        ),
        "drug_interaction": pharmacy_record(p, notes="Acute right hemispheric ischaemic stroke; BP 198/114."),
    }
    workup = _workup(p.patient_id)
    workup["required_actions"][-1] = act(
        "record_diagnosis", patient_id=p.patient_id, icd10_code="I63.511", certainty="confirmed"
    )
    lower_bp = [
        act("get_dose_range", ["drug", "patient_id"], drug="labetalol", route="IV", patient_id=p.patient_id),
        act(
            "add_medication",
            ["patient_id", "drug"],
            patient_id=p.patient_id,
            drug="labetalol",
            dose=20,
            unit="mg",
            route="IV",
            frequency="once over 2 minutes, may repeat once",
            indication="blood pressure 198/114 above the 185/110 thrombolysis limit; recheck in 10 minutes",
        ),
    ]
    lysis = _lysis(p.patient_id, 57.6, lower_bp)
    lysis["max_calls"] = 8
    lysis["nl_assertions"].insert(
        0, "Lowers the blood pressure below 185/110 with IV labetalol before alteplase"
    )
    return pathway(
        "stroke_code_blood_pressure",
        TITLE,
        p,
        "Nadia Haddad (patient id PW-ST04), 59, is brought to the emergency department at 14:00 with left-sided "
        "weakness since 12:50 (last known well 12:45). " + PROTOCOL,
        patients,
        [_triage(p.patient_id, deficits), workup, lysis],
        "What total dose of alteplase did you prescribe, in mg?",
        "57.6 mg",
        ["57.6", "57.6 milligrams"],
        emergency="stroke",
    )


def pathways() -> list[dict]:
    return [left_mca(), heavy_patient(), on_warfarin(), hypertensive_before_lysis()]
