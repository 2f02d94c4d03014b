"""Paediatric fever: ED triage with age-specific danger-zone vital signs (ESI) -> febrile work-up (source,
cultures, coded diagnosis) -> weight-based antimicrobial and antipyretic doses checked in the pharmacy
tools (paediatric dose ranges and caps, allergies)."""

from __future__ import annotations

from .records import (
    Allergy,
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

TITLE = "Paediatric fever"
FEVER = finding("HP:0001945", "Fever")


def _triage(
    pid: str, esi: int, esi_inputs: dict, *, escalate: str | None = None, max_calls: int | None = None
) -> dict:
    actions = [
        act("get_patient_presentation", patient_id=pid),
        act("get_vital_signs", patient_id=pid),
        act("calculate_esi_level", patient_id=pid, **esi_inputs),
    ]
    if escalate:
        actions.append(
            act(
                "escalate_care",
                ["patient_id", "level"],
                patient_id=pid,
                level="resuscitation_team",
                reason=escalate,
            )
        )
    actions.append(
        act(
            "assign_triage_level",
            ["patient_id", "esi_level"],
            patient_id=pid,
            esi_level=esi,
            rationale="febrile child",
        )
    )
    return phase(
        "paediatric triage",
        "triage_emergency",
        "Triage the febrile child: vital signs against the age-specific danger-zone limits, the ESI "
        "decision points and the ESI level.",
        actions,
        ["Interprets heart and respiratory rate against the child's age", f"Assigns ESI level {esi}"]
        + (["Calls the resuscitation team immediately"] if escalate else []),
        max_calls=max_calls,
    )


def _dose(
    pid: str,
    drug: str,
    dose: float,
    route: str,
    frequency: str,
    indication: str,
    dose_route: str | None = None,
) -> list[dict]:
    return [
        act("get_dose_range", ["drug", "patient_id"], drug=drug, route=dose_route or route, patient_id=pid),
        act(
            "add_medication",
            ["patient_id", "drug"],
            patient_id=pid,
            drug=drug,
            dose=dose,
            unit="mg",
            route=route,
            frequency=frequency,
            indication=indication,
        ),
    ]


def febrile_uti_toddler() -> dict:
    p = Person("PW-PF01", "Mia Thompson", 1, "female", 11.0, 80.0, age_months=18, creatinine_mg_dl=0.3)
    v = [vitals("2025-03-01T13:52", 150, 94, 58, 34, 39.4, 98, avpu="alert")]
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="fever for two days and vomiting in a toddler",
            history="Eighteen-month-old girl with 39-40 C fevers for two days, vomited twice today, crying when "
            "passing urine, fewer wet nappies. No cough or rash. Immunisations up to date.",
            vitals_rows=v,
            held={"wbc": (16.2, "10^3/uL"), "glucose": (96.0, "mg/dL")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Fever and vomiting for two days",
            hpi="Two days of high fever with vomiting and crying on voiding; no respiratory symptoms; alert and "
            "consolable between fevers.",
            exam={
                "general": "Miserable but consolable, mildly dry",
                "ears": "Normal tympanic membranes",
                "throat": "Normal",
                "chest": "Clear",
                "abdomen": "Soft, suprapubic tenderness",
                "skin": "No rash",
            },
            vitals_rows=v,
            findings=[
                FEVER,
                finding("HP:0000737", "Irritability", "exam"),
                finding("HP:0002013", "Vomiting"),
                finding("HP:0012085", "Pyuria", "lab", "urine_wbc"),
            ],
            hidden={
                "urine_wbc": (60.0, "/hpf", 20),
                "urine_nitrite": ("positive", "text", 20),
                "urine_culture": ("preliminary: >10^5 CFU/mL Gram-negative rods", "text", 720),
                "crp": (68.0, "mg/L", 45),
                "wbc": (16.2, "10^3/uL", 30),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, notes="Febrile UTI in an 18-month-old, vomiting: IV treatment."
        ),
    }
    esi = {
        "requires_immediate_lifesaving_intervention": False,
        "high_risk_situation": False,
        "confused_lethargic_or_disoriented": False,
        "severe_pain_or_distress": False,
        "expected_resources": 2,
    }
    work = phase(
        "febrile work-up",
        "clinical_diagnosis",
        "Look for the source of the fever with a urine sample and culture, then record the diagnosis.",
        [
            act("get_patient_info", patient_id=p.patient_id),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="urine_wbc",
                priority="urgent",
            ),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="urine_nitrite",
                priority="urgent",
            ),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="urine_culture",
                priority="urgent",
                indication="febrile UTI before antibiotics",
            ),
            act(
                "record_diagnosis",
                ["patient_id", "icd10_code"],
                patient_id=p.patient_id,
                icd10_code="N39.0",
                certainty="provisional",
            ),
        ],
        ["Sends a urine culture before the first antibiotic dose", "Records urinary tract infection, N39.0"],
    )
    drugs = phase(
        "weight-based treatment",
        "drug_interaction",
        "Prescribe IV ceftriaxone (she is vomiting) and paracetamol at her weight-based doses.",
        [
            act("check_allergy", ["patient_id", "drug"], patient_id=p.patient_id, drug="ceftriaxone"),
            *_dose(
                p.patient_id,
                "ceftriaxone",
                550,
                "IV",
                "once daily",
                "febrile urinary tract infection (50 mg/kg)",
            ),
            act(
                "check_patient_interactions",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="acetaminophen",
            ),
            *_dose(p.patient_id, "acetaminophen", 165, "PO", "every 6 hours as needed", "fever (15 mg/kg)"),
        ],
        ["Doses ceftriaxone at 50 mg/kg (550 mg) and paracetamol at 15 mg/kg (165 mg)"],
    )
    return pathway(
        "paediatric_fever_uti",
        TITLE,
        p,
        "Mia Thompson (patient id PW-PF01), 18 months, 11 kg, is brought to the emergency department at 14:00 by her "
        "mother with two days of fever and vomiting.",
        patients,
        [_triage(p.patient_id, 3, esi), work, drugs],
        "What ESI level did you assign?",
        "ESI 3",
        ["3", "ESI level 3", "level 3"],
    )


