"""Post-operative complication: ward deterioration read from the inpatient record (vital-sign and lab
trends, NEWS2, escalation) -> bedside diagnostic work-up -> medication changes in the pharmacy tools
-> documented handover, which the agent declares complete."""

from __future__ import annotations

from .records import (
    Admission,
    Med,
    Person,
    act,
    clinical_record,
    ehr_record,
    ehr_vitals,
    finding,
    pathway,
    pharmacy_record,
    phase,
    vitals,
)

TITLE = "Post-operative complication"
NOW = "2025-03-05T08:00"
BEDSIDE = "2025-03-05T08:15"


def _ward(pid: str, reads: list[dict], team: str, reason: str) -> dict:
    actions = [
        act("get_patient_timeline", patient_id=pid),
        *reads,
        act("calculate_news2", patient_id=pid),
        act("escalate_care", ["patient_id", "team"], patient_id=pid, team=team, reason=reason),
    ]
    return phase(
        "ward deterioration",
        "ehr_management",
        "The night team flags a deteriorating post-operative patient: read the trends in the record, score "
        "NEWS2 and escalate to the right team.",
        actions,
        [
            "Reads the vital-sign and laboratory trends rather than a single value",
            "Calculates NEWS2 from the latest charted observations",
            "Escalates immediately to the appropriate team with the score and the suspected complication",
        ],
        max_calls=len(actions) + 2,
    )


def _handover(pid: str, summary: str) -> dict:
    return phase(
        "handover",
        "ehr_management",
        "Write the event note in the record (what happened, what was found, what was done, the plan) and "
        "declare the handover complete.",
        [
            act(
                "write_clinical_note",
                ["patient_id", "note_type"],
                patient_id=pid,
                note_type="event",
                text=summary,
            )
        ],
        ["Documents the event, the diagnosis, the medication changes and the monitoring plan"],
        transition="agent_declares",
    )


