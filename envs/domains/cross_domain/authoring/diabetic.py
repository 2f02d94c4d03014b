"""Diabetic emergency: ED triage (point-of-care glucose and potassium, ESI) -> metabolic work-up
(ketones, acid-base, coded diagnosis) -> insulin, glucose and home-medication decisions checked in
the pharmacy tools (weight-based infusion rate, renal contraindications, interactions)."""

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

TITLE = "Diabetic emergency"

POLYURIA = finding("HP:0000103", "Polyuria")
POLYDIPSIA = finding("HP:0001959", "Polydipsia")
VOMITING = finding("HP:0002013", "Vomiting")
ABDO_PAIN = finding("HP:0002027", "Abdominal pain")
DEHYDRATION = finding("HP:0001944", "Dehydration", "exam")
TACHYPNEA = finding("HP:0002789", "Tachypnea", "exam")
HYPERGLYCEMIA = finding("HP:0003074", "Hyperglycemia", "lab", "glucose")
KETOACIDOSIS = finding("HP:0001993", "Ketoacidosis", "lab", "beta_hydroxybutyrate")
ACIDOSIS = finding("HP:0001942", "Metabolic acidosis", "lab", "ph_arterial")
KETONURIA = finding("HP:0002919", "Ketonuria", "lab", "urine_ketones")


def _triage(pid: str, tests: list[str], esi_inputs: dict, esi: int, escalate: str | None) -> dict:
    actions = [act("get_patient_presentation", patient_id=pid), act("get_vital_signs", patient_id=pid)]
    actions += [
        act("order_point_of_care_test", ["patient_id", "test"], patient_id=pid, test=t) for t in tests
    ]
    actions.append(act("calculate_esi_level", patient_id=pid, **esi_inputs))
    actions.append(
        act(
            "assign_triage_level",
            ["patient_id", "esi_level"],
            patient_id=pid,
            esi_level=esi,
            rationale="diabetic emergency",
        )
    )
    if escalate:
        actions.append(
            act(
                "escalate_care",
                ["patient_id", "level"],
                patient_id=pid,
                level="physician_now",
                reason=escalate,
            )
        )
    return phase(
        "triage",
        "triage_emergency",
        "Triage the diabetic patient: vital signs, point-of-care glucose (and potassium), the ESI decision "
        "points, and escalation to a physician when the metabolic picture is dangerous.",
        actions,
        ["Checks a capillary glucose at the front door", f"Assigns ESI level {esi}"]
        + (["Asks for immediate physician review"] if escalate else []),
        max_calls=8,
    )


