"""The clinical computations behind the tools, as plain functions over the database.

Tools (tools.py) wrap these with agent-facing errors; the task generator (generate.py) uses the
same functions to compute its oracles, so a gold answer is exactly what the tools return.
Every rule below is either read from the data or stated here explicitly (hepatic policy,
pregnancy category meanings, renal-function formulas).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from envs.core.fuzzy import close_matches
from envs.domains.pregnancy_labels import PACKAGE_LETTER_BASIS, PREGNANCY_LABEL_RULES, PregnancyLabelRule, rule_report  # noqa: F401

from .data_model import (
    DoseProfile, Drug, DrugClass, DrugInteractionDB, InteractionRule, Patient, RenalProfile, RouteDose, SeverityLevel,
)
from .translate import SEVERITY_RANK, fold


class LookupFailure(LookupError):
    """A name, id or route the database does not know; the message lists what it does know."""


# -- names ---------------------------------------------------------------------------------------
def resolve_drug(db: DrugInteractionDB, name: str) -> Drug:
    """A drug by generic name, brand name, synonym or ANSM French name (case/accents ignored)."""
    key = fold(name or "")
    drug_id = db.name_index.get(key)
    if drug_id is None and key.endswith("s"):
        drug_id = db.name_index.get(key[:-1])
    if drug_id is None:
        # difflib's suggestions from a cached index of the name table: ~0.3 ms instead of ~15 ms
        near = close_matches(key, db.name_index, n=5, cutoff=0.75)
        hint = f"; did you mean: {', '.join(near)}?" if near else ""
        raise LookupFailure(f"drug {name!r} is not in the formulary{hint}")
    return db.drugs[drug_id]


def resolve_class(db: DrugInteractionDB, name: str) -> DrugClass:
    """A class by English name, id or French ANSM label."""
    key = fold(name or "")
    cid = db.class_index.get(key)
    if cid is None:
        cid = db.class_index.get(fold(key.replace(" ", "-")))
    if cid is None:
        hits = search_classes(db, name)
        if len(hits) == 1:  # "statins" -> "HMG-CoA reductase inhibitors (statins)"
            return hits[0]
        near = hits[:5]
        hint = f"; matching classes: {', '.join(c.name for c in near)}" if near else ""
        raise LookupFailure(f"drug class {name!r} not found{hint}")
    return db.classes[cid]


def search_classes(db: DrugInteractionDB, query: str) -> list[DrugClass]:
    """Classes whose English or French name contains every word of the query."""
    words = [w for w in fold(query).replace("-", " ").split() if w]
    hits = []
    for cls in db.classes.values():
        text = fold(f"{cls.name} {cls.name_fr} {cls.id}").replace("-", " ")
        if words and all(w in text for w in words):
            hits.append(cls)
    return sorted(hits, key=lambda c: (len(c.name), c.id))


def _non_drug_party(db: DrugInteractionDB, key: str) -> DrugClass | None:
    for cls in db.classes.values():
        if cls.kind != "class" and (key in (fold(cls.name), fold(cls.name_fr), cls.id)
                                    or key == fold(cls.name).split(" (")[0]):
            return cls
    return None


def resolve_party(db: DrugInteractionDB, name: str) -> tuple[str, Drug | DrugClass]:
    """A drug, or failing that a non-drug ANSM party such as grapefruit or alcohol."""
    key = fold(name or "")
    if key not in db.name_index and not (key.endswith("s") and key[:-1] in db.name_index):
        # Check the few non-drug parties before resolve_drug's fuzzy suggestions, which scan every
        # drug name (tens of milliseconds) only to build an error message.
        party = _non_drug_party(db, key)
        if party is not None:
            return "party", party
    return "drug", resolve_drug(db, name)


def get_patient(db: DrugInteractionDB, patient_id: str) -> Patient:
    patient = db.patients.get((patient_id or "").strip().upper())
    if patient is None:
        known = sorted(db.patients)
        raise LookupFailure(f"patient {patient_id!r} not found; known patients: {', '.join(known[:8])}"
                            f"{' ...' if len(known) > 8 else ''} ({len(known)} in all)")
    return patient


# -- interactions --------------------------------------------------------------------------------
def party_keys(db: DrugInteractionDB, subject: Drug | DrugClass) -> list[str]:
    """The rule keys that apply to a drug: itself and every ANSM class it belongs to, and for a fixed
    combination ("trimethoprim/sulfamethoxazole") the keys of each component, whose rules it carries."""
    if isinstance(subject, Drug):
        keys = [f"drug:{subject.id}"] + [f"class:{c}" for c in subject.class_ids]
        for part in combination_components(db, subject):
            keys += [f"drug:{part.id}"] + [f"class:{c}" for c in part.class_ids]
        return list(dict.fromkeys(keys))
    return [f"class:{subject.id}"]


def rules_between(db: DrugInteractionDB, a: Drug | DrugClass, b: Drug | DrugClass) -> list[InteractionRule]:
    """Every ANSM rule whose two parties cover a and b (substance or class level)."""
    if a.id == b.id and type(a) is type(b):
        return []
    keys_a, keys_b = party_keys(db, a), set(party_keys(db, b))
    found: dict[str, InteractionRule] = {}
    for key in keys_a:
        for rule_id in db.party_index.get(key, []):
            rule = db.interactions[rule_id]
            ka, kb = rule.party_a.key, rule.party_b.key
            if (ka == key and kb in keys_b) or (kb == key and ka in keys_b):
                found[rule_id] = rule
    return sorted(found.values(), key=lambda r: r.id)


@dataclass(frozen=True)
class PairContext:
    """What the patient adds to a pair's assessment: daily doses in mg (drug id -> mg/day) and eGFR.
    Dose- and renal-conditional levels are evaluated at these values; without them the most
    severe level applies."""

    daily_mg: tuple[tuple[str, float], ...] = ()
    egfr: float | None = None

    def dose(self, drug_id: str) -> float | None:
        return next((mg for d, mg in self.daily_mg if d == drug_id), None)


_PER_DAY = [
    (re.compile(r"\b(?:four times|qid|q\.i\.d)\b|every 6 ?h|q6h"), 4.0),
    (re.compile(r"\b(?:three times|tid|t\.i\.d)\b|every 8 ?h|q8h"), 3.0),
    (re.compile(r"\b(?:twice|bid|b\.i\.d)\b|every 12 ?h|q12h"), 2.0),
    (re.compile(r"\bweekly\b|\bweek\b"), 1.0 / 7.0),
    (re.compile(r"\b(?:once|daily|every day|qd|od|nightly|at bedtime|every 24 ?h|q24h|each morning)\b"), 1.0),
]


def daily_dose_mg(dose: float, unit: str, frequency: str) -> float | None:
    """mg per day for an order ("81 mg once daily" -> 81; "500 mg every 8 hours" -> 1500); None when
    the unit is not a mass or the frequency is not recognised (as needed, continuous infusion...)."""
    scale = _MASS_TO_MG.get(_norm_unit(unit or ""))
    if scale is None or dose <= 0:
        return None
    freq = fold(frequency or "")
    for pattern, per_day in _PER_DAY:
        if pattern.search(freq):
            return round(dose * scale * per_day, 4)
    return None


def patient_context(db: DrugInteractionDB, patient: Patient, extra: dict[str, float] | None = None) -> PairContext:
    """The patient's daily doses (active orders) and eGFR; `extra` adds a proposed drug's daily dose."""
    doses: dict[str, float] = {}
    for m in patient.active_medications():
        mg = daily_dose_mg(m.dose, m.unit, m.frequency)
        if mg is not None:
            doses[m.drug_id] = mg
    doses.update(extra or {})
    return PairContext(daily_mg=tuple(sorted(doses.items())), egfr=ckd_epi_2021(patient))


# ANSM states aspirin's levels by dose band, in these words (thesaurus 2020, acide acetylsalicylique).
_ASPIRIN_BANDS = (
    (375.0, re.compile(r"antiagregant")),
    (3000.0, re.compile(r"antalgique|antipyretique")),
    (math.inf, re.compile(r"anti-?inflammatoire")),
)


def _in_band(value: float, low: float | None, high: float | None) -> bool:
    return (low is None or value >= low) and (high is None or value < high)


def _overlay_level(rule: InteractionRule, ctx: PairContext | None) -> tuple[SeverityLevel, str]:
    """The US overlay level: the dose or eGFR band the patient falls in, else the rule's own level."""
    default = rule.levels[-1]
    for lv in rule.levels[:-1]:
        if lv.dose_band and ctx is not None:
            mg = ctx.dose(lv.dose_band.drug)
            if mg is not None and _in_band(mg, lv.dose_band.min_daily_mg, lv.dose_band.max_daily_mg):
                return lv, f"US overlay at {lv.dose_band.drug} {mg:g} mg/day: {lv.condition.text if lv.condition else ''}"
        if (lv.renal_band and ctx is not None and ctx.egfr is not None
                and _in_band(ctx.egfr, lv.renal_band.egfr_min, lv.renal_band.egfr_max)):
            return lv, f"US overlay at eGFR {ctx.egfr:g}: {lv.condition.text if lv.condition else ''}"
    banded = len(rule.levels) > 1
    return default, ("US overlay: dose or eGFR not known, the rule's level applies" if banded else "US overlay")


