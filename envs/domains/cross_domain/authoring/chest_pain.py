"""Chest pain: ED triage (vitals, ECG, STEMI alert or HEART score, ESI) -> diagnostic work-up
(troponin, differential, coded diagnosis) -> antithrombotic or analgesic prescribing checked against
the patient's medications and allergies."""

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

TITLE = "Chest pain"
STEMI_PROTOCOL = (
    "Department STEMI protocol: after aspirin 300 mg, a ticagrelor 180 mg loading dose; clopidogrel "
    "600 mg when ticagrelor cannot be used with the patient's medications."
)

# Coded findings shared by the coronary presentations (HPO).
CHEST_PAIN = finding("HP:0100749", "Chest pain")
DIAPHORESIS = finding("HP:0000975", "Diaphoresis", "exam")
NAUSEA = finding("HP:0002018", "Nausea")
DYSPNEA = finding("HP:0002094", "Dyspnea")
ST_ELEVATION = finding("HP:0012251", "ST segment elevation", "lab", "ecg")
ST_DEPRESSION = finding("HP:0012250", "ST segment depression", "lab", "ecg")
TROPONIN_UP = finding("HP:0410173", "Increased circulating troponin I concentration", "lab", "troponin_i")

CARDIAC_EXAM = {
    "general": "Pale, sweaty, in pain",
    "cardiovascular": "Regular rhythm, no murmur, JVP not raised",
    "lungs": "Clear",
    "abdomen": "Soft, non-tender",
    "extremities": "No oedema, calves soft",
}


def _triage(pid: str, esi: int, stemi: bool, extra: list | None = None) -> dict:
    actions = [
        act("get_patient_presentation", patient_id=pid),
        act("get_vital_signs", patient_id=pid),
        act("order_ecg", patient_id=pid),
    ]
    if stemi:
        actions.append(
            act(
                "activate_stemi_alert",
                patient_id=pid,
                ecg_findings="ST elevation meeting STEMI criteria on the 12-lead ECG",
            )
        )
    actions += extra or []
    actions.append(
        act(
            "assign_triage_level",
            ["patient_id", "esi_level"],
            patient_id=pid,
            esi_level=esi,
            rationale="chest pain: " + ("STEMI" if stemi else "risk-stratified"),
        )
    )
    assertions = ["Obtains a 12-lead ECG within the first minutes of arrival"]
    if stemi:
        assertions.append(
            "Recognises ST elevation and activates the STEMI alert (cath lab) before completing documentation"
        )
    assertions.append(f"Assigns ESI level {esi}")
    return phase(
        "triage",
        "triage_emergency",
        "Triage the chest pain: vital signs, a 12-lead ECG within 10 minutes, escalation if the ECG shows a "
        "STEMI, and an ESI level.",
        actions,
        assertions,
        max_calls=8,
    )


def _workup(pid: str, code: str | None, diagnosis: str) -> dict:
    record = (
        act(
            "record_diagnosis",
            ["patient_id", "icd10_code"],
            patient_id=pid,
            icd10_code=code,
            certainty="confirmed",
        )
        if code
        else act("record_diagnosis", patient_id=pid, icd10_code="I21.3", certainty="confirmed")
    )
    return phase(
        "diagnostic work-up",
        "clinical_diagnosis",
        "Confirm the diagnosis: review the chart, order a troponin, rank the differential and record the "
        "diagnosis with its ICD-10-CM code.",
        [
            act("get_patient_info", patient_id=pid),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=pid,
                test="troponin_i",
                priority="stat",
                indication="chest pain",
            ),
            act("generate_ddx", patient_id=pid, top_k=5, scope="common"),
            record,
        ],
        [
            "Orders a troponin and interprets it against the reference limit",
            f"Records {diagnosis} as the working diagnosis",
        ],
    )