def pe_after_hip_replacement() -> dict:
    p = Person(
        "PW-PO01",
        "Janet Morley",
        68,
        "female",
        80.0,
        163.0,
        conditions=("osteoarthritis of the left hip", "hypertension"),
        meds=(Med("amlodipine", 5, "mg", "PO", "once daily", "hypertension"),),
        creatinine_mg_dl=0.9,
    )
    adm = Admission(
        "PW-PO01-A1",
        "2025-03-02T07:00",
        "Elective left total hip replacement for osteoarthritis",
        icd10_codes=["M16.12"],
        orders=[
            (
                Med("enoxaparin", 40, "mg", "SC", "once daily", "VTE prophylaxis after hip replacement"),
                "2025-03-02T18:00",
            ),
            (
                Med("acetaminophen", 1000, "mg", "PO", "every 6 hours", "post-operative analgesia"),
                "2025-03-02T12:00",
            ),
            (
                Med("oxycodone", 5, "mg", "PO", "every 4 hours as needed", "breakthrough pain"),
                "2025-03-02T12:00",
            ),
        ],
        labs=[
            ("2025-03-02T12:00", "hemoglobin", 12.4, "g/dL"),
            ("2025-03-03T06:00", "hemoglobin", 11.3, "g/dL"),
            ("2025-03-05T06:00", "hemoglobin", 11.0, "g/dL"),
            ("2025-03-02T12:00", "creatinine", 0.8, "mg/dL"),
            ("2025-03-03T06:00", "creatinine", 0.8, "mg/dL"),
            ("2025-03-05T06:00", "creatinine", 0.9, "mg/dL"),
        ],
        vitals=[
            ehr_vitals("2025-03-02T12:00", 78, 132, 78, 14, 36.8, 97),
            ehr_vitals("2025-03-03T08:00", 80, 128, 76, 16, 37.1, 96),
            ehr_vitals("2025-03-04T08:00", 84, 126, 74, 16, 37.2, 96),
            ehr_vitals("2025-03-04T20:00", 96, 122, 76, 20, 37.4, 94),
            ehr_vitals("2025-03-05T06:00", 118, 108, 70, 26, 37.6, 89),
        ],
        notes=[
            (
                "2025-03-02T11:30",
                "progress",
                (
                    "Uncomplicated left THR under spinal anaesthesia; enoxaparin "
                    "prophylaxis from 18:00; mobilise day 1."
                ),
            )
        ],
    )
    v = [vitals("2025-03-05T08:10", 120, 106, 68, 28, 37.6, 89, pain=5)]
    patients = {
        "ehr_management": ehr_record(p, adm),
        "clinical_diagnosis": clinical_record(
            p,
            setting="ward",
            chief_complaint="Sudden breathlessness on post-operative day 3",
            hpi="Day 3 after left total hip replacement on prophylactic enoxaparin; since 05:00 breathless with "
            "right-sided pleuritic chest pain; SpO2 89% on air, heart rate 118.",
            exam={
                "general": "Anxious, tachypnoeic",
                "lungs": "Clear, no crackles",
                "cardiovascular": "Tachycardic, JVP not raised",
                "extremities": "Left calf swollen and tender",
            },
            vitals_rows=v,
            inpatient=adm.inpatient_meds,
            encounter_time=BEDSIDE,
            findings=[
                finding("HP:0002094", "Dyspnea"),
                finding("HP:0033771", "Pleuritic chest pain"),
                finding("HP:0001649", "Tachycardia", "exam"),
                finding("HP:0012418", "Hypoxemia", "exam"),
                finding("HP:0033106", "Elevated circulating D-dimer concentration", "lab", "d_dimer"),
            ],
            hidden={
                "ctpa": (
                    (
                        "filling defects in the right lower lobe segmental and subsegmental arteries; RV:LV ratio "
                        "0.8, no right heart strain"
                    ),
                    "text",
                    60,
                ),
                "d_dimer": (4.2, "mg/L FEU", 45),
                "troponin_i": (11.0, "ng/L", 45),
                "leg_doppler": (
                    "occlusive thrombus in the left popliteal and superficial femoral veins",
                    "text",
                    60,
                ),
            },
        ),
        "drug_interaction": pharmacy_record(
            p,
            inpatient=adm.inpatient_meds,
            notes="Post-operative day 3 after left THR; prophylactic enoxaparin.",
        ),
    }
    work = phase(
        "bedside work-up",
        "clinical_diagnosis",
        "Confirm or exclude the suspected complication with imaging and record the diagnosis.",
        [
            act("get_patient_info", patient_id=p.patient_id),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="ctpa",
                priority="stat",
                indication="suspected pulmonary embolism after hip replacement",
            ),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="troponin_i",
                priority="stat",
            ),
            act(
                "record_diagnosis",
                ["patient_id", "icd10_code"],
                patient_id=p.patient_id,
                icd10_code="I26.99",
                certainty="confirmed",
            ),
        ],
        [
            "Confirms pulmonary embolism on CT pulmonary angiography",
            "Risk-stratifies with troponin and the right-ventricle findings",
            "Records pulmonary embolism without acute cor pulmonale, I26.99",
        ],
    )
    drugs = phase(
        "anticoagulation",
        "drug_interaction",
        "Change the prophylactic enoxaparin to a treatment dose suited to her weight and renal function.",
        [
            act("get_patient_details", patient_id=p.patient_id),
            act("calculate_renal_function", patient_id=p.patient_id),
            act(
                "adjust_medication_dose",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="enoxaparin",
                dose=80,
                unit="mg",
                frequency="every 12 hours",
                reason="pulmonary embolism: treatment dose 1 mg/kg, CrCl normal",
            ),
        ],
        [
            "Uses 1 mg/kg every 12 hours after checking the creatinine clearance",
            "Does not add a second anticoagulant on top of the enoxaparin",
        ],
        max_calls=5,
    )
    return pathway(
        "postop_pulmonary_embolism",
        TITLE,
        p,
        "Ward call at 08:00: Janet Morley (patient id PW-PO01), 68, day 3 after a left total hip replacement, has "
        "become breathless and hypoxic overnight.",
        patients,
        [
            _ward(
                p.patient_id,
                [act("get_vital_trend", ["patient_id", "vital"], patient_id=p.patient_id, vital="spo2")],
                "rapid_response",
                "suspected pulmonary embolism day 3 after hip replacement: NEWS2 9, SpO2 89%",
            ),
            work,
            drugs,
            _handover(
                p.patient_id,
                "Day 3 left THR: acute PE confirmed on CTPA (right lower lobe segmental), no RV "
                "strain, troponin normal. Enoxaparin increased to 80 mg every 12 hours. NEWS2 9 "
                "at 06:00, reviewed by the rapid response team; hourly observations.",
            ),
        ],
        "What NEWS2 score did the record give at the time of the call?",
        "9",
        ["NEWS2 9", "NEWS2 score 9"],
        emergency="pulmonary_embolism",
    )