def _aspirin_level(rule: InteractionRule, ctx: PairContext | None) -> tuple[SeverityLevel, str] | None:
    """ANSM's aspirin levels evaluated at the patient's aspirin dose (antiplatelet <= 375 mg/day,
    analgesic < 3 g/day, anti-inflammatory >= 3 g/day), when one level's condition names that band."""
    if ctx is None or "aspirin" not in (rule.party_a.id, rule.party_b.id):
        return None
    mg = ctx.dose("aspirin")
    if mg is None:
        return None
    for ceiling, words in _ASPIRIN_BANDS:
        if mg <= ceiling:
            hits = [lv for lv in rule.levels if lv.condition and words.search(fold(lv.condition.text))]
            if hits:
                return max(hits, key=lambda lv: SEVERITY_RANK[lv.level]), f"aspirin {mg:g} mg/day: the level ANSM states for that dose band"
            return None
    return None


def applicable_level(db: DrugInteractionDB, rule: InteractionRule, a_id: str, b_id: str,
                     ctx: PairContext | None = None) -> tuple[SeverityLevel, str]:
    """The level of a (possibly multi-level) rule that applies to the pair (a, b), and why.

    ANSM rules with several levels state in French which one applies ("avec la doxazosine",
    "pour tous les medicaments sedatifs entre eux"). The build records which thesaurus substances
    each condition names; here:
      1. a single level applies as is;
      2. levels whose condition names the drug matched through a class party (directly or by one
         of its classes) apply; within one class, a condition listing several members applies only
         when it names both drugs;
      3. otherwise levels whose condition names no other substance (general conditions such as
         doses or renal function) apply, the most severe first;
      4. otherwise (every level names other substances only) the least severe level is reported.
    The full French conditions are always returned with the level, so the agent can check.
    """
    if rule.source == "us_overlay":
        return _overlay_level(rule, ctx)
    levels = rule.levels
    if len(levels) == 1:
        return levels[0], "single level"
    at_dose = _aspirin_level(rule, ctx)
    if at_dose is not None:
        return at_dose
    own = {p.id for p in (rule.party_a, rule.party_b) if p.kind == "substance" and p.id}
    party_classes = {p.id for p in (rule.party_a, rule.party_b) if p.kind != "substance" and p.id}
    party_classes |= {db.classes[c].other_of for c in list(party_classes) if c in db.classes and db.classes[c].other_of}
    via_class = {d for d in (a_id, b_id) if d not in own}
    intra = rule.party_a.kind == rule.party_b.kind == "class" and any(
        db.classes[c].other_of in party_classes for c in party_classes if c in db.classes)

    def named_in(lv: SeverityLevel, drug_id: str) -> bool:
        if drug_id in lv.mentions:
            return True
        drug = db.drugs.get(drug_id)
        return bool(drug and set(lv.mentions_classes) - party_classes & set(drug.class_ids))

    def names_pair(lv: SeverityLevel) -> bool:
        hits = {d for d in via_class if named_in(lv, d)}
        # within one class, a list of several members ("amiodarone, disopyramide, sotalol") means
        # "between these": both drugs must be named; a single name ("avec l'oxybate") needs one
        listed = len(lv.mentions) + len(set(lv.mentions_classes) - party_classes)
        both = intra and listed >= 2
        return bool(via_class) and (hits == via_class if both else bool(hits))

    def general(lv: SeverityLevel) -> bool:
        return (set(lv.mentions) <= own and set(lv.mentions_classes) <= party_classes
                and not lv.mentions_other_substances)

    by_rank = lambda lv: SEVERITY_RANK[lv.level]  # noqa: E731
    named = [lv for lv in levels if names_pair(lv)]
    if named:
        chosen = max(named, key=by_rank)
        return chosen, "condition names " + " and ".join(sorted(d for d in via_class if named_in(chosen, d)))
    generic = [lv for lv in levels if general(lv)]
    if generic:
        return max(generic, key=by_rank), "general condition (doses, route, renal function...): most severe applies"
    return min(levels, key=by_rank), "conditions name other substances or classes only: least severe level reported"