def dka_type1() -> dict:
    p = Person(
        "PW-DM01",
        "Liam Fraser",
        22,
        "male",
        68.0,
        180.0,
        conditions=("type 1 diabetes mellitus",),
        meds=(
            Med("insulin glargine", 24, "units", "SC", "once daily at night", "type 1 diabetes"),
            Med("insulin lispro", 6, "units", "SC", "three times daily with meals", "type 1 diabetes"),
        ),
        creatinine_mg_dl=1.3,
    )
    v = [vitals("2025-03-01T13:55", 124, 104, 62, 30, 37.2, 99, pain=5)]
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="vomiting, abdominal pain and rapid breathing",
            history="Type 1 diabetic. Two days of vomiting and central abdominal pain; ran out of insulin lispro and "
            "has missed his glargine for two nights. Very thirsty, passing a lot of urine. Breathing deeply.",
            vitals_rows=v,
            held={"glucose": (486.0, "mg/dL"), "potassium": (5.4, "mmol/L"), "lactate": (2.2, "mmol/L")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Vomiting, abdominal pain and rapid breathing",
            hpi="Type 1 diabetes; missed basal insulin for two nights after running out; two days of vomiting, "
            "polyuria, polydipsia and central abdominal pain; Kussmaul breathing at triage.",
            exam={
                "general": "Dry mucous membranes, ketotic breath, deep sighing respirations",
                "cardiovascular": "Tachycardic, capillary refill 3 s",
                "abdomen": "Diffusely tender, no guarding",
                "neurologic": "Alert and oriented",
            },
            vitals_rows=v,
            social="Student; lives in shared accommodation.",
            findings=[
                POLYURIA,
                POLYDIPSIA,
                VOMITING,
                ABDO_PAIN,
                DEHYDRATION,
                TACHYPNEA,
                HYPERGLYCEMIA,
                KETOACIDOSIS,
                ACIDOSIS,
                KETONURIA,
            ],
            hidden={
                "glucose": (486.0, "mg/dL", 30),
                "beta_hydroxybutyrate": (6.2, "mmol/L", 30),
                "ph_arterial": (7.14, "pH", 15),
                "bicarbonate": (9.0, "mmol/L", 30),
                "sodium": (131.0, "mmol/L", 30),
                "chloride": (96.0, "mmol/L", 30),
                "potassium": (5.4, "mmol/L", 30),
                "urine_ketones": ("3+", "text", 15),
                "creatinine": (1.3, "mg/dL", 30),
            },
        ),
        "drug_interaction": pharmacy_record(
            p,
            notes="DKA: fixed-rate IV insulin 0.1 units/kg/hour per the DKA "
            "protocol; continue basal glargine.",
        ),
    }
    esi = {
        "requires_immediate_lifesaving_intervention": False,
        "high_risk_situation": True,
        "confused_lethargic_or_disoriented": False,
        "severe_pain_or_distress": False,
        "expected_resources": 3,
    }
    workup = phase(
        "metabolic work-up",
        "clinical_diagnosis",
        "Confirm or exclude ketoacidosis: ketones, blood gas and electrolytes; record the coded diagnosis.",
        [
            act("get_patient_info", patient_id=p.patient_id),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="beta_hydroxybutyrate",
                priority="stat",
            ),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="ph_arterial",
                priority="stat",
            ),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="bicarbonate",
                priority="stat",
            ),
            act(
                "record_diagnosis",
                ["patient_id", "icd10_code"],
                patient_id=p.patient_id,
                icd10_code="E10.10",
                certainty="confirmed",
            ),
        ],
        [
            "Confirms ketonaemia (beta-hydroxybutyrate > 3 mmol/L) and acidosis (pH < 7.3 or bicarbonate < 15)",
            "Records type 1 diabetes with ketoacidosis without coma, E10.10",
        ],
    )
    insulin = phase(
        "insulin infusion",
        "drug_interaction",
        "Start the fixed-rate IV insulin infusion for DKA at the weight-based rate, after checking the medication list.",
        [
            act(
                "get_dose_range",
                ["drug", "patient_id"],
                drug="insulin human",
                route="IV_DRIP",
                patient_id=p.patient_id,
            ),
            act(
                "check_patient_interactions",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="insulin human",
            ),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="insulin human",
                dose=6.8,
                unit="units/hr",
                route="IV_DRIP",
                frequency="continuous (0.1 units/kg/hour)",
                indication="DKA fixed-rate IV insulin; hourly capillary glucose and ketones, potassium 2-hourly",
            ),
        ],
        [
            "Calculates the rate from his weight (0.1 units/kg/hour = 6.8 units/hour)",
            "Continues basal insulin glargine rather than stopping it",
            "Plans hourly glucose and potassium monitoring",
        ],
        max_calls=6,
    )
    return pathway(
        "diabetic_emergency_dka",
        TITLE,
        p,
        "Liam Fraser (patient id PW-DM01), 22, a type 1 diabetic, comes to the emergency department at 14:00 with two "
        "days of vomiting, abdominal pain and rapid breathing. The department DKA protocol uses a fixed-rate IV "
        "insulin infusion of 0.1 units/kg/hour.",
        patients,
        [
            _triage(
                p.patient_id,
                ["glucose", "potassium"],
                esi,
                2,
                "suspected diabetic ketoacidosis: glucose 486 mg/dL with Kussmaul breathing",
            ),
            workup,
            insulin,
        ],
        "What insulin infusion rate did you prescribe, in units per hour?",
        "6.8 units/hour",
        ["6.8", "6.8 units/h", "6.8 units/hr", "6.8 units per hour", "6.8 u/h"],
        emergency="dka",
    )