def meningococcal_sepsis() -> dict:
    p = Person("PW-PF02", "Oscar Nilsson", 4, "male", 16.0, 104.0, creatinine_mg_dl=0.4)
    v = [vitals("2025-03-01T13:58", 168, 72, 40, 36, 39.8, 94, gcs=(3, 4, 6), avpu="new_confusion")]
    patients = {
        "triage_emergency": triage_record(
            p,
            arrival_mode="ambulance",
            chief_complaint="fever, drowsy and a spreading purple rash",
            history="Four-year-old boy, fever since the early morning, now drowsy and complaining his neck hurts; "
            "parents noticed purple spots on the legs that do not fade under a glass. Cold hands and feet.",
            vitals_rows=v,
            held={"glucose": (84.0, "mg/dL"), "lactate": (5.1, "mmol/L")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Fever, drowsiness and non-blanching rash",
            hpi="Fever since early morning, drowsy, neck pain and a spreading non-blanching purpuric rash; "
            "capillary refill 5 s; ceftriaxone given in resuscitation.",
            exam={
                "skin": "Non-blanching petechiae and purpura on the legs and trunk",
                "neurologic": "Drowsy, GCS 13, neck stiffness, Kernig positive",
                "cardiovascular": "Cold peripheries, capillary refill 5 s",
            },
            vitals_rows=v,
            findings=[
                FEVER,
                finding("HP:0000967", "Petechiae", "exam"),
                finding("HP:0031179", "Nuchal rigidity", "exam"),
                finding("HP:0001254", "Lethargy", "exam"),
                finding("HP:0002615", "Hypotension", "exam"),
            ],
            hidden={
                "blood_culture": ("Gram-negative diplococci at 12 hours", "text", 720),
                "wbc": (24.0, "10^3/uL", 30),
                "crp": (180.0, "mg/L", 45),
                "platelets": (62.0, "10^3/uL", 30),
                "inr": (1.8, "ratio", 30),
                "lactate": (5.1, "mmol/L", 20),
            },
        ),
        "drug_interaction": pharmacy_record(p, notes="Suspected meningococcal sepsis with meningitis."),
    }
    esi = {
        "requires_immediate_lifesaving_intervention": True,
        "high_risk_situation": True,
        "confused_lethargic_or_disoriented": True,
        "severe_pain_or_distress": False,
        "expected_resources": 5,
    }
    drugs = phase(
        "immediate antibiotic",
        "drug_interaction",
        "Give IV ceftriaxone now at the meningitis dose for his weight; do not wait for investigations.",
        [
            act("check_allergy", ["patient_id", "drug"], patient_id=p.patient_id, drug="ceftriaxone"),
            *_dose(
                p.patient_id,
                "ceftriaxone",
                1600,
                "IV",
                "every 24 hours (meningitis dose)",
                "suspected meningococcal sepsis and meningitis (100 mg/kg)",
            ),
        ],
        [
            "Gives ceftriaxone within minutes of arrival without waiting for tests",
            "Uses the meningitis dose of 100 mg/kg (1600 mg)",
        ],
        max_calls=4,
    )
    work = phase(
        "work-up",
        "clinical_diagnosis",
        "Take blood cultures and bloods for the septic screen and record the working diagnosis.",
        [
            act("get_physical_exam", patient_id=p.patient_id),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="blood_culture",
                priority="stat",
            ),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="platelets",
                priority="stat",
            ),
            act("record_diagnosis", patient_id=p.patient_id, icd10_code="A39.4", certainty="provisional"),
        ],
        [
            "Looks for disseminated intravascular coagulation (platelets)",
            "Records invasive meningococcal disease as the working diagnosis",
        ],
    )
    return pathway(
        "paediatric_fever_meningococcal",
        TITLE,
        p,
        "Oscar Nilsson (patient id PW-PF02), 4 years, 16 kg, arrives by ambulance at 14:00: fever, drowsiness and a "
        "spreading purple rash.",
        patients,
        [
            _triage(
                p.patient_id,
                1,
                esi,
                escalate="fever with non-blanching rash, hypotension and drowsiness: suspected "
                "meningococcal sepsis",
                max_calls=7,
            ),
            drugs,
            work,
        ],
        "What ESI level did you assign?",
        "ESI 1",
        ["1", "ESI level 1", "level 1"],
        emergency="meningitis",
    )