def assess_pair(db: DrugInteractionDB, a: Drug | DrugClass, b: Drug | DrugClass,
                ctx: PairContext | None = None) -> list[tuple[InteractionRule, SeverityLevel, str]]:
    """(rule, applicable level, basis) for every rule covering the pair: US overlay rules first (they
    set the pair's severity, `effective_severity`), then ANSM rules; most severe first within each."""
    out = [(rule, *applicable_level(db, rule, a.id, b.id, ctx)) for rule in rules_between(db, a, b)]
    return sorted(out, key=lambda t: (t[0].source != "us_overlay", -SEVERITY_RANK[t[1].level], t[0].id))


def effective_severity(assessed: list[tuple[InteractionRule, SeverityLevel, str]]) -> str:
    """The pair's severity on the US-referenced scale: the US overlay's level where a rule of the
    overlay covers the pair (it re-rates the ANSM rules it reviews), else the most severe ANSM level."""
    overlay = [lv.level for r, lv, _ in assessed if r.source == "us_overlay"]
    return max_severity(overlay) if overlay else max_severity(lv.level for _, lv, _ in assessed)


def pair_severity(db: DrugInteractionDB, a: Drug | DrugClass, b: Drug | DrugClass, ctx: PairContext | None = None) -> str:
    return effective_severity(assess_pair(db, a, b, ctx))


def max_severity(levels) -> str:
    return max(levels, key=lambda s: SEVERITY_RANK[s], default="none")


def rule_brief(rule: InteractionRule, level: SeverityLevel | None = None, basis: str | None = None) -> dict:
    out = {
        "rule_id": rule.id,
        "source": "US overlay (FDA labelling / US guideline)" if rule.source == "us_overlay" else "ANSM thesaurus 2020",
        "parties": [_party_text(rule.party_a), _party_text(rule.party_b)],
        "severity": level.label if level else rule.severity,
        "severity_level": level.level if level else rule.severity_level,
        "summary": rule.summary.text,
        "mechanism": rule.mechanism.model_dump(),
        "management": [{"level": lv.label, **lv.condition.model_dump()} for lv in rule.levels if lv.condition],
    }
    if rule.source == "us_overlay":
        out["evidence"] = rule.evidence
        out["management"] = [lv.condition.text for lv in rule.levels if lv.condition]
        if rule.reviews:
            out["re_rates"] = rule.reviews
    if len(rule.levels) > 1:
        out["listed_levels"] = [lv.label for lv in rule.levels]
        out["level_basis"] = basis
    elif rule.source == "us_overlay" and basis:
        out["level_basis"] = basis
    return out


def _party_text(p) -> str:
    return f"{p.name} [class]" if p.kind == "class" else p.name


def pair_report(db: DrugInteractionDB, a: Drug | DrugClass, b: Drug | DrugClass, ctx: PairContext | None = None) -> dict:
    assessed = assess_pair(db, a, b, ctx)
    out = {
        "drug_a": a.id, "drug_b": b.id,
        "interaction_found": bool(assessed),
        "severity_level": effective_severity(assessed),
        "rules": [rule_brief(r, lv, basis) for r, lv, basis in assessed],
    }
    ansm = [lv.level for r, lv, _ in assessed if r.source == "ansm"]
    if any(r.source == "us_overlay" for r, _, _ in assessed):
        out["severity_basis"] = "US overlay (FDA labelling / US guideline); the ANSM level is listed as a second source"
        out["ansm_severity_level"] = max_severity(ansm)
    return out


@dataclass(frozen=True)
class PairFinding:
    drug_a: str
    drug_b: str
    severity_level: str
    rule_ids: tuple[str, ...]
    involves_proposed: bool
    multi_level: bool


def _finding(db: DrugInteractionDB, a: Drug, b: Drug, proposed: bool, ctx: PairContext | None = None) -> PairFinding | None:
    assessed = assess_pair(db, a, b, ctx)
    if not assessed:
        return None
    return PairFinding(a.id, b.id, effective_severity(assessed), tuple(r.id for r, _, _ in assessed),
                       proposed, any(len(r.levels) > 1 for r, _, _ in assessed))


def medication_list_findings(db: DrugInteractionDB, patient: Patient, proposed: Drug | None,
                             proposed_daily_mg: float | None = None) -> list[PairFinding]:
    """Interacting pairs among the active medications, plus the proposed drug against each, with
    dose- and renal-conditional levels evaluated at the patient's doses and eGFR."""
    meds = list(dict.fromkeys(m.drug_id for m in patient.active_medications()))
    drugs = [db.drugs[d] for d in meds]
    extra = {proposed.id: proposed_daily_mg} if proposed is not None and proposed_daily_mg is not None else None
    ctx = patient_context(db, patient, extra)
    findings = []
    for i, a in enumerate(drugs):
        for b in drugs[i + 1:]:
            found = _finding(db, a, b, False, ctx)
            if found:
                findings.append(found)
    if proposed is not None:
        for a in drugs:
            if a.id != proposed.id:
                found = _finding(db, proposed, a, True, ctx)
                if found:
                    findings.append(found)
    return sorted(findings, key=lambda f: (not f.involves_proposed, -SEVERITY_RANK[f.severity_level], f.drug_a, f.drug_b))


# -- allergies -----------------------------------------------------------------------------------
def combination_components(db: DrugInteractionDB, drug: Drug) -> list[Drug]:
    """The single agents of a fixed combination ("piperacillin and tazobactam"), when the vocabulary
    has each of them; [] for a single agent. A combination carries no ANSM class of its own, so an
    allergy to a component's class must be checked on the components."""
    parts = [p.strip() for p in re.split(r"\s+and\s+|\s*/\s*|\s*\+\s*", drug.id) if p.strip()]
    if len(parts) < 2:
        return []
    found = [db.drugs[p] for p in parts if p in db.drugs]
    return found if len(found) == len(parts) else []


def allergy_conflicts(db: DrugInteractionDB, patient: Patient, drug: Drug) -> list[dict]:
    """Direct (same drug), class (drug in an allergen ANSM class) and listed cross-reaction conflicts;
    a fixed combination conflicts through any of its components."""
    out = []
    profile = db.dose_profiles.get(drug.id)
    cross = {fold(x) for x in (profile.allergy_cross_reactions if profile else [])}
    agents = [drug] + combination_components(db, drug)
    for allergy in patient.allergies:
        direct = next((a for a in agents if allergy.drug_id == a.id), None)
        member = next((a for a in agents if allergy.class_id and allergy.class_id in a.class_ids), None)
        if direct is not None:
            how = "direct" if direct is drug else f"direct: {direct.name} is a component of {drug.name}"
            out.append({"allergen": allergy.allergen, "match": how, "reaction": allergy.reaction,
                        "severity": allergy.severity})
        elif member is not None:
            via = "" if member is drug else f" (component of {drug.name})"
            out.append({"allergen": allergy.allergen, "match": f"class: {member.name}{via} is a member of "
                        f"'{db.classes[allergy.class_id].name}'", "reaction": allergy.reaction, "severity": allergy.severity})
        elif allergy.drug_id and fold(allergy.drug_id) in cross:
            out.append({"allergen": allergy.allergen, "match": "cross-reaction listed by drugdose",
                        "reaction": allergy.reaction, "severity": allergy.severity})
    return out