def anastomotic_leak() -> dict:
    p = Person(
        "PW-PO02",
        "Rashid Karim",
        57,
        "male",
        82.0,
        176.0,
        conditions=("rectal adenocarcinoma", "type 2 diabetes mellitus"),
        meds=(
            Med("metformin", 500, "mg", "PO", "twice daily", "type 2 diabetes"),
            Med("atorvastatin", 20, "mg", "PO", "once daily", "cardiovascular prevention"),
        ),
        creatinine_mg_dl=1.4,
    )
    adm = Admission(
        "PW-PO02-A1",
        "2025-02-28T07:30",
        "Laparoscopic anterior resection for rectal cancer",
        icd10_codes=["C20"],
        orders=[
            (Med("enoxaparin", 40, "mg", "SC", "once daily", "VTE prophylaxis"), "2025-02-28T18:00"),
            (
                Med("acetaminophen", 1000, "mg", "IV", "every 6 hours", "post-operative analgesia"),
                "2025-02-28T14:00",
            ),
        ],
        labs=[
            ("2025-03-01T06:00", "crp", 62.0, "mg/L"),
            ("2025-03-03T06:00", "crp", 148.0, "mg/L"),
            ("2025-03-05T06:00", "crp", 276.0, "mg/L"),
            ("2025-03-01T06:00", "wbc", 11.2, "10^3/uL"),
            ("2025-03-03T06:00", "wbc", 14.6, "10^3/uL"),
            ("2025-03-05T06:00", "wbc", 19.8, "10^3/uL"),
            ("2025-03-01T06:00", "creatinine", 0.9, "mg/dL"),
            ("2025-03-03T06:00", "creatinine", 1.0, "mg/dL"),
            ("2025-03-05T06:00", "creatinine", 1.4, "mg/dL"),
        ],
        vitals=[
            ehr_vitals("2025-02-28T14:00", 82, 130, 80, 16, 36.9, 97),
            ehr_vitals("2025-03-02T08:00", 88, 126, 78, 18, 37.4, 96),
            ehr_vitals("2025-03-03T08:00", 96, 120, 74, 20, 37.9, 96),
            ehr_vitals("2025-03-04T08:00", 108, 112, 66, 22, 38.4, 95),
            ehr_vitals("2025-03-05T06:00", 124, 98, 58, 26, 38.9, 94),
        ],
        notes=[
            (
                "2025-02-28T13:00",
                "progress",
                "Laparoscopic anterior resection, stapled colorectal anastomosis, no defunctioning stoma.",
            )
        ],
    )
    v = [vitals("2025-03-05T08:10", 126, 96, 56, 26, 38.9, 94, pain=8)]
    patients = {
        "ehr_management": ehr_record(p, adm),
        "clinical_diagnosis": clinical_record(
            p,
            setting="ward",
            chief_complaint="Fever, abdominal pain and tachycardia on post-operative day 5",
            hpi="Day 5 after laparoscopic anterior resection with a stapled anastomosis; increasing abdominal pain, "
            "fever and tachycardia over 48 hours; CRP rising daily.",
            exam={
                "abdomen": "Distended, generalised tenderness with guarding, worst in the left iliac fossa",
                "general": "Flushed, sweaty",
                "cardiovascular": "Tachycardic",
            },
            vitals_rows=v,
            inpatient=adm.inpatient_meds,
            encounter_time=BEDSIDE,
            findings=[
                finding("HP:0001945", "Fever"),
                finding("HP:0002027", "Abdominal pain"),
                finding("HP:0001649", "Tachycardia", "exam"),
                finding("HP:0002586", "Peritonitis", "exam"),
                finding("HP:0011227", "Elevated circulating C-reactive protein concentration", "lab", "crp"),
            ],
            hidden={
                "ct_abdomen": (
                    (
                        "extraluminal gas and a 6 cm rim-enhancing pelvic collection at the colorectal "
                        "anastomosis: anastomotic leak"
                    ),
                    "text",
                    60,
                ),
                "crp": (276.0, "mg/L", 45),
                "lactate": (3.4, "mmol/L", 20),
                "blood_culture": ("pending at 24 h", "text", 1440),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, inpatient=adm.inpatient_meds, notes="Post-operative day 5 after anterior resection; sepsis."
        ),
    }
    work = phase(
        "bedside work-up",
        "clinical_diagnosis",
        "Find the source: imaging, cultures before antibiotics and lactate; record the diagnosis.",
        [
            act("get_patient_info", patient_id=p.patient_id),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="blood_culture",
                priority="stat",
            ),
            act(
                "order_lab", ["patient_id", "test"], patient_id=p.patient_id, test="lactate", priority="stat"
            ),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="ct_abdomen",
                priority="stat",
                indication="suspected anastomotic leak",
            ),
            act("record_diagnosis", patient_id=p.patient_id, icd10_code="K65.0", certainty="confirmed"),
        ],
        ["Takes blood cultures before antibiotics", "Identifies an anastomotic leak with peritonitis on CT"],
    )
    drugs = phase(
        "antimicrobials and medicines",
        "drug_interaction",
        "Start broad-spectrum antibiotics and stop any home medicine that is unsafe in sepsis with a rising creatinine.",
        [
            act(
                "check_allergy",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="piperacillin and tazobactam",
            ),
            act(
                "check_patient_interactions",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="piperacillin and tazobactam",
            ),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="piperacillin and tazobactam",
                dose=4.5,
                unit="g",
                route="IV",
                frequency="every 6 hours",
                indication="anastomotic leak with sepsis",
            ),
            act(
                "discontinue_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="metformin",
                reason="sepsis with lactate 3.4, rising creatinine and iodinated contrast",
            ),
        ],
        ["Starts antibiotics within one hour of recognising sepsis", "Stops metformin"],
        max_calls=6,
    )
    return pathway(
        "postop_anastomotic_leak",
        TITLE,
        p,
        "Ward call at 08:00: Rashid Karim (patient id PW-PO02), 57, day 5 after a laparoscopic anterior resection, "
        "is febrile, tachycardic and in increasing abdominal pain.",
        patients,
        [
            _ward(
                p.patient_id,
                [
                    act(
                        "get_vital_trend",
                        ["patient_id", "vital"],
                        patient_id=p.patient_id,
                        vital="heart_rate",
                    ),
                    act("get_lab_trend", ["patient_id", "test"], patient_id=p.patient_id, test="crp"),
                ],
                "general_surgery",
                "suspected anastomotic leak with sepsis on day 5: NEWS2 9, CRP 276 and rising",
            ),
            work,
            drugs,
            _handover(
                p.patient_id,
                "Day 5 anterior resection: anastomotic leak with pelvic collection on CT, sepsis "
                "(lactate 3.4). Blood cultures taken, piperacillin-tazobactam started, metformin "
                "stopped; general surgical team planning return to theatre.",
            ),
        ],
        "By how much did the CRP change over the admission, in mg/L, according to the lab trend?",
        "214 mg/L",
        ["214", "+214", "214 mg/l", "rose by 214 mg/L"],
        emergency="sepsis",
    )