def euglycaemic_dka() -> dict:
    p = Person(
        "PW-DM02",
        "Angela Reyes",
        58,
        "female",
        74.0,
        163.0,
        conditions=("type 2 diabetes mellitus", "hypertension"),
        meds=(
            Med("metformin", 1000, "mg", "PO", "twice daily", "type 2 diabetes"),
            Med("dapagliflozin", 10, "mg", "PO", "once daily", "type 2 diabetes"),
            Med("amlodipine", 5, "mg", "PO", "once daily", "hypertension"),
        ),
        allergies=(Allergy("sulfamethoxazole", "rash", "moderate"),),
        creatinine_mg_dl=1.0,
    )
    v = [vitals("2025-03-01T13:52", 112, 118, 70, 28, 37.0, 98, pain=3)]
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="vomiting and breathlessness after a stomach bug",
            history="Three days of diarrhoea and vomiting, barely eating or drinking; since this morning breathless "
            "and exhausted. Type 2 diabetes on metformin and dapagliflozin, still taking both.",
            vitals_rows=v,
            held={"glucose": (212.0, "mg/dL"), "potassium": (4.6, "mmol/L")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Vomiting and breathlessness after gastroenteritis",
            hpi="Three days of gastroenteritis with poor intake while continuing metformin and the SGLT2 inhibitor "
            "dapagliflozin; now tachypnoeic and exhausted. Capillary glucose only 212 mg/dL.",
            exam={
                "general": "Tired, dry mucous membranes, deep respirations",
                "abdomen": "Soft, mildly tender",
                "neurologic": "Alert",
            },
            vitals_rows=v,
            social="Teacher; no alcohol.",
            findings=[VOMITING, DEHYDRATION, TACHYPNEA, HYPERGLYCEMIA, KETOACIDOSIS, ACIDOSIS, KETONURIA],
            hidden={
                "glucose": (212.0, "mg/dL", 30),
                "beta_hydroxybutyrate": (5.4, "mmol/L", 30),
                "ph_arterial": (7.19, "pH", 15),
                "bicarbonate": (11.0, "mmol/L", 30),
                "sodium": (137.0, "mmol/L", 30),
                "chloride": (102.0, "mmol/L", 30),
                "urine_ketones": ("3+", "text", 15),
                "lactate": (1.4, "mmol/L", 30),
                "creatinine": (1.0, "mg/dL", 30),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, notes="Suspected SGLT2-inhibitor-associated (euglycaemic) DKA."
        ),
    }
    esi = {
        "requires_immediate_lifesaving_intervention": False,
        "high_risk_situation": True,
        "confused_lethargic_or_disoriented": False,
        "severe_pain_or_distress": False,
        "expected_resources": 3,
    }
    workup = phase(
        "metabolic work-up",
        "clinical_diagnosis",
        "The glucose is only modestly raised: check ketones and the blood gas before excluding ketoacidosis, then "
        "record the coded diagnosis.",
        [
            act("get_patient_info", patient_id=p.patient_id),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="beta_hydroxybutyrate",
                priority="stat",
            ),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="ph_arterial",
                priority="stat",
            ),
            act("generate_ddx", patient_id=p.patient_id, top_k=5, scope="common"),
            act(
                "record_diagnosis",
                ["patient_id", "icd10_code"],
                patient_id=p.patient_id,
                icd10_code="E11.10",
                certainty="confirmed",
            ),
        ],
        [
            "Does not exclude ketoacidosis because the glucose is below 250 mg/dL",
            "Records type 2 diabetes with ketoacidosis without coma, E11.10",
        ],
    )
    drugs = phase(
        "medication changes",
        "drug_interaction",
        "Stop the drug that caused the ketoacidosis and start the insulin infusion.",
        [
            act("get_patient_medications", patient_id=p.patient_id),
            act(
                "discontinue_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="dapagliflozin",
                reason="SGLT2-inhibitor-associated euglycaemic ketoacidosis",
            ),
            act(
                "check_patient_interactions",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="insulin human",
            ),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="insulin human",
                dose=7.4,
                unit="units/hr",
                route="IV_DRIP",
                frequency="continuous (0.1 units/kg/hour) with 10% dextrose",
                indication="euglycaemic DKA; hourly capillary glucose and ketones, potassium 2-hourly",
            ),
        ],
        [
            "Stops dapagliflozin as the precipitant",
            "Gives dextrose with the insulin because the glucose is not high",
        ],
        max_calls=6,
    )
    return pathway(
        "diabetic_emergency_euglycaemic_dka",
        TITLE,
        p,
        "Angela Reyes (patient id PW-DM02), 58, with type 2 diabetes, comes to the emergency department at 14:00 "
        "breathless and exhausted after three days of vomiting and diarrhoea.",
        patients,
        [
            _triage(
                p.patient_id,
                ["glucose", "potassium"],
                esi,
                2,
                "possible ketoacidosis on an SGLT2 inhibitor: Kussmaul breathing",
            ),
            workup,
            drugs,
        ],
        "Which ICD-10-CM code did you record?",
        "E11.10",
        ["E1110"],
        emergency="dka",
    )