# -- alternatives --------------------------------------------------------------------------------
def alternatives(db: DrugInteractionDB, drug: Drug, patient: Patient, within: DrugClass | None = None) -> dict:
    """Peers of `drug` in its therapeutic ANSM classes (or `within`), ranked by their worst interaction
    with the patient's other active medications; allergy conflicts are excluded."""
    if within is not None:
        classes = [within]
    else:
        classes = [db.classes[c] for c in drug.class_ids if db.classes[c].therapeutic]
    others = [db.drugs[m.drug_id] for m in patient.active_medications() if m.drug_id != drug.id]
    ctx = patient_context(db, patient)
    current = max_severity(pair_severity(db, drug, o, ctx) for o in others)
    peers: dict[str, dict] = {}
    excluded = []
    for cls in classes:
        for member_id in cls.members:
            if member_id == drug.id or member_id in peers:
                continue
            member = db.drugs[member_id]
            if allergy_conflicts(db, patient, member):
                excluded.append(member_id)
                continue
            severities = {o.id: pair_severity(db, member, o, ctx) for o in others if o.id != member_id}
            peers[member_id] = {"drug": member_id, "worst_severity": max_severity(severities.values()),
                                "interacting_with": sorted(k for k, v in severities.items() if v != "none")}
    ranked = sorted(peers.values(), key=lambda p: (SEVERITY_RANK[p["worst_severity"]], p["drug"]))
    safer = [p for p in ranked if SEVERITY_RANK[p["worst_severity"]] < SEVERITY_RANK[current]]
    return {"drug": drug.id, "current_worst_severity": current, "classes_searched": [c.name for c in classes],
            "safer_alternatives": safer, "other_candidates": [p for p in ranked if p not in safer],
            "excluded_for_allergy": sorted(set(excluded))}


# -- renal and hepatic ---------------------------------------------------------------------------
def cockcroft_gault(patient: Patient) -> float:
    """Creatinine clearance (mL/min), Cockcroft-Gault with actual body weight, x0.85 if female."""
    crcl = (140 - patient.age) * patient.weight_kg / (72 * patient.serum_creatinine_mg_dl)
    if patient.sex == "female":
        crcl *= 0.85
    return round(crcl, 1)


def ckd_epi_2021(patient: Patient) -> float:
    """eGFR (mL/min/1.73 m2), race-free CKD-EPI 2021 creatinine equation."""
    scr = patient.serum_creatinine_mg_dl
    female = patient.sex == "female"
    kappa, alpha = (0.7, -0.241) if female else (0.9, -0.302)
    egfr = 142 * min(scr / kappa, 1) ** alpha * max(scr / kappa, 1) ** -1.200 * 0.9938 ** patient.age
    if female:
        egfr *= 1.012
    return round(egfr, 1)


@dataclass(frozen=True)
class RenalLabelRule:
    """A drug's lowest renal band as its US label states it, where open-medicine's table calls the band
    "contraindicated". `below`: the band is renal function < below (in the table's metric, which is the
    label's). `level`: "contraindicated" only where the label's section 4 says so; "avoid" where the label
    says not recommended / avoid or gives no renal contraindication (a guideline may advise against it)."""
    metric: str
    below: float
    level: str
    dose: str
    label: str
    statement: str


# Every open-medicine tier marked "contraindicated" is checked here against the drug's US label; the
# reward's severity-5 contraindication pattern reads `level`, not the package's word.
RENAL_LABEL_RULES: dict[str, RenalLabelRule] = {
    "metformin": RenalLabelRule(
        "egfr", 30, "contraindicated", "Contraindicated (eGFR below 30 mL/min/1.73 m2)",
        "Glucophage (metformin) USPI 4 CONTRAINDICATIONS (severe renal impairment: eGFR below 30 mL/min/1.73 m2) and "
        "2 DOSAGE AND ADMINISTRATION (eGFR 30-45: initiation not recommended)",
        "contraindicated below eGFR 30; starting it at eGFR 30-45 is not recommended"),
    "sotalol": RenalLabelRule(
        "crcl", 40, "contraindicated", "Contraindicated for AFIB/AFL (creatinine clearance below 40 mL/min)",
        "Betapace AF / sotalol hydrochloride tablets USPI 4 CONTRAINDICATIONS (for AFIB/AFL: creatinine clearance "
        "< 40 mL/min) and 2 DOSAGE AND ADMINISTRATION (dosing interval by creatinine clearance)",
        "the formulary's regimen (80 mg twice daily, up to 160 mg) is the AFIB/AFL one, whose label contraindicates "
        "creatinine clearance < 40 mL/min; for ventricular arrhythmias the label lengthens the interval instead"),
    "lithium": RenalLabelRule(
        "crcl", 30, "avoid", "Not recommended (severe renal impairment); avoid if possible",
        "Lithium carbonate USPI 4 CONTRAINDICATIONS (hypersensitivity to an inactive ingredient only: no renal "
        "contraindication), "
        "2 DOSAGE AND ADMINISTRATION (CLcr 30-89 mL/min: start lower, titrate slowly) and 8 USE IN SPECIFIC "
        "POPULATIONS (renal impairment: severe, CLcr < 30 mL/min, not recommended)",
        "not recommended below creatinine clearance 30 mL/min; not a label contraindication"),
    "methotrexate": RenalLabelRule(
        "crcl", 15, "avoid", "Avoid (elimination reduced; if used, very low dose with close monitoring)",
        "Methotrexate tablets USPI (2020) 4 CONTRAINDICATIONS (pregnancy in non-neoplastic disease, severe "
        "hypersensitivity: no renal contraindication), boxed warning and 5 WARNINGS AND PRECAUTIONS (renal toxicity "
        "and increased toxicity with renal impairment) and 8 USE IN SPECIFIC POPULATIONS (renal impairment)",
        "elimination is reduced: monitor closely and reduce the dose or stop; the US label does not contraindicate "
        "it by renal function"),
    "spironolactone": RenalLabelRule(
        "egfr", 30, "avoid", "Avoid initiating (eGFR below 30 mL/min/1.73 m2)",
        "Aldactone (spironolactone) USPI 4 CONTRAINDICATIONS (hyperkalemia, Addison's disease, eplerenone: no renal "
        "contraindication) and 2.2 Treatment of Heart Failure (eGFR 30-50: consider 25 mg every other day); "
        "2022 AHA/ACC/HFSA heart failure guideline (MRA only with eGFR > 30 mL/min/1.73 m2 and potassium < 5.0)",
        "no label contraindication by renal function; the heart failure guideline starts an MRA only above eGFR 30 "
        "(hyperkalaemia risk)"),
}