def _stemi_drugs(pid: str, p2y12: str, blocked: str | None) -> dict:
    """The P2Y12 loading dose (aspirin 300 mg was given before arrival, as the histories say)."""
    dose = {"ticagrelor": 180, "clopidogrel": 600}[p2y12]
    actions = [act("check_allergy", ["patient_id", "drug"], patient_id=pid, drug=p2y12)]
    if blocked:
        actions.append(
            act("check_patient_interactions", ["patient_id", "drug"], patient_id=pid, drug=blocked)
        )
    actions += [
        act("check_patient_interactions", ["patient_id", "drug"], patient_id=pid, drug=p2y12),
        act(
            "add_medication",
            ["patient_id", "drug"],
            patient_id=pid,
            drug=p2y12,
            dose=dose,
            unit="mg",
            route="PO",
            frequency="once (loading dose)",
            indication="STEMI: P2Y12 loading before primary PCI",
        ),
    ]
    assertions = [
        "Checks allergies and the current medication list before the P2Y12 loading dose",
        "Accounts for the aspirin 300 mg already given before arrival instead of repeating it",
    ]
    if blocked:
        assertions.append(
            f"Does not give {blocked}: the interaction check reports a contraindicated combination "
            "with ritonavir, so the protocol's alternative is used"
        )
    assertions.append(f"Gives the {p2y12} loading dose before the patient leaves for the cath lab")
    return phase(
        "antithrombotic therapy",
        "drug_interaction",
        "Give the P2Y12 loading dose of the STEMI protocol, checked against allergies and the current "
        "medications.",
        actions,
        assertions,
        max_calls=6,
    )


