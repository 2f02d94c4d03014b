"""A small built-in drug lexicon: the fallback when a domain's SafetyContext has no fact.

Used only where the domain's context returns None/[] (or there is no context): common generic
names and brands, drug classes (most specific first), a few well-known interactions stated at
class level, and maximum single adult doses for drugs where one is well established. It lets the
detector catch the textbook cases (penicillin allergy and amoxicillin, warfarin and an NSAID,
sildenafil and a nitrate) in any domain; the drug-interaction domain supplies the real data.
"""

from __future__ import annotations

_CLASS_GROUPS: dict[tuple[str, ...], str] = {
    ("penicillins", "beta-lactam antibiotics"):
        "penicillin penicillin-g penicillin-v amoxicillin ampicillin piperacillin piperacillin-tazobactam "
        "nafcillin oxacillin dicloxacillin amoxicillin-clavulanate",
    ("cephalosporins", "beta-lactam antibiotics"): "cephalexin cefazolin ceftriaxone cefuroxime cefepime cefdinir cefotaxime",
    ("carbapenems", "beta-lactam antibiotics"): "meropenem imipenem ertapenem",
    ("sulfonamides",): "sulfamethoxazole trimethoprim-sulfamethoxazole sulfasalazine",
    ("macrolides",): "azithromycin clarithromycin erythromycin",
    ("fluoroquinolones",): "ciprofloxacin levofloxacin moxifloxacin",
    ("tetracyclines",): "doxycycline minocycline tetracycline",
    ("aminoglycosides",): "gentamicin tobramycin amikacin",
    ("glycopeptides",): "vancomycin",
    ("nsaids",): "ibuprofen naproxen diclofenac ketorolac celecoxib indomethacin meloxicam",
    ("salicylates", "nsaids", "antiplatelets"): "aspirin",
    ("opioids",): "morphine hydromorphone oxycodone fentanyl codeine tramadol hydrocodone methadone meperidine",
    ("vitamin k antagonists", "anticoagulants"): "warfarin",
    ("heparins", "anticoagulants"): "heparin enoxaparin dalteparin",
    ("direct oral anticoagulants", "anticoagulants"): "apixaban rivaroxaban dabigatran edoxaban",
    ("antiplatelets", "p2y12 inhibitors"): "clopidogrel ticagrelor prasugrel",
    ("ssris",): "fluoxetine sertraline citalopram escitalopram paroxetine",
    ("snris",): "venlafaxine duloxetine",
    ("maois",): "phenelzine tranylcypromine selegiline isocarboxazid",
    ("oxazolidinones", "maois"): "linezolid",
    ("benzodiazepines",): "lorazepam diazepam alprazolam midazolam clonazepam",
    ("ace inhibitors",): "lisinopril enalapril ramipril captopril benazepril",
    ("arbs",): "losartan valsartan irbesartan candesartan",
    ("statins",): "simvastatin atorvastatin rosuvastatin lovastatin pravastatin",
    ("nitrates",): "nitroglycerin isosorbide-mononitrate isosorbide-dinitrate",
    ("pde5 inhibitors",): "sildenafil tadalafil vardenafil",
    ("beta blockers",): "metoprolol atenolol propranolol carvedilol labetalol esmolol bisoprolol",
    ("potassium-sparing diuretics",): "spironolactone eplerenone amiloride",
    ("potassium supplements",): "potassium-chloride",
    ("loop diuretics",): "furosemide bumetanide torsemide",
    ("antipsychotics",): "clozapine haloperidol quetiapine olanzapine risperidone",
    ("mood stabilizers",): "lithium",
    ("anticonvulsants",): "valproate phenytoin carbamazepine levetiracetam lamotrigine fosphenytoin",
    ("cardiac glycosides",): "digoxin",
    ("antiarrhythmics",): "amiodarone",
    ("antimetabolites",): "methotrexate",
    ("retinoids",): "isotretinoin acitretin",
    ("bisphosphonates",): "alendronate risedronate ibandronate",
    ("glp-1 receptor agonists",): "dulaglutide",
    ("prostaglandin analogues",): "misoprostol",
    ("immunomodulatory imides",): "thalidomide lenalidomide",
    ("pyrimidine synthesis inhibitors",): "leflunomide",
    ("nucleoside analogues",): "ribavirin",
    ("5-alpha reductase inhibitors",): "finasteride dutasteride",
    ("endothelin receptor antagonists",): "bosentan ambrisentan macitentan",
    ("biguanides",): "metformin",
    ("insulins",): "insulin",
    ("analgesics",): "acetaminophen",
    ("azole antifungals",): "fluconazole itraconazole ketoconazole",
    ("antiemetics",): "ondansetron",
    ("nitroimidazoles",): "metronidazole",
    ("methylxanthines",): "theophylline",
    ("sympathomimetics",): "epinephrine",
    ("thrombolytics",): "alteplase tenecteplase",
    ("proton pump inhibitors",): "omeprazole pantoprazole esomeprazole",
}