@dataclass(frozen=True)
class RenalLabelDose:
    """A renal band whose regimen the US label gives per indication where open-medicine's table gives one:
    `dose` replaces the table's text for the band [min, max] (the table's metric, which is the label's)."""
    min: float
    max: float | None
    dose: str
    label: str
    statement: str


_ZOSYN_RENAL = ("Zosyn (piperacillin and tazobactam) USPI 2 DOSAGE AND ADMINISTRATION, dosage in adult patients with "
                "renal impairment (table: all indications except nosocomial pneumonia / nosocomial pneumonia)")

# Bands where one regimen in the table stands for two in the label. Piperacillin-tazobactam: the table's
# normal dose is "3.375-4.5 g q6h" but its reduced bands carry only the 3.375 g regimen's reduction; the
# 4.5 g q6h regimen (nosocomial pneumonia, and the antipseudomonal dose ATS/IDSA 2019 gives for pneumonia
# with P. aeruginosa risk) reduces to 3.375 g q6h at CrCl 20-40 and 2.25 g q6h below 20.
RENAL_LABEL_DOSES: dict[str, tuple[RenalLabelDose, ...]] = {
    "piperacillin and tazobactam": (
        RenalLabelDose(20, 40, "2.25 g IV q6h (3.375 g IV q6h for the 4.5 g q6h regimen: nosocomial pneumonia)",
                       _ZOSYN_RENAL, "creatinine clearance 20-40 mL/min: 2.25 g every 6 hours, nosocomial pneumonia "
                       "3.375 g every 6 hours"),
        RenalLabelDose(0, 19, "2.25 g IV q8h (2.25 g IV q6h for the 4.5 g q6h regimen: nosocomial pneumonia)",
                       _ZOSYN_RENAL, "creatinine clearance below 20 mL/min: 2.25 g every 8 hours, nosocomial "
                       "pneumonia 2.25 g every 6 hours"),
    ),
}


def renal_label_tiers(profile: RenalProfile) -> list[dict]:
    """The drug's renal tiers (highest band first) with its label rules applied: a tier inside a
    contraindication rule's band takes the label's level and wording (RENAL_LABEL_RULES), a band whose
    regimen the label gives per indication takes the label's regimens (RENAL_LABEL_DOSES); the package's
    own are kept as `source_*`."""
    rule = RENAL_LABEL_RULES.get(profile.drug_id)
    doses = {(d.min, d.max): d for d in RENAL_LABEL_DOSES.get(profile.drug_id, ())}
    out = []
    for tier in profile.tiers:
        row = tier.model_dump()
        if (rule is not None and rule.metric == profile.metric and tier.max is not None and tier.max < rule.below
                and tier.adjustment_type == "contraindicated"):
            row.update(source_adjustment_type=tier.adjustment_type, source_dose=tier.dose,
                       adjustment_type=rule.level, dose=rule.dose,
                       label_rule={"source": rule.label, "statement": rule.statement})
        elif (tier.min, tier.max) in doses:
            dose = doses[(tier.min, tier.max)]
            row.update(source_adjustment_type=tier.adjustment_type, source_dose=tier.dose, dose=dose.dose,
                       label_rule={"source": dose.label, "statement": dose.statement})
        out.append(row)
    return out


def renal_contraindicated_below(profile: RenalProfile) -> float | None:
    """The renal function (profile's metric) below which the drug's label contraindicates it, else None."""
    limits = [t["max"] + 1 for t in renal_label_tiers(profile)
              if t["adjustment_type"] == "contraindicated" and t["max"] is not None]
    return max(limits) if limits else None


def renal_tier(profile: RenalProfile, value: float) -> dict:
    """The tier whose lower bound is the highest one not above `value` (tiers cover 0 to infinity), with
    the drug's label rule applied (`renal_label_tiers`)."""
    if value < 0 or not math.isfinite(value):
        raise ValueError(f"renal function must be a non-negative number, got {value}")
    tiers = renal_label_tiers(profile)  # sorted by min, descending
    for tier in tiers:
        if value >= tier["min"]:
            return tier
    return tiers[-1]


# The formulary's default convention (not a source fact): what a hepatic caution flag means for each
# Child-Pugh class, for flagged drugs without a drug-specific label rule below.
HEPATIC_POLICY = {
    None: "no_adjustment",
    "A": "use_with_caution",
    "B": "reduce_dose_and_monitor",
    "C": "avoid_or_specialist_review",
}
HEPATIC_DEFAULT_BASIS = "formulary default convention for a hepatic caution flag (no drug-specific label rule encoded)"


@dataclass(frozen=True)
class HepaticLabelRule:
    """A drug's hepatic recommendation per Child-Pugh class as its US label states it, with the label
    section it comes from. "avoid" = the label says avoid / not recommended (not a contraindication).
    None of the flagged drugs' labels contraindicates the drug by hepatic function for every route and
    indication the formulary covers; a route- or indication-limited contraindication (IV acetaminophen,
    oral diazepam, methotrexate outside oncology) is stated in `statement`."""
    by_class: dict[str, str]
    label: str
    statement: str


def _all(recommendation: str) -> dict[str, str]:
    return {"A": recommendation, "B": recommendation, "C": recommendation}


