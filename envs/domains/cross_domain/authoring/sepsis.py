"""Sepsis bundle: ED triage (sepsis screen, lactate, qSOFA/NEWS2/ESI, sepsis-team escalation) -> source
work-up (cultures before antibiotics, source imaging, coded diagnosis) -> antimicrobials checked in the
pharmacy tools (allergy, interactions, renal dose adjustment, weight-based dose)."""

from __future__ import annotations

from .records import (
    Allergy,
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

TITLE = "Sepsis bundle"
PROTOCOL = (
    "Sepsis antimicrobial protocol: piperacillin-tazobactam 4.5 g IV every 6 hours (renally adjusted); after "
    "anaphylaxis to a penicillin, aztreonam 2 g IV every 8 hours."
)

FEVER = finding("HP:0001945", "Fever")
TACHYCARDIA = finding("HP:0001649", "Tachycardia", "exam")
TACHYPNEA = finding("HP:0002789", "Tachypnea", "exam")
HYPOTENSION = finding("HP:0002615", "Hypotension", "exam")
LEUKOCYTOSIS = finding("HP:0001974", "Leukocytosis", "lab", "wbc")


def _triage(
    pid: str, tests: list[str], score: dict, esi: int, level: str, reason: str, *, presentation: bool = False
) -> dict:
    actions = [act("get_patient_presentation", patient_id=pid)] if presentation else []
    actions += [act("get_vital_signs", patient_id=pid)]
    actions += [
        act("order_point_of_care_test", ["patient_id", "test"], patient_id=pid, test=t) for t in tests
    ]
    actions += [
        act("screen_sepsis", patient_id=pid),
        score,
        act("escalate_care", ["patient_id", "level"], patient_id=pid, level=level, reason=reason),
        act(
            "assign_triage_level",
            ["patient_id", "esi_level"],
            patient_id=pid,
            esi_level=esi,
            rationale="suspected sepsis",
        ),
    ]
    return phase(
        "sepsis screen",
        "triage_emergency",
        "Screen for sepsis at the front door: vital signs, lactate, the sepsis screen and a severity score; "
        "escalate to the team the physiology calls for and assign the ESI level.",
        actions,
        [
            "Measures a lactate as part of the sepsis screen",
            "Escalates to the sepsis (or resuscitation) team within the first minutes",
            f"Assigns ESI level {esi}",
        ],
        max_calls=len(actions) + 2,
    )


def _cultures(
    pid: str,
    source_tests: list[str],
    code: str,
    compare_code: bool,
    diagnosis: str,
    extra: list | None = None,
) -> dict:
    record = act(
        "record_diagnosis",
        ["patient_id", "icd10_code"] if compare_code else ["patient_id"],
        patient_id=pid,
        icd10_code=code,
        certainty="provisional",
    )
    return phase(
        "source and cultures",
        "clinical_diagnosis",
        "Take blood cultures before the first antibiotic dose, look for the source and record the diagnosis.",
        [
            act("get_patient_info", patient_id=pid),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=pid,
                test="blood_culture",
                priority="stat",
                indication="sepsis: before antibiotics",
            ),
            *[
                act("order_lab", ["patient_id", "test"], patient_id=pid, test=t, priority="stat")
                for t in source_tests
            ],
            *(extra or []),
            record,
        ],
        [
            "Draws blood cultures before the antibiotics are given",
            "Identifies the likely source of infection",
            f"Records {diagnosis}",
        ],
    )