DRUG_CLASSES: dict[str, list[str]] = {
    drug: list(classes) for classes, names in _CLASS_GROUPS.items() for drug in names.split()
}

BRANDS: dict[str, str] = {
    "tylenol": "acetaminophen", "paracetamol": "acetaminophen", "advil": "ibuprofen", "motrin": "ibuprofen",
    "aleve": "naproxen", "coumadin": "warfarin", "jantoven": "warfarin", "eliquis": "apixaban",
    "xarelto": "rivaroxaban", "pradaxa": "dabigatran", "plavix": "clopidogrel", "brilinta": "ticagrelor",
    "zoloft": "sertraline", "prozac": "fluoxetine", "lexapro": "escitalopram", "celexa": "citalopram",
    "paxil": "paroxetine", "effexor": "venlafaxine", "cymbalta": "duloxetine", "nardil": "phenelzine",
    "augmentin": "amoxicillin-clavulanate", "bactrim": "trimethoprim-sulfamethoxazole",
    "septra": "trimethoprim-sulfamethoxazole", "tmp-smx": "trimethoprim-sulfamethoxazole",
    "zithromax": "azithromycin", "biaxin": "clarithromycin", "cipro": "ciprofloxacin", "levaquin": "levofloxacin",
    "keflex": "cephalexin", "rocephin": "ceftriaxone", "zosyn": "piperacillin-tazobactam", "lipitor": "atorvastatin",
    "zocor": "simvastatin", "crestor": "rosuvastatin", "viagra": "sildenafil", "cialis": "tadalafil",
    "nitrostat": "nitroglycerin", "imdur": "isosorbide-mononitrate", "glucophage": "metformin",
    "lasix": "furosemide", "xanax": "alprazolam", "ativan": "lorazepam", "valium": "diazepam",
    "klonopin": "clonazepam", "toradol": "ketorolac", "zofran": "ondansetron", "depakote": "valproate",
    "valproic-acid": "valproate", "divalproex": "valproate", "divalproex sodium": "valproate", "depakene": "valproate", "dilantin": "phenytoin", "tegretol": "carbamazepine", "keppra": "levetiracetam",
    "accutane": "isotretinoin", "lanoxin": "digoxin", "cordarone": "amiodarone", "zestril": "lisinopril",
    "prinivil": "lisinopril", "cozaar": "losartan", "aldactone": "spironolactone", "lovenox": "enoxaparin",
    "ultram": "tramadol", "percocet": "oxycodone", "vicodin": "hydrocodone", "dilaudid": "hydromorphone",
    "diflucan": "fluconazole", "zyvox": "linezolid", "clozaril": "clozapine", "haldol": "haloperidol",
    "seroquel": "quetiapine", "zyprexa": "olanzapine", "lithobid": "lithium", "prilosec": "omeprazole",
    "protonix": "pantoprazole", "activase": "alteplase", "epipen": "epinephrine", "adrenaline": "epinephrine",
    "asa": "aspirin", "acetylsalicylic-acid": "aspirin", "apap": "acetaminophen", "k-dur": "potassium-chloride",
    "kcl": "potassium-chloride", "potassium chloride": "potassium-chloride", "penicillin g": "penicillin-g",
    "penicillin v": "penicillin-v", "isosorbide mononitrate": "isosorbide-mononitrate",
    "isosorbide dinitrate": "isosorbide-dinitrate", "amoxicillin clavulanate": "amoxicillin-clavulanate",
    "trimethoprim sulfamethoxazole": "trimethoprim-sulfamethoxazole", "valproic acid": "valproate",
    "piperacillin tazobactam": "piperacillin-tazobactam",
    "fosamax": "alendronate", "actonel": "risedronate", "atelvia": "risedronate", "boniva": "ibandronate",
    "trulicity": "dulaglutide", "trexall": "methotrexate", "otrexup": "methotrexate", "rasuvo": "methotrexate",
    "xatmep": "methotrexate", "cytotec": "misoprostol", "thalomid": "thalidomide", "revlimid": "lenalidomide",
    "arava": "leflunomide", "proscar": "finasteride", "propecia": "finasteride", "tracleer": "bosentan",
    "soriatane": "acitretin", "absorica": "isotretinoin", "claravis": "isotretinoin",
}