# Drug-specific rules transcribed from US labels (USPI sections named in `label`). Where a label
# states one recommendation for any hepatic impairment, the three classes carry it. Of the drugs
# with a hepatic caution flag, haloperidol and ketamine have none: their labels give no dosing by
# hepatic function (HEPATIC_CONVENTION_ONLY), so the named default convention answers for them.
HEPATIC_LABEL_RULES: dict[str, HepaticLabelRule] = {
    "insulin human": HepaticLabelRule(
        {"A": "reduce_dose_and_monitor", "B": "reduce_dose_and_monitor", "C": "reduce_dose_and_monitor"},
        "Humulin R USPI 5.3 Hypoglycemia (hepatic impairment a risk factor) and 8 USE IN SPECIFIC POPULATIONS (hepatic impairment)",
        "hepatic impairment: monitor glucose more often and adjust (usually reduce) the insulin dose; not a contraindication"),
    "metformin": HepaticLabelRule(
        {"A": "avoid", "B": "avoid", "C": "avoid"},
        "Glucophage/metformin USPI boxed warning and 5.1 Lactic acidosis (hepatic impairment)",
        "avoid use in patients with clinical or laboratory evidence of hepatic disease (risk of lactic acidosis)"),
    "sacubitril/valsartan": HepaticLabelRule(
        {"A": "no_adjustment", "B": "reduce_dose_and_monitor", "C": "avoid"},
        "Entresto USPI 2 DOSAGE AND ADMINISTRATION (hepatic impairment) and 8.6 Hepatic Impairment",
        "mild (Child-Pugh A): no starting-dose adjustment; moderate (B): start at half the usual dose (24/26 mg twice daily); severe (C): not recommended"),
    "ondansetron": HepaticLabelRule(
        {"A": "no_adjustment", "B": "no_adjustment", "C": "reduce_dose_and_monitor"},
        "Zofran USPI 2 DOSAGE AND ADMINISTRATION and 8.6 Hepatic Impairment",
        "mild or moderate: no adjustment; severe (Child-Pugh score >= 10): do not exceed 8 mg total daily dose"),
    "acetaminophen": HepaticLabelRule(
        {"A": "use_with_caution", "B": "use_with_caution", "C": "reduce_dose_and_monitor"},
        "Ofirmev (acetaminophen injection) USPI 4 CONTRAINDICATIONS (severe hepatic impairment or severe active liver "
        "disease) and 5.1 Hepatic Injury; oral products: OTC Drug Facts liver warning",
        "use with caution in hepatic impairment or active liver disease; severe impairment: the IV product is "
        "contraindicated (Ofirmev 4), by mouth use a reduced total daily dose with monitoring (liver warning: ask a "
        "doctor with liver disease)"),
    "amiodarone": HepaticLabelRule(
        _all("use_with_caution"),
        "Nexterone (amiodarone injection) and Cordarone USPI 5 WARNINGS AND PRECAUTIONS (hepatic injury) and boxed "
        "warning (tablets: hepatotoxicity)",
        "no Child-Pugh dosing in the label: obtain baseline and periodic liver enzymes; reduce the dose or stop if they "
        "exceed three times normal or liver injury is suspected"),
    "colchicine": HepaticLabelRule(
        {"A": "use_with_caution", "B": "use_with_caution", "C": "reduce_dose_and_monitor"},
        "Colcrys (colchicine) USPI 2 DOSAGE AND ADMINISTRATION (dose modification) and 8.7 Hepatic Impairment; 4 "
        "CONTRAINDICATIONS (with P-gp or strong CYP3A4 inhibitors in hepatic impairment)",
        "mild to moderate impairment: no dose adjustment, monitor closely for adverse effects; severe: reduce the "
        "prophylaxis dose, do not repeat a flare course within 2 weeks"),
    "diazepam": HepaticLabelRule(
        {"A": "use_with_caution", "B": "use_with_caution", "C": "avoid"},
        "Diazepam Injection USP label PRECAUTIONS (compromised liver function: usual precautions; clearance reduced in "
        "cirrhosis, CLINICAL PHARMACOLOGY); Valium (oral) label CONTRAINDICATIONS (severe hepatic insufficiency)",
        "use with caution (half-life prolonged in cirrhosis); severe hepatic insufficiency: avoid - the oral label "
        "contraindicates it, the injection label does not"),
    "diltiazem": HepaticLabelRule(
        _all("use_with_caution"),
        "Cardizem (diltiazem) injection label PRECAUTIONS (impaired hepatic function)",
        "extensively metabolised by the liver: use with caution and monitor in impaired hepatic function; no "
        "Child-Pugh dosing"),
    "fentanyl": HepaticLabelRule(
        _all("use_with_caution"),
        "Fentanyl Citrate Injection USPI 8 USE IN SPECIFIC POPULATIONS (hepatic impairment) and 5 WARNINGS AND "
        "PRECAUTIONS (respiratory depression)",
        "administer with caution in hepatic impairment, titrate the dose and monitor for respiratory depression and "
        "sedation"),
    "fluconazole": HepaticLabelRule(
        _all("use_with_caution"),
        "Diflucan (fluconazole) label WARNINGS (hepatic injury)",
        "administer with caution to patients with liver dysfunction; monitor liver tests and stop at signs of liver "
        "injury; no Child-Pugh dosing"),
    "furosemide": HepaticLabelRule(
        _all("use_with_caution"),
        "Furosemide Injection USP label WARNINGS (hepatic cirrhosis and ascites; hepatic coma)",
        "in cirrhosis with ascites start therapy in hospital (sudden fluid and electrolyte shifts can precipitate "
        "hepatic coma); do not start in hepatic coma until it improves"),
    "labetalol": HepaticLabelRule(
        _all("use_with_caution"),
        "Labetalol HCl Injection label PRECAUTIONS (impaired hepatic function) and WARNINGS (hepatic injury)",
        "use with caution in impaired hepatic function since its metabolism may be diminished"),
    "lidocaine": HepaticLabelRule(
        {"A": "use_with_caution", "B": "use_with_caution", "C": "reduce_dose_and_monitor"},
        "Lidocaine HCl (Xylocaine) injection labels PRECAUTIONS (hepatic disease)",
        "amide metabolised by the liver: use with caution in hepatic disease; severe hepatic disease raises the risk "
        "of toxic plasma concentrations (lower doses, monitor)"),
    "lorazepam": HepaticLabelRule(
        {"A": "use_with_caution", "B": "use_with_caution", "C": "reduce_dose_and_monitor"},
        "Ativan (lorazepam) labels PRECAUTIONS (impaired hepatic function; hepatic encephalopathy)",
        "usual precautions in hepatic impairment; may worsen hepatic encephalopathy; severe hepatic insufficiency: "
        "adjust the dose carefully to response, lower doses may suffice"),
    "methotrexate": HepaticLabelRule(
        _all("avoid"),
        "methotrexate labels: older tablet label CONTRAINDICATIONS (psoriasis or rheumatoid arthritis with alcoholic "
        "or other chronic liver disease); current USPI 5 WARNINGS AND PRECAUTIONS (hepatotoxicity)",
        "avoid in chronic liver disease for non-neoplastic indications; the section-4 contraindication is limited to "
        "those indications, which an order does not state"),
    "metoprolol": HepaticLabelRule(
        _all("reduce_dose_and_monitor"),
        "Lopressor (metoprolol) USPI 8.6 Hepatic Impairment",
        "metabolised by the liver, levels rise with poor hepatic function: initiate at lower doses and increase "
        "gradually"),
    "midazolam": HepaticLabelRule(
        _all("use_with_caution"),
        "Midazolam Injection label WARNINGS/PRECAUTIONS and CLINICAL PHARMACOLOGY (hepatic impairment: clearance "
        "reduced, half-life prolonged in cirrhosis)",
        "use with caution and titrate slowly; effects may be prolonged in hepatic impairment"),
    "morphine": HepaticLabelRule(
        _all("reduce_dose_and_monitor"),
        "Morphine Sulfate Injection USPI 2 DOSAGE AND ADMINISTRATION and 8.6 Hepatic Impairment",
        "pharmacokinetics altered in cirrhosis: start with a lower than usual dose and titrate slowly, monitoring for "
        "respiratory depression, sedation and hypotension"),
    "rocuronium": HepaticLabelRule(
        _all("use_with_caution"),
        "Zemuron (rocuronium) USPI 8 USE IN SPECIFIC POPULATIONS (hepatic impairment) and 12.3 Pharmacokinetics",
        "clinical duration prolonged in hepatic impairment (larger volume of distribution, longer half-life): use "
        "with caution and monitor neuromuscular blockade"),
}