def urosepsis_allergy() -> dict:
    p = Person(
        "PW-SE01",
        "Irene Castillo",
        71,
        "female",
        64.0,
        158.0,
        conditions=("recurrent urinary tract infections", "hypertension", "osteoporosis"),
        meds=(
            Med("amlodipine", 5, "mg", "PO", "once daily", "hypertension"),
            Med("risedronate", 35, "mg", "PO", "once weekly", "osteoporosis"),
        ),
        allergies=(
            Allergy(
                "piperacillin-tazobactam",
                "anaphylaxis (2022 admission)",
                "severe",
                "piperacillin and tazobactam",
            ),
        ),
        creatinine_mg_dl=1.1,
    )
    v = [vitals("2025-03-01T13:54", 112, 96, 58, 24, 38.9, 95, pain=6)]
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="fever, rigors and right loin pain",
            history="Two days of burning urine, since this morning shaking chills and right loin pain; feels faint "
            "on standing. Anaphylaxis to piperacillin-tazobactam in 2022. Amlodipine, risedronate.",
            vitals_rows=v,
            held={"lactate": (3.1, "mmol/L"), "wbc": (17.2, "10^3/uL"), "glucose": (142.0, "mg/dL")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Fever, rigors and right loin pain",
            hpi="Dysuria for two days, rigors and right loin pain today; hypotensive and tachycardic at triage with "
            "lactate 3.1. Anaphylaxis to piperacillin-tazobactam (2022).",
            exam={
                "general": "Flushed, rigoring",
                "abdomen": "Right costovertebral angle tenderness",
                "cardiovascular": "Tachycardic, warm peripheries",
            },
            vitals_rows=v,
            findings=[
                FEVER,
                finding("HP:0030157", "Flank pain"),
                finding("HP:6000106", "Costovertebral angle tenderness", "exam"),
                finding("HP:0100518", "Dysuria"),
                finding("HP:0025145", "Rigors"),
                finding("HP:0012085", "Pyuria", "lab", "urine_wbc"),
                LEUKOCYTOSIS,
            ],
            hidden={
                "blood_culture": ("Gram-negative rods in 2 of 2 bottles at 14 hours", "text", 840),
                "urine_culture": (
                    "pending: >10^5 CFU/mL Gram-negative rods on the preliminary read",
                    "text",
                    720,
                ),
                "urine_wbc": (85.0, "/hpf", 20),
                "urine_nitrite": ("positive", "text", 20),
                "wbc": (17.2, "10^3/uL", 30),
                "lactate": (3.1, "mmol/L", 20),
                "creatinine": (1.1, "mg/dL", 30),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, notes="Urosepsis; documented anaphylaxis to piperacillin-tazobactam."
        ),
    }
    triage = _triage(
        p.patient_id,
        ["lactate", "wbc"],
        act("calculate_qsofa", patient_id=p.patient_id),
        2,
        "sepsis_team",
        "suspected urosepsis: SBP 96, lactate 3.1, qSOFA 2",
    )
    drugs = phase(
        "antimicrobials",
        "drug_interaction",
        "Give the first antibiotic dose within the hour, choosing per protocol after checking her allergy record.",
        [
            act("check_allergy", ["patient_id", "drug"], patient_id=p.patient_id, drug="aztreonam"),
            act(
                "check_patient_interactions",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="aztreonam",
            ),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="aztreonam",
                dose=2,
                unit="g",
                route="IV",
                frequency="every 8 hours",
                indication="urosepsis; penicillin anaphylaxis",
            ),
        ],
        [
            "Does not give piperacillin-tazobactam or another penicillin after the documented anaphylaxis",
            "Gives the first dose of aztreonam within one hour of recognising sepsis",
        ],
        max_calls=5,
    )
    return pathway(
        "sepsis_bundle_urosepsis",
        TITLE,
        p,
        "Irene Castillo (patient id PW-SE01), 71, comes to the emergency department at 14:00 with fever, rigors and "
        "right loin pain. " + PROTOCOL,
        patients,
        [
            triage,
            _cultures(
                p.patient_id,
                ["urine_culture", "urine_wbc"],
                "A41.9",
                True,
                "sepsis of urinary source (A41.9) as the provisional diagnosis",
            ),
            drugs,
        ],
        "What qSOFA score did you calculate?",
        "2",
        ["qSOFA 2", "qSOFA score 2"],
        emergency="sepsis",
    )