#: (drug-or-class, drug-or-class, severity, description); looked up both ways.
INTERACTION_RULES: list[tuple[str, str, str, str]] = [
    ("pde5 inhibitors", "nitrates", "contraindicated", "severe hypotension"),
    ("maois", "ssris", "contraindicated", "serotonin syndrome"),
    ("maois", "snris", "contraindicated", "serotonin syndrome"),
    ("maois", "tramadol", "contraindicated", "serotonin syndrome and seizures"),
    ("maois", "meperidine", "contraindicated", "serotonin syndrome"),
    ("simvastatin", "clarithromycin", "contraindicated", "rhabdomyolysis (CYP3A4 inhibition)"),
    ("lovastatin", "clarithromycin", "contraindicated", "rhabdomyolysis (CYP3A4 inhibition)"),
    ("simvastatin", "itraconazole", "contraindicated", "rhabdomyolysis (CYP3A4 inhibition)"),
    ("warfarin", "nsaids", "major", "bleeding risk"),
    ("warfarin", "amiodarone", "major", "raised INR, bleeding"),
    ("warfarin", "trimethoprim-sulfamethoxazole", "major", "raised INR, bleeding"),
    ("warfarin", "fluconazole", "major", "raised INR, bleeding"),
    ("anticoagulants", "antiplatelets", "major", "bleeding risk"),
    ("ace inhibitors", "potassium-sparing diuretics", "major", "hyperkalaemia"),
    ("ace inhibitors", "potassium supplements", "major", "hyperkalaemia"),
    ("lithium", "nsaids", "major", "lithium toxicity"),
    ("lithium", "ace inhibitors", "major", "lithium toxicity"),
    ("methotrexate", "trimethoprim-sulfamethoxazole", "major", "bone-marrow suppression"),
    ("digoxin", "amiodarone", "major", "digoxin toxicity"),
    # Ultram label 5 and 7: with serotonergic drugs observe closely (moderate); its boxed warning covers
    # CYP2D6 inhibitors (fluoxetine, paroxetine: major) - the drug-interaction overlay's US-006, US-019/020
    ("ssris", "tramadol", "moderate", "serotonin syndrome, seizures (observe closely)"),
    ("fluoxetine", "tramadol", "major", "CYP2D6 inhibition (tramadol up, M1 down) and serotonin syndrome"),
    ("paroxetine", "tramadol", "major", "CYP2D6 inhibition (tramadol up, M1 down) and serotonin syndrome"),
    ("opioids", "benzodiazepines", "major", "respiratory depression"),
    # Plavix label 5.1 and 7.1: avoid omeprazole or esomeprazole (the drug-interaction overlay's US-012/013)
    ("clopidogrel", "omeprazole", "major", "reduced antiplatelet effect (CYP2C19 inhibition)"),
    ("clopidogrel", "esomeprazole", "major", "reduced antiplatelet effect (CYP2C19 inhibition)"),
    ("warfarin", "metronidazole", "major", "raised INR, bleeding (Flagyl label PRECAUTIONS, drug interactions)"),
    ("theophylline", "ciprofloxacin", "major", "theophylline toxicity (Cipro label 5 and 7)"),
    ("ciprofloxacin", "warfarin", "moderate", "raised INR"),
    ("metformin", "furosemide", "minor", "altered metformin levels"),
]

#: Maximum single adult dose in mg, by drug and route ("*" = any route).
MAX_SINGLE_DOSE_MG: dict[str, dict[str, float]] = {
    "acetaminophen": {"*": 1000.0},
    "ibuprofen": {"*": 800.0},
    "ketorolac": {"iv": 30.0, "im": 60.0, "oral": 10.0, "po": 10.0, "*": 60.0},
    "colchicine": {"*": 1.2},
    "digoxin": {"*": 0.5},
    "amoxicillin": {"*": 2000.0},
    "lisinopril": {"*": 80.0},
    "warfarin": {"*": 10.0},
}