def hhs() -> dict:
    p = Person(
        "PW-DM03",
        "Walter Kim",
        79,
        "male",
        70.0,
        172.0,
        conditions=("type 2 diabetes mellitus", "hypertension", "benign prostatic hyperplasia"),
        meds=(
            Med("metformin", 1000, "mg", "PO", "twice daily", "type 2 diabetes"),
            Med("glipizide", 10, "mg", "PO", "twice daily", "type 2 diabetes"),
            Med("lisinopril", 20, "mg", "PO", "once daily", "hypertension"),
            Med("tamsulosin", 0.4, "mg", "PO", "once daily", "benign prostatic hyperplasia"),
        ),
        creatinine_mg_dl=2.4,
    )
    v = [vitals("2025-03-01T13:50", 108, 96, 58, 22, 37.6, 96, gcs=(3, 4, 6), avpu="new_confusion")]
    patients = {
        "triage_emergency": triage_record(
            p,
            arrival_mode="ambulance",
            chief_complaint="confused and drowsy for two days",
            history="Found confused by his daughter; increasingly drowsy for two days, drinking a lot, recent urinary "
            "infection. Type 2 diabetes on metformin and glipizide; lisinopril; tamsulosin.",
            vitals_rows=v,
            held={"glucose": (912.0, "mg/dL"), "potassium": (5.1, "mmol/L"), "bun": (64.0, "mg/dL")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Confusion and drowsiness",
            hpi="Two days of increasing drowsiness, polyuria and thirst after a urinary infection; confused at triage "
            "(GCS 13). Capillary glucose 912 mg/dL.",
            exam={
                "general": "Drowsy, very dry mucous membranes, reduced skin turgor",
                "neurologic": "GCS 13 (E3 V4 M6), no focal deficit",
                "abdomen": "Soft, suprapubic tenderness",
            },
            vitals_rows=v,
            social="Widower, lives alone.",
            findings=[
                POLYURIA,
                POLYDIPSIA,
                DEHYDRATION,
                HYPERGLYCEMIA,
                finding("HP:0001289", "Confusion", "exam"),
            ],
            hidden={
                "glucose": (912.0, "mg/dL", 30),
                "beta_hydroxybutyrate": (0.6, "mmol/L", 30),
                "ph_arterial": (7.34, "pH", 15),
                "bicarbonate": (22.0, "mmol/L", 30),
                "sodium": (149.0, "mmol/L", 30),
                "creatinine": (2.4, "mg/dL", 30),
                "bun": (64.0, "mg/dL", 30),
                "urine_wbc": (48.0, "/hpf", 30),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, notes="Hyperosmolar hyperglycaemic state with acute kidney injury."
        ),
    }
    esi = {
        "requires_immediate_lifesaving_intervention": False,
        "high_risk_situation": True,
        "confused_lethargic_or_disoriented": True,
        "severe_pain_or_distress": False,
        "expected_resources": 4,
    }
    workup = phase(
        "metabolic work-up",
        "clinical_diagnosis",
        "Distinguish a hyperosmolar state from ketoacidosis (ketones, gas, sodium, renal function); record the "
        "coded diagnosis.",
        [
            act("get_patient_info", patient_id=p.patient_id),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="beta_hydroxybutyrate",
                priority="stat",
            ),
            act("order_lab", ["patient_id", "test"], patient_id=p.patient_id, test="sodium", priority="stat"),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="creatinine",
                priority="stat",
            ),
            act(
                "record_diagnosis",
                ["patient_id", "icd10_code"],
                patient_id=p.patient_id,
                icd10_code="E11.00",
                certainty="confirmed",
            ),
        ],
        [
            "Finds no significant ketosis or acidosis and a very high glucose with hypernatraemia",
            "Records type 2 diabetes with hyperosmolarity without coma, E11.00",
        ],
    )
    drugs = phase(
        "home medication review",
        "drug_interaction",
        "Review his diabetes medication against the renal function and stop what is contraindicated.",
        [
            act("calculate_renal_function", patient_id=p.patient_id),
            act(
                "get_renal_dose_adjustment", ["drug", "patient_id"], drug="metformin", patient_id=p.patient_id
            ),
            act(
                "discontinue_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="metformin",
                reason="eGFR below 30 mL/min/1.73 m2: contraindicated (lactic acidosis)",
            ),
        ],
        [
            "Computes the renal function before deciding on metformin",
            "Stops metformin because the renal dose check says it is contraindicated",
        ],
    )
    return pathway(
        "diabetic_emergency_hhs",
        TITLE,
        p,
        "Walter Kim (patient id PW-DM03), 79, with type 2 diabetes, is brought in by ambulance at 14:00, confused and "
        "drowsy for two days.",
        patients,
        [
            _triage(
                p.patient_id,
                ["glucose", "potassium"],
                esi,
                2,
                "new confusion with glucose 912 mg/dL: possible hyperosmolar state",
            ),
            workup,
            drugs,
        ],
        "Which home medication did the renal dose check require you to stop? Give its generic name.",
        "metformin",
        ["glucophage"],
        emergency="other",
    )