def pneumonia_shock_ckd() -> dict:
    p = Person(
        "PW-SE02",
        "Frank Mensah",
        66,
        "male",
        78.0,
        175.0,
        conditions=(
            "chronic obstructive pulmonary disease",
            "chronic kidney disease stage 3b",
            "hypertension",
        ),
        meds=(
            Med("ipratropium", 40, "mcg", "INH", "four times daily", "COPD"),
            Med("amlodipine", 10, "mg", "PO", "once daily", "hypertension"),
            Med("atorvastatin", 20, "mg", "PO", "once daily", "cardiovascular prevention"),
        ),
        creatinine_mg_dl=2.1,
    )
    v = [vitals("2025-03-01T13:51", 124, 82, 48, 32, 39.2, 87, gcs=(4, 4, 6), avpu="new_confusion")]
    patients = {
        "triage_emergency": triage_record(
            p,
            arrival_mode="ambulance",
            chief_complaint="breathless, feverish and confused",
            history="Three days of productive cough and fever; this morning breathless at rest and muddled. COPD and "
            "chronic kidney disease (baseline creatinine 1.8 mg/dL).",
            vitals_rows=v,
            held={"lactate": (4.6, "mmol/L"), "wbc": (21.4, "10^3/uL")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Breathlessness, fever and confusion",
            hpi="Three days of productive cough and fever, now hypotensive (82/48), hypoxic (87% on air), confused; "
            "lactate 4.6. Baseline creatinine 1.8 mg/dL.",
            exam={
                "general": "Confused, peripherally cool",
                "lungs": "Bronchial breathing and crackles at the left base",
                "cardiovascular": "Tachycardic, capillary refill 4 s",
            },
            vitals_rows=v,
            findings=[
                FEVER,
                finding("HP:0031245", "Productive cough"),
                finding("HP:0030830", "Crackles", "exam"),
                TACHYPNEA,
                HYPOTENSION,
                finding("HP:0012418", "Hypoxemia", "exam"),
                finding("HP:0032177", "Parenchymal consolidation", "imaging", "chest_xray"),
                LEUKOCYTOSIS,
            ],
            labs=[("creatinine", 2.1, "mg/dL", "2025-03-01T14:10")],
            hidden={
                "blood_culture": ("pending at 24 h", "text", 1440),
                "chest_xray": ("dense left lower lobe consolidation with air bronchograms", "text", 30),
                "wbc": (21.4, "10^3/uL", 30),
                "lactate": (4.6, "mmol/L", 20),
                "procalcitonin": (18.2, "ng/mL", 60),
            },
        ),
        "drug_interaction": pharmacy_record(p, notes="Septic shock from pneumonia; CKD 3b."),
    }
    esi = act(
        "calculate_esi_level",
        patient_id=p.patient_id,
        requires_immediate_lifesaving_intervention=True,
        high_risk_situation=True,
        confused_lethargic_or_disoriented=True,
        severe_pain_or_distress=False,
        expected_resources=5,
    )
    triage = _triage(
        p.patient_id,
        ["lactate", "wbc"],
        esi,
        1,
        "resuscitation_team",
        "septic shock: SBP 82, lactate 4.6, SpO2 87%, new confusion",
    )
    drugs = phase(
        "antimicrobials",
        "drug_interaction",
        "Give the protocol antibiotic now at a full first dose, then set the maintenance dose for his renal function.",
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
                frequency="first dose now",
                indication="septic shock from pneumonia: full first dose",
            ),
            act(
                "get_renal_dose_adjustment",
                ["drug", "patient_id"],
                drug="piperacillin and tazobactam",
                patient_id=p.patient_id,
            ),
            act(
                "adjust_medication_dose",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="piperacillin and tazobactam",
                dose=2.25,
                unit="g",
                frequency="every 6 hours",
                reason="CrCl 38 mL/min: renal maintenance dose after the full first dose",
            ),
        ],
        [
            "Does not delay or reduce the first antibiotic dose because of the kidney function",
            "Adjusts the maintenance dose to the creatinine clearance",
        ],
        max_calls=7,
    )
    return pathway(
        "sepsis_bundle_septic_shock",
        TITLE,
        p,
        "Frank Mensah (patient id PW-SE02), 66, is brought in by ambulance at 14:00, breathless, febrile and "
        "confused. " + PROTOCOL,
        patients,
        [
            triage,
            _cultures(
                p.patient_id,
                ["chest_xray", "procalcitonin"],
                "R65.21",
                True,
                "severe sepsis with septic shock (R65.21)",
            ),
            drugs,
        ],
        "What ESI level did you assign?",
        "ESI 1",
        ["1", "ESI level 1", "level 1"],
        emergency="sepsis",
    )