def haemorrhage_after_knee_replacement() -> dict:
    p = Person(
        "PW-PO03",
        "Dennis Hale",
        71,
        "male",
        82.0,
        178.0,
        conditions=("osteoarthritis of the right knee", "ischaemic heart disease", "hypertension"),
        meds=(
            Med("aspirin", 75, "mg", "PO", "once daily", "ischaemic heart disease"),
            Med("ramipril", 5, "mg", "PO", "once daily", "hypertension"),
        ),
        creatinine_mg_dl=1.3,
    )
    adm = Admission(
        "PW-PO03-A1",
        "2025-03-04T07:30",
        "Elective right total knee replacement for osteoarthritis",
        icd10_codes=["M17.11"],
        orders=[
            (Med("enoxaparin", 40, "mg", "SC", "once daily", "VTE prophylaxis"), "2025-03-04T18:00"),
            (
                Med("ketorolac", 15, "mg", "IV", "every 6 hours", "post-operative analgesia"),
                "2025-03-04T12:00",
            ),
            (
                Med("acetaminophen", 1000, "mg", "PO", "every 6 hours", "post-operative analgesia"),
                "2025-03-04T12:00",
            ),
        ],
        labs=[
            ("2025-03-04T07:00", "hemoglobin", 13.6, "g/dL"),
            ("2025-03-04T20:00", "hemoglobin", 11.4, "g/dL"),
            ("2025-03-05T05:00", "hemoglobin", 8.2, "g/dL"),
            ("2025-03-04T07:00", "creatinine", 1.0, "mg/dL"),
            ("2025-03-05T05:00", "creatinine", 1.3, "mg/dL"),
        ],
        vitals=[
            ehr_vitals("2025-03-04T12:00", 76, 138, 82, 14, 36.7, 97),
            ehr_vitals("2025-03-04T20:00", 88, 124, 76, 16, 36.9, 96),
            ehr_vitals("2025-03-05T02:00", 104, 108, 64, 18, 37.0, 96),
            ehr_vitals("2025-03-05T06:00", 124, 88, 52, 22, 36.4, 95),
        ],
        notes=[("2025-03-04T11:00", "progress", "Right TKR, tourniquet time 78 min, drain in situ.")],
    )
    v = [vitals("2025-03-05T08:10", 126, 86, 50, 22, 36.4, 95, pain=7)]
    patients = {
        "ehr_management": ehr_record(p, adm),
        "clinical_diagnosis": clinical_record(
            p,
            setting="ward",
            chief_complaint="Hypotension and tachycardia on post-operative day 1",
            hpi="Day 1 after right total knee replacement; on aspirin, prophylactic enoxaparin and IV ketorolac; "
            "drain output 900 mL overnight; haemoglobin 13.6 -> 8.2 g/dL.",
            exam={
                "knee": "Tense swollen right thigh and knee, wound oozing, drain full of fresh blood",
                "general": "Pale, clammy",
                "cardiovascular": "Tachycardic, cool peripheries",
            },
            vitals_rows=v,
            inpatient=adm.inpatient_meds,
            encounter_time=BEDSIDE,
            findings=[
                finding("HP:0001903", "Anemia", "lab", "hemoglobin"),
                finding("HP:0001649", "Tachycardia", "exam"),
                finding("HP:0002615", "Hypotension", "exam"),
            ],
            hidden={
                "hemoglobin": (7.6, "g/dL", 20),
                "platelets": (188.0, "10^3/uL", 20),
                "inr": (1.1, "ratio", 30),
                "ptt": (31.0, "s", 30),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, inpatient=adm.inpatient_meds, notes="Post-operative day 1 after right TKR; bleeding."
        ),
    }
    work = phase(
        "bedside work-up",
        "clinical_diagnosis",
        "Examine the surgical site, repeat the haemoglobin, check coagulation and record the diagnosis.",
        [
            act("get_physical_exam", patient_id=p.patient_id),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="hemoglobin",
                priority="stat",
            ),
            act("order_lab", ["patient_id", "test"], patient_id=p.patient_id, test="inr", priority="stat"),
            act(
                "record_diagnosis",
                ["patient_id", "icd10_code"],
                patient_id=p.patient_id,
                icd10_code="D62",
                certainty="confirmed",
            ),
        ],
        ["Finds the bleeding source at the operated knee", "Records acute posthaemorrhagic anaemia, D62"],
    )
    drugs = phase(
        "medication changes",
        "drug_interaction",
        "Stop the drugs that add to the bleeding and give tranexamic acid at the weight-based dose.",
        [
            act("check_allergy", ["patient_id", "drug"], patient_id=p.patient_id, drug="tranexamic acid"),
            act(
                "check_patient_interactions",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="tranexamic acid",
            ),
            act(
                "discontinue_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="enoxaparin",
                reason="active post-operative haemorrhage",
            ),
            act(
                "discontinue_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="ketorolac",
                reason="NSAID antiplatelet effect during haemorrhage; creatinine rising",
            ),
            act("get_dose_range", ["drug", "patient_id"], drug="tranexamic acid", patient_id=p.patient_id),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="tranexamic acid",
                dose=1000,
                unit="mg",
                route="IV",
                frequency="once over 10 minutes",
                indication="post-operative haemorrhage",
            ),
        ],
        [
            "Stops enoxaparin and ketorolac",
            "Gives tranexamic acid 1000 mg (15 mg/kg capped at 1 g)",
            "Arranges blood transfusion and surgical review of the knee",
        ],
        max_calls=7,
    )
    return pathway(
        "postop_haemorrhage",
        TITLE,
        p,
        "Ward call at 08:00: Dennis Hale (patient id PW-PO03), 71, day 1 after a right total knee replacement, is "
        "hypotensive and tachycardic with a full drain.",
        patients,
        [
            _ward(
                p.patient_id,
                [
                    act("get_lab_trend", ["patient_id", "test"], patient_id=p.patient_id, test="hemoglobin"),
                    act(
                        "get_vital_trend",
                        ["patient_id", "vital"],
                        patient_id=p.patient_id,
                        vital="systolic_bp",
                    ),
                ],
                "rapid_response",
                "post-operative haemorrhage with shock: Hb 13.6 -> 8.2, SBP 88, NEWS2 8",
            ),
            work,
            drugs,
            _handover(
                p.patient_id,
                "Day 1 right TKR: haemorrhage into the knee, Hb 7.6, SBP 86. Enoxaparin and "
                "ketorolac stopped, tranexamic acid 1 g given, 2 units red cells requested, "
                "orthopaedic registrar reviewing; 15-minute observations.",
            ),
        ],
        "What dose of tranexamic acid did you give, in mg?",
        "1000 mg",
        ["1000", "1 g", "1g", "1000mg"],
        emergency="other",
    )