def neonatal_fever() -> dict:
    p = Person("PW-PF03", "Amara Osei", 0, "female", 3.8, 52.0, age_months=0, creatinine_mg_dl=0.4)
    v = [vitals("2025-03-01T13:55", 176, 74, 44, 58, 38.4, 97, gcs=None, avpu="alert")]
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="fever in a three-week-old baby",
            history="Twenty-one-day-old girl, born at term, rectal temperature 38.4 C at home, feeding less than "
            "usual since this morning and sleepier. No rash.",
            vitals_rows=v,
            held={"glucose": (72.0, "mg/dL")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Fever 38.4 C at 21 days of age",
            hpi="Term neonate aged 21 days with fever 38.4 C and reduced feeding since the morning; no focus on "
            "history.",
            exam={
                "general": "Sleepy but rousable, fontanelle soft",
                "chest": "Clear",
                "skin": "No rash, mild jaundice",
                "umbilicus": "Clean",
            },
            vitals_rows=v,
            findings=[
                FEVER,
                finding("HP:0011968", "Feeding difficulties"),
                finding("HP:0001254", "Lethargy", "exam"),
            ],
            hidden={
                "blood_culture": ("pending at 24 h", "text", 1440),
                "urine_culture": ("pending at 24 h", "text", 1440),
                "wbc": (17.8, "10^3/uL", 30),
                "crp": (24.0, "mg/L", 45),
                "urine_wbc": (3.0, "/hpf", 20),
            },
        ),
        "drug_interaction": pharmacy_record(p, notes="Febrile neonate (21 days): empirical IV antibiotics."),
    }
    esi = {
        "requires_immediate_lifesaving_intervention": False,
        "high_risk_situation": True,
        "confused_lethargic_or_disoriented": False,
        "severe_pain_or_distress": False,
        "expected_resources": 4,
    }
    work = phase(
        "septic screen",
        "clinical_diagnosis",
        "Every febrile neonate needs a full septic screen: blood and urine cultures and inflammatory markers; record "
        "the working diagnosis.",
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
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="urine_culture",
                priority="stat",
            ),
            act("order_lab", ["patient_id", "test"], patient_id=p.patient_id, test="crp", priority="stat"),
            act("record_diagnosis", patient_id=p.patient_id, icd10_code="P81.9", certainty="provisional"),
        ],
        [
            "Does not rely on the well appearance: performs the full septic screen",
            "Treats as presumed neonatal sepsis",
        ],
    )
    drugs = phase(
        "empirical antibiotics",
        "drug_interaction",
        "Start the neonatal empirical regimen at weight-based doses.",
        [
            act("check_allergy", ["patient_id", "drug"], patient_id=p.patient_id, drug="ampicillin"),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="ampicillin",
                dose=190,
                unit="mg",
                route="IV",
                frequency="every 8 hours",
                indication="presumed neonatal sepsis (50 mg/kg)",
            ),
            act(
                "check_patient_interactions",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="gentamicin",
            ),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="gentamicin",
                dose=15,
                unit="mg",
                route="IV",
                frequency="every 24 hours",
                indication="presumed neonatal sepsis (4 mg/kg); trough level before the third dose",
            ),
        ],
        [
            "Starts ampicillin and gentamicin at neonatal weight-based doses",
            "Avoids ceftriaxone in a jaundiced neonate",
            "Plans gentamicin level monitoring",
        ],
        max_calls=6,
    )
    return pathway(
        "paediatric_fever_neonate",
        TITLE,
        p,
        "Amara Osei (patient id PW-PF03), 21 days old, 3.8 kg, is brought to the emergency department at 14:00 with "
        "a temperature of 38.4 C and reduced feeding.",
        patients,
        [_triage(p.patient_id, 2, esi, max_calls=6), work, drugs],
        "What ESI level did you assign?",
        "ESI 2",
        ["2", "ESI level 2", "level 2"],
        emergency="sepsis",
    )