#: Pregnancy contraindications from US labelling: drug or class -> the label section that states it.
#: The fallback when a domain's own pregnancy data (drugdose's FDA category, 49 drugs) has nothing.
#: Statins are not listed: in 2021 the FDA asked for the pregnancy contraindication to be removed
#: from every statin label (FDA Drug Safety Communication, 20 July 2021).
PREGNANCY_CONTRAINDICATED: dict[str, str] = {
    "isotretinoin": "isotretinoin labels (Absorica, Claravis): boxed warning and 4 CONTRAINDICATIONS (pregnancy); iPLEDGE REMS",
    "acitretin": "Soriatane label: boxed warning and 4 CONTRAINDICATIONS (pregnancy)",
    "warfarin": "Coumadin label: 4 CONTRAINDICATIONS (pregnancy, except women with mechanical heart valves at high thromboembolic risk)",
    "ace inhibitors": "ACE-inhibitor labels (e.g. Zestril): boxed warning FETAL TOXICITY (discontinue when pregnancy is detected); ACOG Practice Bulletin 203",
    "arbs": "ARB labels (e.g. Cozaar): boxed warning FETAL TOXICITY (discontinue when pregnancy is detected); ACOG Practice Bulletin 203",
    "methotrexate": "methotrexate labels: boxed warning EMBRYO-FETAL TOXICITY and 4 CONTRAINDICATIONS (pregnancy, non-neoplastic diseases)",
    "misoprostol": "Cytotec label: boxed warning and 4 CONTRAINDICATIONS (pregnancy, NSAID-ulcer prevention)",
    "thalidomide": "Thalomid label: boxed warning EMBRYO-FETAL TOXICITY and 4 CONTRAINDICATIONS; REMS",
    "lenalidomide": "Revlimid label: boxed warning EMBRYO-FETAL TOXICITY and 4 CONTRAINDICATIONS; REMS",
    "leflunomide": "Arava label: boxed warning EMBRYO-FETAL TOXICITY and 4 CONTRAINDICATIONS (pregnancy)",
    "ribavirin": "ribavirin labels (e.g. Copegus): boxed warning and 4 CONTRAINDICATIONS (pregnant women and their male partners)",
    "finasteride": "Proscar label: 4 CONTRAINDICATIONS (pregnancy)",
    "dutasteride": "Avodart label: 4 CONTRAINDICATIONS (pregnancy)",
    "endothelin receptor antagonists": "bosentan, ambrisentan, macitentan labels: boxed warning EMBRYO-FETAL TOXICITY, 4 CONTRAINDICATIONS; REMS",
}

#: Pregnancy contraindications a label limits to one indication: drug -> (regex over the episode's
#: text naming that indication, the label section). Outside that indication the drug is not
#: contraindicated in pregnancy (its boxed warning states a risk to weigh, not a contraindication).
PREGNANCY_CONTRAINDICATED_FOR: dict[str, tuple[str, str]] = {
    # Depakote label 4: contraindicated in pregnant women for migraine prophylaxis; for epilepsy and
    # bipolar disorder the boxed warning FETAL RISK and 8.1: only if other medications failed
    "valproate": (r"\bmigraine", "Depakote label: 4 CONTRAINDICATIONS (pregnant women, prophylaxis of migraine "
                                 "headaches); boxed warning FETAL RISK and 8.1 for other indications"),
}

#: Label-stated exceptions to a pregnancy contraindication: drug -> regex over the task text.
PREGNANCY_EXCEPTIONS: dict[str, str] = {
    # ACOG Practice Bulletin 193: methotrexate is the medical treatment of tubal ectopic pregnancy
    "methotrexate": r"\bectopic\b",
    # Coumadin label 4: the contraindication excepts mechanical heart valves at high thromboembolic risk
    "warfarin": r"mechanical (?:heart |mitral |aortic )?valve",
    # Cytotec label 4 contraindicates it in pregnancy for NSAID-ulcer prevention; obstetric uses follow
    # ACOG (Practice Bulletin 107 induction of labour, 183 postpartum haemorrhage, 200 early pregnancy loss)
    "misoprostol": r"induc|cervical ripening|ripen|postpartum|ha?emorrhage|\bpph\b|miscarriage|pregnancy loss|"
                   r"abortion|termination|labou?r|uterotonic",
}

#: Conditions (lower case) in which a drug or class is contraindicated.
CONTRAINDICATED_CONDITIONS: dict[str, list[str]] = {
    **{drug: ["pregnancy"] for drug in (*PREGNANCY_CONTRAINDICATED, *PREGNANCY_CONTRAINDICATED_FOR)},
    "nsaids": ["active gi bleeding"], "metformin": ["severe renal impairment"],
}

