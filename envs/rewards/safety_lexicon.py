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
    ("retinoids",): "isotretinoin",
    ("biguanides",): "metformin",
    ("insulins",): "insulin",
    ("analgesics",): "acetaminophen",
    ("azole antifungals",): "fluconazole itraconazole ketoconazole",
    ("antiemetics",): "ondansetron",
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
    "valproic-acid": "valproate", "dilantin": "phenytoin", "tegretol": "carbamazepine", "keppra": "levetiracetam",
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
    ("ssris", "tramadol", "major", "serotonin syndrome, seizures"),
    ("opioids", "benzodiazepines", "major", "respiratory depression"),
    ("clopidogrel", "omeprazole", "moderate", "reduced antiplatelet effect"),
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

#: Conditions (lower case) in which a drug or class is contraindicated.
CONTRAINDICATED_CONDITIONS: dict[str, list[str]] = {
    "isotretinoin": ["pregnancy"], "warfarin": ["pregnancy"], "methotrexate": ["pregnancy"],
    "valproate": ["pregnancy"], "ace inhibitors": ["pregnancy"], "arbs": ["pregnancy"], "statins": ["pregnancy"],
    "nsaids": ["active gi bleeding"], "metformin": ["severe renal impairment"],
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
    "heparin": r"\ba?ptt\b|anti-?xa",
    "insulin": r"glucose|blood sugar|fingerstick|\bcbg\b",
    "amiodarone": r"\btsh\b|thyroid|liver function|\blfts?\b|pulmonary function",
    "phenytoin": r"phenytoin (?:level|concentration)s?|serum phenytoin",
    "potassium-chloride": r"potassium (?:level|monitoring)|serum potassium|\bbmp\b|electrolytes",
}
#: Classes whose every member needs monitoring.
HIGH_ALERT_CLASS_MONITORING: dict[str, str] = {
    "aminoglycosides": r"\b(?:peak|trough|drug level|serum level)s?\b|renal function|creatinine",
}