def pneumonia_child() -> dict:
    p = Person("PW-PF04", "Chloe Baptiste", 6, "female", 21.0, 118.0, creatinine_mg_dl=0.4)
    v = [vitals("2025-03-01T13:54", 126, 100, 62, 28, 39.1, 93, avpu="alert")]
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="cough, fever and fast breathing",
            history="Six-year-old girl with three days of cough and fever to 39.5 C, breathing faster since last night, "
            "pain on the right when she coughs. Drinking a little. Immunised.",
            vitals_rows=v,
            held={"wbc": (18.6, "10^3/uL")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Cough, fever and fast breathing for three days",
            hpi="Three days of cough and high fever, tachypnoea since last night, right-sided pleuritic pain.",
            exam={
                "chest": "Reduced air entry and bronchial breathing at the right upper zone, no wheeze",
                "general": "Flushed, mild subcostal recession",
                "ears": "Normal",
            },
            vitals_rows=v,
            findings=[
                FEVER,
                finding("HP:0012735", "Cough"),
                finding("HP:0002789", "Tachypnea", "exam"),
                finding("HP:0033771", "Pleuritic chest pain"),
                finding("HP:0032177", "Parenchymal consolidation", "imaging", "chest_xray"),
            ],
            hidden={
                "chest_xray": ("right upper lobe consolidation, no effusion", "text", 45),
                "wbc": (18.6, "10^3/uL", 30),
                "crp": (112.0, "mg/L", 45),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, notes="Community-acquired pneumonia, 21 kg, tolerating oral fluids."
        ),
    }
    esi = {
        "requires_immediate_lifesaving_intervention": False,
        "high_risk_situation": False,
        "confused_lethargic_or_disoriented": False,
        "severe_pain_or_distress": False,
        "expected_resources": 2,
    }
    work = phase(
        "febrile work-up",
        "clinical_diagnosis",
        "Confirm the source with a chest radiograph and bloods and record the diagnosis.",
        [
            act("get_patient_info", patient_id=p.patient_id),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="chest_xray",
                priority="urgent",
            ),
            act("order_lab", ["patient_id", "test"], patient_id=p.patient_id, test="crp", priority="urgent"),
            act(
                "record_diagnosis",
                ["patient_id", "icd10_code"],
                patient_id=p.patient_id,
                icd10_code="J18.9",
                certainty="confirmed",
            ),
        ],
        ["Confirms right upper lobe consolidation on the radiograph", "Records pneumonia, J18.9"],
    )
    drugs = phase(
        "weight-based treatment",
        "drug_interaction",
        "Prescribe high-dose oral amoxicillin and paracetamol for her weight.",
        [
            act("check_allergy", ["patient_id", "drug"], patient_id=p.patient_id, drug="amoxicillin"),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="amoxicillin",
                dose=945,
                unit="mg",
                route="PO",
                frequency="twice daily for 5 days",
                indication="community-acquired pneumonia (90 mg/kg/day)",
            ),
            act(
                "check_patient_interactions",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="acetaminophen",
            ),
            *_dose(
                p.patient_id,
                "acetaminophen",
                315,
                "PO",
                "every 6 hours as needed",
                "fever and pain (15 mg/kg)",
            ),
        ],
        ["Doses amoxicillin at 90 mg/kg/day in two doses", "Doses paracetamol at 15 mg/kg (315 mg)"],
    )
    return pathway(
        "paediatric_fever_pneumonia",
        TITLE,
        p,
        "Chloe Baptiste (patient id PW-PF04), 6 years, 21 kg, is brought to the emergency department at 14:00 with "
        "three days of cough, fever and fast breathing.",
        patients,
        [_triage(p.patient_id, 3, esi), work, drugs],
        "Which ICD-10-CM code did you record?",
        "J18.9",
        ["J189"],
    )