def stemi_inferior() -> dict:
    p = Person(
        "PW-CP01",
        "Peter Walsh",
        61,
        "male",
        86.0,
        178.0,
        conditions=("hypertension", "hypercholesterolaemia", "current smoker"),
        meds=(
            Med("amlodipine", 10, "mg", "PO", "once daily", "hypertension"),
            Med("atorvastatin", 40, "mg", "PO", "once daily at night", "hypercholesterolaemia"),
        ),
        creatinine_mg_dl=1.0,
    )
    v = [vitals("2025-03-01T13:56", 92, 142, 88, 20, 36.8, 96, pain=8)]
    ecg = "sinus rhythm 90/min, 3 mm ST elevation in II, III and aVF with reciprocal ST depression in I and aVL: inferior STEMI"
    patients = {
        "triage_emergency": triage_record(
            p,
            arrival_mode="ambulance",
            chief_complaint="central crushing chest pain for 45 minutes",
            history="Central crushing chest pain radiating to the jaw and left arm since 13:10, at rest, with "
            "sweating and nausea. Aspirin 300 mg chewed, given by the paramedics at 13:40. Smoker of 30 pack-years. "
            "Takes amlodipine 10 mg and atorvastatin 40 mg.",
            vitals_rows=v,
            held={"ecg": (ecg, "text"), "troponin_i": (412.0, "ng/L")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Central crushing chest pain for 45 minutes",
            hpi="Crushing central chest pain at rest since 13:10 radiating to the jaw, with diaphoresis and nausea. "
            "Paramedics gave aspirin 300 mg at 13:40. Inferior ST elevation on the triage ECG.",
            exam=CARDIAC_EXAM,
            vitals_rows=v,
            social="Smoker, 30 pack-years; alcohol 10 units/week.",
            family="Father had a myocardial infarction at 58.",
            findings=[CHEST_PAIN, DIAPHORESIS, NAUSEA, ST_ELEVATION, TROPONIN_UP],
            hidden={
                "troponin_i": (412.0, "ng/L", 60),
                "ecg": (ecg, "text", 10),
                "potassium": (4.1, "mmol/L", 60),
                "creatinine": (1.0, "mg/dL", 60),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, notes="Inferior STEMI, going to the cath lab for primary PCI."
        ),
    }
    return pathway(
        "chest_pain_stemi_inferior",
        TITLE,
        p,
        "Peter Walsh (patient id PW-CP01), 61, arrives by ambulance at 14:00 with 45 minutes of central crushing "
        "chest pain, sweating and nausea; the paramedics gave aspirin 300 mg at 13:40. " + STEMI_PROTOCOL,
        patients,
        [
            _triage(p.patient_id, 2, True),
            _workup(p.patient_id, None, "an ST-elevation myocardial infarction"),
            _stemi_drugs(p.patient_id, "ticagrelor", None),
        ],
        "Which P2Y12 inhibitor did you prescribe? Give its generic name.",
        "ticagrelor",
        ["brilinta"],
        emergency="stemi",
    )


def stemi_on_ritonavir() -> dict:
    p = Person(
        "PW-CP02",
        "Daniel Okafor",
        54,
        "male",
        78.0,
        181.0,
        conditions=("HIV infection, virologically suppressed", "hypertension"),
        meds=(
            Med("darunavir", 800, "mg", "PO", "once daily", "HIV antiretroviral therapy"),
            Med("ritonavir", 100, "mg", "PO", "once daily", "pharmacokinetic booster of darunavir"),
            Med("tenofovir", 245, "mg", "PO", "once daily", "HIV antiretroviral therapy"),
            Med("ramipril", 5, "mg", "PO", "once daily", "hypertension"),
        ),
        creatinine_mg_dl=1.1,
    )
    v = [vitals("2025-03-01T13:57", 104, 128, 80, 22, 36.9, 95, pain=9)]
    ecg = (
        "sinus tachycardia 104/min, 4 mm ST elevation V1-V5 with reciprocal ST depression in III and aVF: "
        "anterior STEMI"
    )
    patients = {
        "triage_emergency": triage_record(
            p,
            arrival_mode="walk-in",
            chief_complaint="chest tightness and breathlessness for one hour",
            history="Heavy central chest tightness for one hour, started climbing stairs and did not settle with rest; "
            "clammy. Took aspirin 300 mg at home at 13:20 on the telephone advice of the emergency call handler. "
            "HIV on darunavir boosted with ritonavir plus tenofovir; ramipril for blood pressure.",
            vitals_rows=v,
            held={"ecg": (ecg, "text"), "troponin_i": (1860.0, "ng/L")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Chest tightness and breathlessness for one hour",
            hpi="One hour of heavy central chest tightness with breathlessness and sweating; anterior ST elevation "
            "on the triage ECG; took aspirin 300 mg at 13:20. Antiretroviral therapy: darunavir/ritonavir and "
            "tenofovir.",
            exam=CARDIAC_EXAM,
            vitals_rows=v,
            social="Never smoked; works as a bus driver.",
            findings=[CHEST_PAIN, DIAPHORESIS, DYSPNEA, ST_ELEVATION, TROPONIN_UP],
            hidden={
                "troponin_i": (1860.0, "ng/L", 60),
                "ecg": (ecg, "text", 10),
                "creatinine": (1.1, "mg/dL", 60),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, notes="Anterior STEMI for primary PCI. Boosted protease inhibitor regimen."
        ),
    }
    return pathway(
        "chest_pain_stemi_antiretroviral",
        TITLE,
        p,
        "Daniel Okafor (patient id PW-CP02), 54, walks into the emergency department at 14:00 with an hour of "
        "chest tightness and breathlessness and has chewed aspirin 300 mg. He takes antiretroviral therapy. "
        + STEMI_PROTOCOL,
        patients,
        [
            _triage(p.patient_id, 2, True),
            _workup(p.patient_id, None, "an ST-elevation myocardial infarction"),
            _stemi_drugs(p.patient_id, "clopidogrel", "ticagrelor"),
        ],
        "Which P2Y12 inhibitor did you prescribe? Give its generic name.",
        "clopidogrel",
        ["plavix"],
        emergency="stemi",
    )


def nstemi() -> dict:
    p = Person(
        "PW-CP03",
        "Margaret Doyle",
        72,
        "female",
        68.0,
        160.0,
        conditions=("type 2 diabetes mellitus", "hypertension", "chronic kidney disease stage 3a"),
        meds=(
            Med("metformin", 500, "mg", "PO", "twice daily", "type 2 diabetes"),
            Med("lisinopril", 10, "mg", "PO", "once daily", "hypertension"),
            Med("atorvastatin", 20, "mg", "PO", "once daily", "cardiovascular prevention"),
        ),
        allergies=(Allergy("codeine", "vomiting and confusion", "moderate"),),
        creatinine_mg_dl=1.3,
    )
    v = [vitals("2025-03-01T13:54", 88, 156, 84, 18, 36.7, 97, pain=6)]
    ecg = "sinus rhythm 88/min, 1.5 mm horizontal ST depression V4-V6, no ST elevation"
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="intermittent chest pressure since this morning",
            history="Three episodes of central chest pressure since 07:00, each 10-20 minutes, the last one at 13:30 "
            "with sweating; chewed aspirin 300 mg at 13:35 on the advice of the emergency call handler. Diabetic and "
            "hypertensive. Metformin, lisinopril, atorvastatin.",
            vitals_rows=v,
            held={"ecg": (ecg, "text"), "troponin_i": (96.0, "ng/L")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Intermittent chest pressure since this morning",
            hpi="Three episodes of central chest pressure at rest since 07:00 lasting 10-20 minutes, the last with "
            "sweating; aspirin 300 mg taken at 13:35. Lateral ST depression on the triage ECG; point-of-care troponin "
            "raised.",
            exam={**CARDIAC_EXAM, "general": "Comfortable at rest now"},
            vitals_rows=v,
            social="Ex-smoker (stopped 10 years ago); lives with her husband.",
            findings=[CHEST_PAIN, DIAPHORESIS, ST_DEPRESSION, TROPONIN_UP],
            labs=[("creatinine", 1.3, "mg/dL", "2025-03-01T14:10")],
            hidden={
                "troponin_i": (148.0, "ng/L", 60),
                "ecg": (ecg, "text", 10),
                "potassium": (4.6, "mmol/L", 60),
                "hba1c": (7.9, "%", 120),
            },
        ),
        "drug_interaction": pharmacy_record(p, notes="Suspected NSTEMI; CKD stage 3a."),
    }
    heart = act(
        "calculate_heart_score",
        patient_id=p.patient_id,
        history="highly",
        ecg="st_deviation",
        risk_factor_count=3,
        atherosclerotic_disease=False,
    )
    triage = _triage(
        p.patient_id,
        2,
        False,
        [
            act(
                "order_point_of_care_test", ["patient_id", "test"], patient_id=p.patient_id, test="troponin_i"
            ),
            heart,
        ],
    )
    drugs = phase(
        "anticoagulation",
        "drug_interaction",
        "Start anticoagulation for NSTEMI (aspirin was taken before arrival), checked against allergies and the "
        "medication list.",
        [
            act("check_allergy", ["patient_id", "drug"], patient_id=p.patient_id, drug="heparin"),
            act(
                "check_patient_interactions", ["patient_id", "drug"], patient_id=p.patient_id, drug="heparin"
            ),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="heparin",
                dose=4000,
                unit="units",
                route="IV",
                frequency="once (bolus), then infusion",
                indication="NSTEMI anticoagulation; aPTT at 6 hours",
            ),
        ],
        [
            "Checks the medication list for interactions before anticoagulating",
            "Does not repeat the aspirin taken before arrival",
            "Plans aPTT monitoring for unfractionated heparin",
        ],
    )
    return pathway(
        "chest_pain_nstemi",
        TITLE,
        p,
        "Margaret Doyle (patient id PW-CP03), 72, comes to the emergency department at 14:00 with intermittent chest "
        "pressure since this morning; she chewed aspirin 300 mg on the advice of the emergency call handler.",
        patients,
        [triage, _workup(p.patient_id, "I21.4", "a non-ST-elevation myocardial infarction (I21.4)"), drugs],
        "Which ICD-10-CM code did you record for the diagnosis?",
        "I21.4",
        ["I214"],
    )


def low_risk_chest_pain() -> dict:
    p = Person(
        "PW-CP04",
        "Sofia Marin",
        34,
        "female",
        61.0,
        168.0,
        conditions=("generalised anxiety disorder",),
        meds=(Med("sertraline", 100, "mg", "PO", "once daily", "generalised anxiety disorder"),),
        creatinine_mg_dl=0.7,
    )
    v = [vitals("2025-03-01T13:58", 84, 122, 76, 16, 36.6, 99, pain=4)]
    ecg = "sinus rhythm 82/min, normal axis, normal intervals, no ST or T-wave changes"
    patients = {
        "triage_emergency": triage_record(
            p,
            chief_complaint="left-sided chest pain for two days",
            history="Sharp left parasternal chest pain for two days, worse on twisting and on pressing the chest wall, "
            "started after moving furniture. No breathlessness, no sweating. Smokes 5 cigarettes a day; "
            "mother had a myocardial infarction at 52.",
            vitals_rows=v,
            held={"ecg": (ecg, "text"), "troponin_i": (3.0, "ng/L")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Left-sided chest pain for two days",
            hpi="Sharp left parasternal pain for two days after moving furniture, reproduced by pressure over the "
            "left 3rd-4th costochondral junctions, worse on twisting. Normal ECG and troponin at triage.",
            exam={
                "general": "Well, talking comfortably",
                "chest wall": "Tenderness over the left 3rd and 4th "
                "costochondral junctions reproducing the pain; no swelling",
                "cardiovascular": "Normal heart sounds",
                "lungs": "Clear",
                "extremities": "Calves soft",
            },
            vitals_rows=v,
            social="Smokes 5 cigarettes a day.",
            family="Mother had a myocardial infarction at 52.",
            findings=[CHEST_PAIN, finding("HP:0033771", "Pleuritic chest pain")],
            hidden={"troponin_i": (3.0, "ng/L", 60), "d_dimer": (0.3, "mg/L FEU", 60)},
        ),
        "drug_interaction": pharmacy_record(p, notes="Musculoskeletal chest wall pain; takes sertraline."),
    }
    heart = act(
        "calculate_heart_score",
        patient_id=p.patient_id,
        history="slightly",
        ecg="normal",
        risk_factor_count=2,
        atherosclerotic_disease=False,
    )
    triage = _triage(
        p.patient_id,
        3,
        False,
        [
            act(
                "order_point_of_care_test", ["patient_id", "test"], patient_id=p.patient_id, test="troponin_i"
            ),
            heart,
        ],
    )
    workup = phase(
        "diagnostic work-up",
        "clinical_diagnosis",
        "Examine the chest wall, repeat the troponin and record the diagnosis.",
        [
            act("get_physical_exam", patient_id=p.patient_id),
            act(
                "order_lab",
                ["patient_id", "test"],
                patient_id=p.patient_id,
                test="troponin_i",
                priority="urgent",
                indication="repeat troponin",
            ),
            act(
                "record_diagnosis",
                ["patient_id", "icd10_code"],
                patient_id=p.patient_id,
                icd10_code="R07.89",
                certainty="confirmed",
            ),
        ],
        [
            "Repeats the troponin before attributing the pain to the chest wall",
            "Records chest wall (other chest) pain, R07.89",
        ],
    )
    analgesia = phase(
        "analgesia",
        "drug_interaction",
        "Choose an anti-inflammatory analgesic that is safe with her medication.",
        [
            act("check_allergy", ["patient_id", "drug"], patient_id=p.patient_id, drug="ibuprofen"),
            act(
                "check_patient_interactions",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="ibuprofen",
            ),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="ibuprofen",
                dose=400,
                unit="mg",
                route="PO",
                frequency="three times daily with food for 5 days",
                indication="costochondral chest wall pain; aware of the sertraline bleeding interaction, short course",
            ),
        ],
        ["Checks ibuprofen against sertraline and acknowledges the bleeding-risk interaction"],
    )
    return pathway(
        "chest_pain_low_risk",
        TITLE,
        p,
        "Sofia Marin (patient id PW-CP04), 34, walks into the emergency department at 14:00 with two days of "
        "left-sided chest pain.",
        patients,
        [triage, workup, analgesia],
        "What HEART score did you calculate? Give the number.",
        "1",
        ["HEART score 1", "HEART 1"],
    )


def stemi_cardiogenic_shock() -> dict:
    p = Person(
        "PW-CP05",
        "Harold Benson",
        68,
        "male",
        92.0,
        176.0,
        conditions=("type 2 diabetes mellitus", "hypertension", "peripheral arterial disease"),
        meds=(
            Med("metformin", 1000, "mg", "PO", "twice daily", "type 2 diabetes"),
            Med("clopidogrel", 75, "mg", "PO", "once daily", "peripheral arterial disease"),
            Med("simvastatin", 40, "mg", "PO", "once daily", "peripheral arterial disease"),
        ),
        allergies=(Allergy("morphine", "anaphylaxis", "severe"),),
        creatinine_mg_dl=1.2,
    )
    v = [vitals("2025-03-01T13:59", 118, 78, 46, 28, 36.1, 89, gcs=(3, 5, 6), avpu="alert", pain=9)]
    ecg = (
        "sinus tachycardia 118/min, 5 mm ST elevation V1-V6, I and aVL, with new right bundle branch block: "
        "extensive anterior STEMI"
    )
    patients = {
        "triage_emergency": triage_record(
            p,
            arrival_mode="ambulance",
            chief_complaint="chest pain, grey and clammy, low blood pressure",
            history="Crushing chest pain for two hours; grey, cold and clammy on the ambulance crew's arrival; "
            "blood pressure 80/50 in the ambulance; paramedics gave aspirin 300 mg at 13:45. Takes clopidogrel for "
            "leg arteries, metformin, simvastatin. Anaphylaxis to morphine.",
            vitals_rows=v,
            held={"ecg": (ecg, "text"), "troponin_i": (5200.0, "ng/L"), "lactate": (4.8, "mmol/L")},
        ),
        "clinical_diagnosis": clinical_record(
            p,
            chief_complaint="Chest pain with hypotension",
            hpi="Two hours of crushing chest pain; hypotensive (78/46), tachycardic and hypoxic; extensive anterior "
            "ST elevation; cold peripheries suggesting cardiogenic shock. Aspirin 300 mg given by the paramedics.",
            exam={
                "general": "Grey, clammy, drowsy but rousable",
                "cardiovascular": "Cold peripheries, thready pulse, JVP raised",
                "lungs": "Bibasal crackles",
                "abdomen": "Soft",
            },
            vitals_rows=v,
            social="Retired; ex-smoker.",
            findings=[CHEST_PAIN, DIAPHORESIS, DYSPNEA, ST_ELEVATION, TROPONIN_UP],
            hidden={
                "troponin_i": (5200.0, "ng/L", 60),
                "ecg": (ecg, "text", 10),
                "lactate": (4.8, "mmol/L", 30),
            },
        ),
        "drug_interaction": pharmacy_record(
            p, notes="Extensive anterior STEMI with cardiogenic shock; already on clopidogrel 75 mg daily."
        ),
    }
    triage = _triage(
        p.patient_id,
        1,
        True,
        [
            act(
                "escalate_care",
                ["patient_id", "level"],
                patient_id=p.patient_id,
                level="resuscitation_team",
                reason="cardiogenic shock with anterior STEMI: SBP 78, SpO2 89%",
            ),
            act(
                "calculate_esi_level",
                patient_id=p.patient_id,
                requires_immediate_lifesaving_intervention=True,
                high_risk_situation=True,
                confused_lethargic_or_disoriented=False,
                severe_pain_or_distress=True,
                expected_resources=5,
            ),
        ],
    )
    drugs = phase(
        "medication safety for the cath lab",
        "drug_interaction",
        "Before primary PCI in shock: review the medication list, stop any drug that is unsafe in shock or with "
        "iodinated contrast, and start heparin.",
        [
            act("get_patient_medications", patient_id=p.patient_id),
            act(
                "discontinue_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="metformin",
                reason="cardiogenic shock with lactate 4.8 and iodinated contrast for PCI: lactic acidosis risk",
            ),
            act(
                "check_patient_interactions", ["patient_id", "drug"], patient_id=p.patient_id, drug="heparin"
            ),
            act(
                "add_medication",
                ["patient_id", "drug"],
                patient_id=p.patient_id,
                drug="heparin",
                dose=5000,
                unit="units",
                route="IV",
                frequency="once (bolus) before PCI",
                indication="STEMI: anticoagulation for primary PCI; aPTT/ACT monitoring",
            ),
        ],
        [
            "Stops metformin because of shock, hyperlactataemia and contrast",
            (
                "Continues clopidogrel and leaves the P2Y12 strategy to the interventional team instead of adding a second "
                "P2Y12 inhibitor"
            ),
            "Avoids morphine for analgesia because of the documented anaphylaxis",
        ],
        max_calls=6,
    )
    return pathway(
        "chest_pain_stemi_shock",
        TITLE,
        p,
        "Harold Benson (patient id PW-CP05), 68, is brought in by ambulance at 14:00 with two hours of crushing "
        "chest pain; the crew report a blood pressure of 80/50. He already takes clopidogrel; the interventional "
        "team will decide on the P2Y12 strategy in the cath lab.",
        patients,
        [
            triage,
            _workup(p.patient_id, None, "an ST-elevation myocardial infarction with cardiogenic shock"),
            drugs,
        ],
        "What ESI level did you assign?",
        "ESI 1",
        ["1", "ESI level 1", "level 1"],
        emergency="stemi",
    )


def pathways() -> list[dict]:
    return [
        stemi_inferior(),
        stemi_on_ritonavir(),
        nstemi(),
        low_risk_chest_pain(),
        stemi_cardiogenic_shock(),
    ]