def sulfonylurea_hypoglycaemia() -> dict:
    p = Person(
        "PW-DM04",
        "Edith Novak",
        76,
        "female",
        58.0,
        155.0,
        conditions=("type 2 diabetes mellitus", "hypertension", "chronic kidney disease stage 3b"),
        meds=(
            Med("glyburide", 5, "mg", "PO", "twice daily", "type 2 diabetes"),
            Med("lisinopril", 10, "mg", "PO", "once daily", "hypertension"),
            Med("clarithromycin", 500, "mg", "PO", "twice daily", "chest infection (day 3 of 7)"),
        ),
        allergies=(Allergy("amoxicillin", "widespread urticaria", "moderate", "penicillins", "class"),),
        creatinine_mg_dl=1.6,
    )
    v = [vitals("2025-03-01T13:53", 96, 148, 82, 18, 36.4, 97, gcs=(3, 4, 6), avpu="new_confusion")]
    patients = {
        "triage_emergency": triage_record(
            p,
            arrival_mode="ambulance",
            chief_complaint="found confused and sweaty at home",
            history="Daughter found her sweaty, muddled and slurring words at lunchtime. Started clarithromycin 3 "
            "days ago for a chest infection (penicillin allergy). Takes glyburide and lisinopril.",
            vitals_rows=v,
            held={"glucose": (36.0, "mg/dL"), "potassium": (4.8, "mmol/L")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Confusion and sweating",
            hpi="Found sweaty and confused at home; capillary glucose 36 mg/dL at triage. On glyburide; clarithromycin "
            "started 3 days ago; CKD stage 3b.",
            exam={
                "general": "Sweaty, pale",
                "neurologic": "GCS 13, no focal deficit, pupils equal",
                "lungs": "Few crackles at the left base",
            },
            vitals_rows=v,
            social="Lives alone; daughter visits daily.",
            findings=[
                finding("HP:0001943", "Hypoglycemia", "lab", "glucose"),
                finding("HP:0001289", "Confusion", "exam"),
                finding("HP:0000975", "Diaphoresis", "exam"),
            ],
            hidden={
                "glucose": (36.0, "mg/dL", 15),
                "creatinine": (1.6, "mg/dL", 30),
                "potassium": (4.8, "mmol/L", 30),
            },
        ),
        "drug_interaction": pharmacy_record(p, notes="Severe hypoglycaemia on a sulfonylurea with CKD 3b."),
    }
    esi = {
        "requires_immediate_lifesaving_intervention": False,
        "high_risk_situation": True,
        "confused_lethargic_or_disoriented": True,
        "severe_pain_or_distress": False,
        "expected_resources": 2,
    }
    workup = phase(
        "work-up",
        "clinical_diagnosis",
        "Confirm the hypoglycaemia on the laboratory sample drawn before treatment, review her medicines and record "
        "the coded diagnosis.",
        [
            act("get_medication_list", patient_id=p.patient_id),
            act(
                "order_lab", ["patient_id", "test"], patient_id=p.patient_id, test="glucose", priority="stat"
            ),
            act(
                "record_diagnosis",
                ["patient_id", "icd10_code"],
                patient_id=p.patient_id,
                icd10_code="E11.649",
                certainty="confirmed",
            ),
        ],
        [
            "Confirms the hypoglycaemia on a laboratory glucose",
            "Records type 2 diabetes with hypoglycaemia without coma, E11.649",
        ],
    )
    drugs = phase(
        "glucose and medication review",
        "drug_interaction",
        "Give IV glucose at the weight-based dose, then find the interaction behind the hypoglycaemia and stop the "
        "responsible diabetes drug.",
        [
            act("get_patient_details", patient_id=p.patient_id),
            act("check_patient_interactions", patient_id=p.patient_id),
            act(
                "get_dose_range", ["drug", "patient_id"], drug="glucose", route="IV", patient_id=p.patient_id
            ),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="glucose",
                dose=25,
                unit="g",
                route="IV",
                frequency="once (50% dextrose 50 mL), repeat per glucose check",
                indication="severe hypoglycaemia; capillary glucose every 15 minutes",
            ),
            act(
                "discontinue_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="glyburide",
                reason="severe hypoglycaemia: long-acting sulfonylurea in CKD 3b, potentiated by clarithromycin",
            ),
        ],
        [
            "Gives IV glucose immediately (25 g, the adult cap)",
            "Identifies the clarithromycin-sulfonylurea interaction",
            (
                "Stops glyburide and plans prolonged glucose "
                "monitoring because sulfonylurea hypoglycaemia recurs"
            ),
        ],
        max_calls=6,
    )
    return pathway(
        "diabetic_emergency_hypoglycaemia",
        TITLE,
        p,
        "Edith Novak (patient id PW-DM04), 76, is brought in by ambulance at 14:00 after her daughter found her "
        "sweaty and confused at home.",
        patients,
        [
            _triage(p.patient_id, ["glucose"], esi, 2, "capillary glucose 36 mg/dL with confusion"),
            drugs,
            workup,
        ],
        "Which diabetes medication did you stop? Give its generic name.",
        "glyburide",
        ["glibenclamide"],
        emergency="other",
    )


def pathways() -> list[dict]:
    return [dka_type1(), euglycaemic_dka(), hhs(), sulfonylurea_hypoglycaemia()]