def viral_urti() -> dict:
    p = Person(
        "PW-PF05",
        "Noah Fischer",
        2,
        "male",
        13.0,
        88.0,
        age_months=26,
        allergies=(Allergy("ibuprofen", "urticaria and wheeze", "moderate"),),
        creatinine_mg_dl=0.3,
    )
    v = [vitals("2025-03-01T13:57", 130, 98, 60, 28, 38.6, 98, avpu="alert")]
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="runny nose, cough and temperature",
            history="Two-year-old boy with a runny nose, mild cough and temperatures to 38.6 C for a day; playing, "
            "eating and drinking, wet nappies as usual. Older sister has a cold. Ibuprofen once caused hives "
            "and wheeze.",
            vitals_rows=v,
            held={},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Coryza, cough and fever for one day",
            hpi="One day of coryza, mild dry cough and fever to 38.6 C; feeding normally; playful in the waiting room.",
            exam={
                "general": "Playful, well perfused",
                "ears": "Normal tympanic membranes",
                "throat": "Mildly red, no exudate",
                "chest": "Clear, no recession",
                "skin": "No rash",
            },
            vitals_rows=v,
            findings=[FEVER, finding("HP:0031417", "Rhinorrhea"), finding("HP:0012735", "Cough")],
            hidden={},
        ),
        "drug_interaction": pharmacy_record(p, notes="Viral upper respiratory infection; ibuprofen allergy."),
    }
    esi = {
        "requires_immediate_lifesaving_intervention": False,
        "high_risk_situation": False,
        "confused_lethargic_or_disoriented": False,
        "severe_pain_or_distress": False,
        "expected_resources": 0,
    }
    work = phase(
        "examination",
        "clinical_diagnosis",
        "Examine for a bacterial focus (ears, throat, chest) and write the assessment in the chart.",
        [
            act("get_patient_info", patient_id=p.patient_id),
            act("get_physical_exam", patient_id=p.patient_id),
            act(
                "write_clinical_note",
                ["patient_id", "note_type"],
                patient_id=p.patient_id,
                note_type="progress",
                content="Well, playful 2-year-old with coryza, cough and fever for one day; normal ears, throat mildly "
                "red without exudate, chest clear. Viral upper respiratory infection; no tests or antibiotics "
                "needed.",
            ),
        ],
        [
            "Finds no bacterial focus and does not order tests or antibiotics",
            "Documents a viral upper respiratory infection",
        ],
    )
    drugs = phase(
        "antipyretic",
        "drug_interaction",
        "Choose an antipyretic he can take and dose it for his weight.",
        [
            act("check_allergy", ["patient_id", "drug"], patient_id=p.patient_id, drug="ibuprofen"),
            act("check_allergy", ["patient_id", "drug"], patient_id=p.patient_id, drug="acetaminophen"),
            *_dose(p.patient_id, "acetaminophen", 195, "PO", "every 6 hours as needed", "fever (15 mg/kg)"),
        ],
        [
            "Avoids ibuprofen because of the documented reaction",
            "Gives the parents safety-netting advice (breathing difficulty, poor drinking, fewer wet nappies)",
        ],
    )
    return pathway(
        "paediatric_fever_viral",
        TITLE,
        p,
        "Noah Fischer (patient id PW-PF05), 2 years, 13 kg, is brought to the emergency department at 14:00 with a "
        "day of runny nose, cough and temperatures.",
        patients,
        [_triage(p.patient_id, 5, esi), work, drugs],
        "What ESI level did you assign?",
        "ESI 5",
        ["5", "ESI level 5", "level 5"],
    )


def pathways() -> list[dict]:
    return [febrile_uti_toddler(), meningococcal_sepsis(), neonatal_fever(), pneumonia_child(), viral_urti()]