def aki_hyperkalaemia() -> dict:
    p = Person(
        "PW-PO04",
        "Gloria Mendes",
        74,
        "female",
        66.0,
        160.0,
        conditions=("heart failure with reduced ejection fraction", "hypertension"),
        meds=(
            Med("lisinopril", 20, "mg", "PO", "once daily", "heart failure"),
            Med("spironolactone", 25, "mg", "PO", "once daily", "heart failure"),
            Med("bisoprolol", 2.5, "mg", "PO", "once daily", "heart failure"),
        ),
        creatinine_mg_dl=2.7,
    )
    adm = Admission(
        "PW-PO04-A1",
        "2025-03-03T02:00",
        "Emergency laparotomy for adhesional small bowel obstruction",
        admission_type="emergency",
        icd10_codes=["K56.50"],
        orders=[
            (
                Med("potassium chloride", 20, "mEq", "IV", "every 8 hours", "maintenance fluids"),
                "2025-03-03T08:00",
            ),
            (Med("enoxaparin", 40, "mg", "SC", "once daily", "VTE prophylaxis"), "2025-03-03T18:00"),
            (
                Med("acetaminophen", 1000, "mg", "IV", "every 6 hours", "post-operative analgesia"),
                "2025-03-03T08:00",
            ),
        ],
        labs=[
            ("2025-03-03T06:00", "creatinine", 0.9, "mg/dL"),
            ("2025-03-04T06:00", "creatinine", 1.6, "mg/dL"),
            ("2025-03-05T06:00", "creatinine", 2.7, "mg/dL"),
            ("2025-03-03T06:00", "potassium", 4.6, "mmol/L"),
            ("2025-03-04T06:00", "potassium", 5.8, "mmol/L"),
            ("2025-03-05T06:00", "potassium", 6.9, "mmol/L"),
        ],
        vitals=[
            ehr_vitals("2025-03-03T08:00", 84, 118, 70, 16, 37.0, 96, urine_ml=240),
            ehr_vitals("2025-03-04T08:00", 76, 110, 64, 16, 36.9, 96, urine_ml=310),
            ehr_vitals("2025-03-05T06:00", 54, 102, 60, 18, 36.8, 96, urine_ml=90),
        ],
        notes=[
            (
                "2025-03-03T04:00",
                "progress",
                (
                    "Laparotomy and adhesiolysis, no bowel resection. Home lisinopril and "
                    "spironolactone continued post-operatively."
                ),
            )
        ],
    )
    v = [vitals("2025-03-05T08:10", 54, 100, 58, 18, 36.8, 96, pain=3)]
    patients = {
        "ehr_management": ehr_record(p, adm),
        "clinical_diagnosis": clinical_record(
            p,
            setting="ward",
            chief_complaint="Potassium 6.9 and falling urine output on post-operative day 2",
            hpi="Day 2 after emergency laparotomy; lisinopril and spironolactone continued and potassium chloride in "
            "the maintenance fluids; urine output 90 mL overnight; creatinine 0.9 -> 2.7 mg/dL.",
            exam={
                "general": "Weak, alert",
                "cardiovascular": "Bradycardic 54/min, regular",
                "abdomen": "Soft wound",
            },
            vitals_rows=v,
            inpatient=adm.inpatient_meds,
            encounter_time=BEDSIDE,
            findings=[
                finding("HP:0002153", "Hyperkalemia", "lab", "potassium"),
                finding("HP:0100520", "Oliguria", "exam"),
                finding("HP:0003259", "Elevated circulating creatinine concentration", "lab", "creatinine"),
            ],
            hidden={
                "potassium": (6.9, "mmol/L", 15),
                "creatinine": (2.7, "mg/dL", 20),
                "ecg": ("sinus bradycardia 54/min, PR 220 ms, tall peaked T waves V2-V5", "text", 10),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, inpatient=adm.inpatient_meds, notes="Post-operative AKI with potassium 6.9 mmol/L."
        ),
    }
    work = phase(
        "bedside work-up",
        "clinical_diagnosis",
        "Repeat the potassium, get an ECG for hyperkalaemic changes and record the diagnosis.",
        [
            act("get_patient_info", patient_id=p.patient_id),
            act("order_lab", ["patient_id", "test"], patient_id=p.patient_id, test="ecg", priority="stat"),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="potassium",
                priority="stat",
            ),
            act(
                "record_diagnosis",
                ["patient_id", "icd10_code"],
                patient_id=p.patient_id,
                icd10_code="E87.5",
                certainty="confirmed",
            ),
        ],
        [
            "Recognises ECG changes of hyperkalaemia",
            "Records hyperkalaemia, E87.5, with the acute kidney injury",
        ],
    )
    drugs = phase(
        "emergency treatment and medicines",
        "drug_interaction",
        "Protect the heart and shift potassium now, then stop every drug that raises potassium or harms the "
        "kidney.",
        [
            act("check_patient_interactions", patient_id=p.patient_id),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="calcium gluconate",
                dose=1,
                unit="g",
                route="IV",
                frequency="once over 10 minutes, repeat if ECG changes persist",
                indication="hyperkalaemia 6.9 with ECG changes: cardiac membrane stabilisation, cardiac monitor",
            ),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="insulin human",
                dose=10,
                unit="units",
                route="IV",
                frequency="once with 25 g glucose",
                indication="hyperkalaemia: potassium shift; capillary glucose hourly for 6 hours",
            ),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="glucose",
                dose=25,
                unit="g",
                route="IV",
                frequency="once with the insulin",
                indication="prevent hypoglycaemia after IV insulin",
            ),
            act(
                "discontinue_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="potassium chloride",
                reason="potassium 6.9",
            ),
            act(
                "discontinue_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="spironolactone",
                reason="potassium 6.9 with AKI",
            ),
            act(
                "discontinue_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="lisinopril",
                reason="AKI (creatinine 2.7) with hyperkalaemia",
            ),
        ],
        [
            "Gives IV calcium first because of the ECG changes",
            "Gives insulin with glucose and monitors glucose",
            "Stops potassium chloride, spironolactone and lisinopril",
        ],
        max_calls=9,
    )
    return pathway(
        "postop_hyperkalaemia",
        TITLE,
        p,
        "Ward call at 08:00: Gloria Mendes (patient id PW-PO04), 74, day 2 after an emergency laparotomy, has a "
        "potassium of 6.9 mmol/L and has passed little urine overnight.",
        patients,
        [
            _ward(
                p.patient_id,
                [
                    act("get_lab_trend", ["patient_id", "test"], patient_id=p.patient_id, test="potassium"),
                    act("get_lab_trend", ["patient_id", "test"], patient_id=p.patient_id, test="creatinine"),
                ],
                "critical_care_outreach",
                "potassium 6.9 with bradycardia and oliguric AKI after laparotomy",
            ),
            work,
            drugs,
            _handover(
                p.patient_id,
                "Day 2 laparotomy: oliguric AKI (creatinine 0.9 -> 2.7) with potassium 6.9 and "
                "ECG changes. Calcium gluconate, insulin with glucose given; potassium chloride, "
                "spironolactone and lisinopril stopped; repeat potassium in 2 hours, renal review.",
            ),
        ],
        "By how much did the creatinine rise over the admission, in mg/dL, according to the lab trend?",
        "1.8 mg/dL",
        ["1.8", "+1.8", "1.8 mg/dl", "rose by 1.8 mg/dL"],
        emergency="hyperkalemia",
    )


def pathways() -> list[dict]:
    return [
        pe_after_hip_replacement(),
        anastomotic_leak(),
        haemorrhage_after_knee_replacement(),
        aki_hyperkalaemia(),
    ]