def cholangitis_on_warfarin() -> dict:
    p = Person(
        "PW-SE03",
        "Lorraine Pike",
        52,
        "female",
        70.0,
        166.0,
        conditions=("atrial fibrillation", "gallstones"),
        meds=(
            Med("warfarin", 5, "mg", "PO", "once daily", "stroke prevention in atrial fibrillation"),
            Med("bisoprolol", 2.5, "mg", "PO", "once daily", "rate control"),
        ),
        creatinine_mg_dl=0.9,
    )
    v = [vitals("2025-03-01T13:56", 118, 104, 62, 22, 39.4, 96, pain=7)]
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="fever, upper abdominal pain and yellow eyes",
            history="Known gallstones. Two days of right upper abdominal pain, fevers with rigors since last night, "
            "yellow eyes noticed by her husband. Warfarin for atrial fibrillation; bisoprolol.",
            vitals_rows=v,
            held={"lactate": (2.6, "mmol/L"), "wbc": (18.1, "10^3/uL")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Fever, right upper quadrant pain and jaundice",
            hpi="Charcot triad: fever with rigors, right upper quadrant pain and jaundice; known gallstones; on "
            "warfarin for atrial fibrillation.",
            exam={
                "general": "Jaundiced, rigoring",
                "abdomen": "Tender right upper quadrant, positive Murphy sign",
                "cardiovascular": "Irregularly irregular, tachycardic",
            },
            vitals_rows=v,
            findings=[
                FEVER,
                finding("HP:0000952", "Jaundice", "exam"),
                finding("HP:0002027", "Abdominal pain"),
                finding("HP:0025145", "Rigors"),
                LEUKOCYTOSIS,
            ],
            hidden={
                "blood_culture": ("Gram-negative rods in 1 of 2 bottles at 16 hours", "text", 960),
                "ruq_ultrasound": (
                    (
                        "common bile duct dilated to 11 mm with a 9 mm distal stone; gallbladder "
                        "calculi without wall thickening"
                    ),
                    "text",
                    45,
                ),
                "total_bilirubin": (4.8, "mg/dL", 45),
                "alp": (410.0, "U/L", 45),
                "inr": (3.1, "ratio", 30),
                "wbc": (18.1, "10^3/uL", 30),
            },
        ),
        "drug_interaction": pharmacy_record(p, notes="Acute cholangitis; anticoagulated with warfarin."),
    }
    triage = _triage(
        p.patient_id,
        ["lactate", "wbc"],
        act("calculate_news2", patient_id=p.patient_id),
        2,
        "sepsis_team",
        "sepsis with jaundice and rigors: suspected cholangitis",
        presentation=True,
    )
    work = _cultures(
        p.patient_id,
        ["ruq_ultrasound", "total_bilirubin", "inr"],
        "K80.33",
        False,
        "acute cholangitis from an obstructing common bile duct stone",
        [
            act(
                "write_clinical_note",
                ["patient_id", "note_type"],
                patient_id=p.patient_id,
                note_type="consult",
                content="Gastroenterology consulted for urgent ERCP: acute cholangitis with an obstructing common "
                "bile duct stone (CBD 11 mm), sepsis; INR 3.1 on warfarin to be corrected before the procedure.",
            )
        ],
    )
    drugs = phase(
        "antimicrobials",
        "drug_interaction",
        "Start the protocol antibiotic after checking allergies and her warfarin for interactions.",
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
                indication="acute cholangitis; INR daily while on warfarin",
            ),
        ],
        [
            "Checks the antibiotic against warfarin and plans INR monitoring",
            "Arranges biliary decompression as source control",
        ],
        max_calls=5,
    )
    return pathway(
        "sepsis_bundle_cholangitis",
        TITLE,
        p,
        "Lorraine Pike (patient id PW-SE03), 52, comes to the emergency department at 14:00 with fever, rigors, right "
        "upper abdominal pain and yellow eyes. " + PROTOCOL,
        patients,
        [triage, work, drugs],
        "What NEWS2 score did you calculate at triage?",
        "7",
        ["NEWS2 7", "NEWS2 score 7"],
        emergency="sepsis",
    )