# Flagged drugs whose US labels state no hepatic dosing (checked: Haldol injection label; Ketalar USPI,
# whose 5 WARNINGS AND PRECAUTIONS covers hepatobiliary dysfunction with recurrent use only).
HEPATIC_CONVENTION_ONLY = {
    "haloperidol": "Haldol (haloperidol) injection label: no dosing by hepatic function",
    "ketamine": "Ketalar (ketamine) USPI: no dosing by hepatic function (5 WARNINGS AND PRECAUTIONS: hepatobiliary "
                "dysfunction with recurrent use)",
}

HEPATIC_RECOMMENDATIONS = ("no_adjustment", "no_flagged_concern", "use_with_caution", "reduce_dose_and_monitor",
                           "avoid", "avoid_or_specialist_review", "no_data")


def hepatic_assessment(db: DrugInteractionDB, drug: Drug, child_pugh: str | None) -> dict:
    """The hepatic recommendation for a drug at a Child-Pugh class: the drug's label rule where one is
    encoded (`HEPATIC_LABEL_RULES`, with its section in `basis`), else the default convention for the
    source packages' hepatic caution flags."""
    flags = {}
    if drug.id in db.dose_profiles:
        flags["drugdose.hepatic_caution"] = db.dose_profiles[drug.id].hepatic_caution
    if drug.id in db.renal_profiles:
        flags["open-medicine.hepatic_interaction_flag"] = db.renal_profiles[drug.id].hepatic_flag
    rule = HEPATIC_LABEL_RULES.get(drug.id)
    label = None
    if rule is not None:
        recommendation = rule.by_class[child_pugh] if child_pugh else "no_adjustment"
        basis = f"US label: {rule.label}"
        label = {"source": rule.label, "statement": rule.statement}
    elif not flags:
        recommendation, basis = "no_data", "no hepatic data for this drug in the formulary sources"
    elif not any(flags.values()):
        recommendation, basis = "no_flagged_concern", "no hepatic caution flag in the formulary sources"
    else:
        recommendation, basis = HEPATIC_POLICY[child_pugh], HEPATIC_DEFAULT_BASIS
    out = {"drug": drug.id, "child_pugh_class": child_pugh, "hepatic_flags": flags,
           "hepatic_caution": any(flags.values()) if flags else None, "recommendation": recommendation,
           "basis": basis}
    if label:
        out["label_rule"] = label
    elif drug.id in HEPATIC_CONVENTION_ONLY:
        out["label_checked"] = HEPATIC_CONVENTION_ONLY[drug.id]
    return out



PREGNANCY_CATEGORIES = {
    "A": ("Adequate well-controlled studies in pregnant women have not shown a risk to the fetus.", "acceptable"),
    "B": ("Animal studies show no risk, without adequate studies in pregnant women (or animal risk not confirmed in humans).", "acceptable"),
    "C": ("Risk cannot be ruled out: animal studies show adverse effects or are lacking, and human data are inadequate.", "use_only_if_benefit_justifies_risk"),
    "D": ("Positive evidence of human fetal risk; benefits may warrant use despite the risk.", "avoid_unless_no_safer_alternative"),
    "X": ("Fetal abnormalities or risk clearly outweigh any possible benefit.", "contraindicated"),
}

# The pregnancy label table is shared with the medical_qa tools and the knowledge base's drug
# monographs (one source of truth): envs/domains/pregnancy_labels.py.
PREGNANCY_RECOMMENDATIONS = ("acceptable", "use_only_if_benefit_justifies_risk", "avoid_unless_no_safer_alternative",
                             "contraindicated", "limit_continuous_use_to_5_7_days", "not_expected_to_cause_harm",
                             "risk_not_established", "contraindicated_for_migraine_prophylaxis", "no_data")


# ANSM class ids -> the class names of the US-label pregnancy table (envs/rewards/safety_lexicon.py).
_LABEL_CLASSES = {"ace-inhibitors": "ace inhibitors", "angiotensin-ii-receptor-blockers": "arbs"}


def label_pregnancy_contraindication(db: DrugInteractionDB, drug: Drug) -> str | None:
    """The US-label citation when the label contraindicates the drug (or its class) in every pregnancy:
    the domain's `PREGNANCY_LABEL_RULES` first (a contraindication limited to one indication is not
    one), else `safety_lexicon.PREGNANCY_CONTRAINDICATED`, boxed warnings and section 4 we transcribed."""
    from envs.rewards import safety_lexicon as lex  # the reward's table: one source for tools and reward

    rule = PREGNANCY_LABEL_RULES.get(drug.id)
    if rule is not None:
        return rule.section if rule.recommendation == "contraindicated" else None
    names = [drug.id, drug.id.replace(" ", "-"), lex.BRANDS.get(drug.id, ""), lex.BRANDS.get(drug.id.replace(" ", "-"), "")]
    names += [_LABEL_CLASSES.get(c, "") for c in drug.class_ids]
    return next((lex.PREGNANCY_CONTRAINDICATED[n] for n in names if n in lex.PREGNANCY_CONTRAINDICATED), None)


def pregnancy_assessment(db: DrugInteractionDB, drug: Drug) -> dict:
    """The drug's pregnancy conclusion: its label rule where `PREGNANCY_LABEL_RULES` has one (section
    in `label_section`, a letter only with its date); else drugdose's letter, named as package data;
    else the US label's pregnancy contraindication when there is one; else no data."""
    rule = PREGNANCY_LABEL_RULES.get(drug.id)
    if rule is not None:
        return {"drug": drug.id, **rule_report(rule)}
    profile = db.dose_profiles.get(drug.id)
    category = profile.pregnancy_category if profile else None
    if category not in PREGNANCY_CATEGORIES:
        label = label_pregnancy_contraindication(db, drug)
        if label:
            return {"drug": drug.id, "fda_category": None, "recommendation": "contraindicated", "us_label": label,
                    "label_section": label,
                    "note": "no FDA letter category in drugdose; the US label contraindicates it in pregnancy"}
        return {"drug": drug.id, "fda_category": None, "recommendation": "no_data",
                "note": "no FDA pregnancy category in the formulary sources (drugdose covers 49 emergency drugs) "
                        "and no pregnancy contraindication in the US-label table"}
    meaning, recommendation = PREGNANCY_CATEGORIES[category]
    return {"drug": drug.id, "fda_category": category, "fda_category_date": None, "meaning": meaning,
            "recommendation": recommendation, "label_section": None, "basis": PACKAGE_LETTER_BASIS,
            "source": profile.provenance[0].model_dump()}