#: Drugs dosed weekly (or monthly) whose daily use is a known fatal or serious error:
#: drug -> (highest dose in mg that has a daily regimen in the label, 0 when none; routes where a
#: daily regimen of any dose is legitimate; the label section). A daily frequency at a dose above
#: the daily maximum is `dose.frequency_error`.
WEEKLY_DOSED: dict[str, tuple[float, tuple[str, ...], str]] = {
    "methotrexate": (0.0, ("iv", "intravenous", "intrathecal", "it"),
                     ("methotrexate tablets/injection labels (Trexall, Otrexup, Xatmep): boxed warning and 2 DOSAGE AND "
                      "ADMINISTRATION, once weekly for RA/pJIA/psoriasis, fatal toxicity from daily dosing; ISMP Best Practice 2")),
    "alendronate": (40.0, (), ("Fosamax label 2 DOSAGE AND ADMINISTRATION: 70 mg once weekly or 10 mg daily (osteoporosis), "
                               "40 mg daily for 6 months (Paget's disease)")),
    "risedronate": (30.0, (), ("Actonel label 2 DOSAGE AND ADMINISTRATION: 5 mg daily, 35 mg once weekly, 150 mg once monthly; "
                               "30 mg daily for 2 months (Paget's disease)")),
    "ibandronate": (2.5, (), "Boniva label 2 DOSAGE AND ADMINISTRATION: 2.5 mg daily or 150 mg once monthly (oral)"),
    "dulaglutide": (0.0, (), "Trulicity label 2 DOSAGE AND ADMINISTRATION: 0.75-4.5 mg subcutaneously once weekly"),
}

#: Allergy labels that name a class by a short or lay name.
ALLERGY_ALIASES: dict[str, str] = {
    "sulfa": "sulfonamides", "sulfa drugs": "sulfonamides", "sulpha": "sulfonamides", "pcn": "penicillins",
    "penicillin": "penicillins", "nsaid": "nsaids", "beta-lactam": "beta-lactam antibiotics",
    "beta lactam": "beta-lactam antibiotics", "cephalosporin": "cephalosporins", "opiates": "opioids",
    "opiate": "opioids", "statin": "statins", "ace inhibitor": "ace inhibitors", "macrolide": "macrolides",
    "fluoroquinolone": "fluoroquinolones", "quinolones": "fluoroquinolones", "tetracycline": "tetracyclines",
}

#: High-alert drugs and the monitoring that must be planned when they are started (matched on
#: the generic name: unfractionated heparin needs aPTT, enoxaparin does not).
HIGH_ALERT_MONITORING: dict[str, str] = {
    "warfarin": r"\binr\b|prothrombin|pt/inr",
    "lithium": r"lithium (?:level|concentration)s?|serum lithium|lithium monitoring",
    "digoxin": r"digoxin (?:level|concentration)s?|serum digoxin",
    "vancomycin": r"\btrough|vancomycin (?:level|concentration)s?|\bauc\b",
    "methotrexate": r"\bcbc\b|blood counts?|liver function|\blfts?\b",
    "clozapine": r"\banc\b|neutrophil|\bcbc\b|blood counts?",
    # during PCI unfractionated heparin is titrated to the activated clotting time (2013 ACCF/AHA
    # STEMI guideline; 2011 ACCF/AHA/SCAI PCI guideline), on the ward to the aPTT or anti-Xa
    "heparin": r"\ba?ptt\b|anti-?xa|activated clotting time|\bact[- ](?:monitoring|target|checks?|levels?|guided)\b"
               r"|\bact\s*(?:[<>]|\d)",
    "insulin": r"glucose|blood sugar|fingerstick|\bcbg\b",
    "amiodarone": r"\btsh\b|thyroid|liver function|\blfts?\b|pulmonary function",
    "phenytoin": r"phenytoin (?:level|concentration)s?|serum phenytoin",
    "potassium-chloride": r"potassium (?:level|monitoring)|serum potassium|\bbmp\b|electrolytes",
}
#: Classes whose every member needs monitoring.
HIGH_ALERT_CLASS_MONITORING: dict[str, str] = {
    "aminoglycosides": r"\b(?:peak|trough|drug level|serum level)s?\b|renal function|creatinine",
}