def febrile_neutropenia() -> dict:
    p = Person(
        "PW-SE04",
        "Tomasz Wrobel",
        38,
        "male",
        72.0,
        183.0,
        conditions=("diffuse large B-cell lymphoma on R-CHOP chemotherapy (day 10 of cycle 3)",),
        meds=(
            Med("aciclovir", 400, "mg", "PO", "twice daily", "antiviral prophylaxis"),
            Med("allopurinol", 300, "mg", "PO", "once daily", "tumour lysis prophylaxis"),
            Med("ondansetron", 8, "mg", "PO", "twice daily as needed", "nausea"),
        ),
        creatinine_mg_dl=0.9,
    )
    v = [vitals("2025-03-01T13:57", 116, 108, 66, 20, 38.7, 97, pain=2)]
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="fever 10 days after chemotherapy",
            history="Lymphoma, third cycle of R-CHOP ten days ago. Temperature 38.7 at home with shivers; feels washed "
            "out. Aciclovir, allopurinol, ondansetron.",
            vitals_rows=v,
            held={"wbc": (0.6, "10^3/uL"), "neutrophil_percent": (30.0, "%"), "lactate": (1.9, "mmol/L")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Fever ten days after chemotherapy",
            hpi="Fever 38.7 with rigors on day 10 after R-CHOP; no localising symptoms; Hickman line in situ, site "
            "clean.",
            exam={
                "general": "Flushed",
                "lines": "Tunnelled central line site clean",
                "lungs": "Clear",
                "mouth": "Mild mucositis",
            },
            vitals_rows=v,
            findings=[FEVER, TACHYCARDIA, finding("HP:0001875", "Neutropenia", "lab", "neutrophils_abs")],
            hidden={
                "neutrophils_abs": (0.18, "10^3/uL", 30),
                "wbc": (0.6, "10^3/uL", 30),
                "blood_culture": ("pending at 24 h", "text", 1440),
                "lactate": (1.9, "mmol/L", 20),
                "creatinine": (0.9, "mg/dL", 30),
            },
        ),
        "drug_interaction": pharmacy_record(p, notes="Febrile neutropenia after R-CHOP."),
    }
    esi = act(
        "calculate_esi_level",
        patient_id=p.patient_id,
        requires_immediate_lifesaving_intervention=False,
        high_risk_situation=True,
        confused_lethargic_or_disoriented=False,
        severe_pain_or_distress=False,
        expected_resources=3,
    )
    triage = _triage(
        p.patient_id,
        ["lactate", "wbc", "neutrophil_percent"],
        esi,
        2,
        "sepsis_team",
        "neutropenic sepsis: fever 38.7 ten days after chemotherapy, WBC 0.6",
        presentation=True,
    )
    drugs = phase(
        "antimicrobials",
        "drug_interaction",
        "Give the protocol antibiotic at the full adult dose within one hour of arrival.",
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
                "get_dose_range",
                ["drug", "patient_id"],
                drug="piperacillin and tazobactam",
                patient_id=p.patient_id,
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
                indication="febrile neutropenia",
            ),
        ],
        [
            "Gives the first dose of piperacillin-tazobactam within one hour (door-to-needle)",
            "Uses the 4.5 g adult cap rather than the weight-based figure",
        ],
        max_calls=6,
    )
    return pathway(
        "sepsis_bundle_neutropenic",
        TITLE,
        p,
        "Tomasz Wrobel (patient id PW-SE04), 38, on chemotherapy for lymphoma, comes to the emergency department at "
        "14:00 with a fever of 38.7 C ten days after his last cycle. " + PROTOCOL,
        patients,
        [
            triage,
            _cultures(
                p.patient_id,
                ["neutrophils_abs"],
                "D70.1",
                True,
                "agranulocytosis secondary to chemotherapy (D70.1) with fever",
            ),
            drugs,
        ],
        "Which ICD-10-CM code did you record for the neutropenia?",
        "D70.1",
        ["D701"],
        emergency="sepsis",
    )


def pathways() -> list[dict]:
    return [urosepsis_allergy(), pneumonia_shock_ckd(), cholangitis_on_warfarin(), febrile_neutropenia()]