# -- dosing --------------------------------------------------------------------------------------
_MASS_TO_MG = {"g": 1000.0, "mg": 1.0, "mcg": 0.001}
_UNIT_ALIASES = {"µg": "mcg", "ug": "mcg", "microgram": "mcg", "micrograms": "mcg", "milligram": "mg", "milligrams": "mg",
                 "gram": "g", "grams": "g", "unit": "units", "iu": "units", "meq": "mEq", "hour": "hr", "h": "hr"}


def _norm_unit(unit: str) -> str:
    parts = [p.strip() for p in unit.strip().split("/")]
    out = []
    for p in parts:
        low = p.lower()
        out.append(_UNIT_ALIASES.get(low, "mEq" if low == "meq" else low))
    return "/".join(out)


def find_route(profile: DoseProfile, route: str) -> RouteDose:
    for r in profile.routes:
        if r.route.lower() == route.strip().lower():
            return r
    raise LookupFailure(f"no {route!r} dose range for {profile.drug_id}; routes: {', '.join(r.route for r in profile.routes)}")


def convert(amount: float, unit_from: str, unit_to: str) -> float:
    """Convert between mass units (g, mg, mcg) with identical denominators; other units must match."""
    f, t = _norm_unit(unit_from), _norm_unit(unit_to)
    if f == t:
        return amount
    fn, *fd = f.split("/")
    tn, *td = t.split("/")
    if fd != td or fn not in _MASS_TO_MG or tn not in _MASS_TO_MG:
        raise ValueError(f"cannot convert {unit_from!r} to {unit_to!r}")
    return amount * _MASS_TO_MG[fn] / _MASS_TO_MG[tn]


def dose_range(route: RouteDose, weight_kg: float | None, age_years: float | None = None) -> dict:
    """Absolute range (per-kg doses times weight) and the single-dose cap in the dose's numerator unit."""
    unit = route.dose_unit
    if route.per_kg:
        if weight_kg is None:
            raise ValueError(f"{route.route} dose is weight-based ({unit}); give weight_kg or patient_id")
        if weight_kg <= 0:
            raise ValueError(f"weight_kg must be positive, got {weight_kg}")
        parts = unit.split("/")
        abs_unit = "/".join(p for i, p in enumerate(parts) if not (i > 0 and p == "kg"))
        lo, hi = route.dose_min * weight_kg, route.dose_max * weight_kg
    else:
        abs_unit, lo, hi = unit, route.dose_min, route.dose_max
    numerator = abs_unit.split("/")[0]
    cap = route.max_single_dose
    pediatric = age_years is not None and age_years < 18 and route.pediatric_max_dose is not None
    if pediatric:
        cap = route.pediatric_max_dose
    cap_abs = None
    if cap is not None and "/" not in abs_unit and not route.continuous_infusion:
        cap_abs = convert(cap, route.cap_unit or numerator, numerator)
    if hi > 0:
        max_single = min(hi, cap_abs) if cap_abs is not None else hi
    else:  # the source gives only a cap (e.g. intranasal naloxone)
        max_single = cap_abs
    return {
        "route": route.route, "unit": abs_unit, "min": _r(lo), "max": _r(hi),
        "max_single_dose_cap": _r(cap_abs) if cap_abs is not None else None,
        "cap_applied": "pediatric" if pediatric and cap_abs is not None else ("adult" if cap_abs is not None else None),
        "recommended_max_single_dose": _r(max_single) if max_single is not None else None,
        "per_kg": route.per_kg, "dose_per_kg": f"{route.dose_min}-{route.dose_max} {unit}" if route.per_kg else None,
        "frequency": route.frequency, "continuous_infusion": route.continuous_infusion, "notes": route.notes,
    }


def _r(x: float) -> float:
    return round(x, 4)


def _close(a: float, b: float) -> bool:
    """Equal within float noise from unit conversion (0.09 g -> 90.00000000000001 mg)."""
    return abs(a - b) <= 1e-9 * max(1.0, abs(b))


def dose_check(route: RouteDose, dose: float, unit: str, weight_kg: float | None, age_years: float | None = None) -> dict:
    """Classify one dose against the route's range (drugdose `dose_min`-`dose_max`, times weight when per kg)
    and its single-dose cap (drugdose `max_single_dose_mg`, or `pediatric_max_dose_mg` under 18).

    Statuses: exceeds_max_single_dose (over the cap), above_range, below_range, within_range.
    Where the weight-based minimum is above the cap, the cap is the dose the guideline or label gives: alteplase
    0.9 mg/kg, maximum 90 mg (AHA/ASA 2019 acute ischaemic stroke) is 90 mg at 112 kg, not 100.8 mg;
    likewise piperacillin-tazobactam 4.5 g (Zosyn label), tranexamic acid 1 g (CRASH-2), glucose 25 g. A dose equal to
    the cap there is within_range with `at_cap` true and a `cap_note` saying so; a dose under the cap
    stays below_range (it is below both the weight-based dose and the capped one)."""
    if dose <= 0 or not math.isfinite(dose):
        raise ValueError(f"dose must be a positive number, got {dose}")
    rng = dose_range(route, weight_kg, age_years)
    given = convert(dose, unit, rng["unit"])
    cap = rng["max_single_dose_cap"]
    cap_below_range = cap is not None and rng["min"] > cap and not _close(rng["min"], cap)
    at_cap = False
    if cap is not None and given > cap and not _close(given, cap):
        status = "exceeds_max_single_dose"
    elif rng["max"] > 0 and given > rng["max"] + 1e-9:
        status = "above_range"
    elif cap_below_range and _close(given, cap):
        status, at_cap = "within_range", True
    elif given < rng["min"] - 1e-9:
        status = "below_range"
    else:
        status = "within_range"
    cap_note = None
    if at_cap:
        which = "paediatric " if rng["cap_applied"] == "pediatric" else ""
        span = f"{rng['min']:g}" if _close(rng["min"], rng["max"]) else f"{rng['min']:g}-{rng['max']:g}"
        per_kg = f"{route.dose_min:g}" if route.dose_min == route.dose_max else f"{route.dose_min:g}-{route.dose_max:g}"
        basis = f"{per_kg} {route.dose_unit} x {weight_kg:g} kg = {span}" if route.per_kg else span
        cap_note = (f"{basis} {rng['unit']} is above the {which}single-dose cap of {cap:g} {rng['unit']}; "
                    f"the dose is capped at {cap:g} {rng['unit']}")
    reference = cap if cap is not None else (rng["max"] if rng["max"] > 0 else None)
    return {**rng, "dose_given": _r(given), "status": status, "at_cap": at_cap, "cap_note": cap_note,
            "ratio_to_max": _r(given / reference) if reference else None}
