"""The drug reference the clinical_diagnosis, triage_emergency and ehr_management domains share, and
the `RecordSafetyContext` base their safety contexts answer drug facts from. A shared domain
library: it sits beside the domain folders, belongs to none of them, and imports no domain.

Drug facts come from two places, in this order:
1. the authored formulary (`envs/domains/clinical_diagnosis/authored/formulary.json`: class,
   allergy groups, routes, maximum single dose; 53 drugs), and
2. the drug-interaction domain's built database (`domain_build_dir("drug_interaction")/db.json`:
   1,053 drugs with ANSM classes, 1,584 ANSM interaction rules, dose profiles, renal tiers,
   pregnancy data), read through that domain's public entry point
   (`drug_reference_source()` of its environment module, found through `envs.registry`) so its
   logic is not duplicated here and no domain imports another. It is loaded once per process, on
   the first fact that needs it; when it has not been built the reference says so
   (`DrugReference.status`) and answers from the formulary alone.
Where both are silent, the reward's built-in lexicon answers (`use_builtin_fallback = True`).

Patient facts (allergies, current medications, conditions) are read by each domain's subclass of
`RecordSafetyContext` from the toolkit's *current* database, so they reflect the end of the
episode. A recorded allergy to a drug also names the drug's most specific allergy group
(amoxicillin -> penicillin), the way the prescribing tools block it. Renal conditions
("egfr < 30", "crcl < 30") are computed from the latest creatinine with the project calculators
(CKD-EPI 2021, Cockcroft-Gault) at the thresholds the drug-interaction renal tables use, so they
match its contraindications.
"""

from __future__ import annotations

import json
import re
import threading
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable

from envs.rewards.safety import BaseSafetyContext
from envs.rewards.safety_lexicon import ALLERGY_ALIASES

# Authored with the clinical_diagnosis domain, whose build hashes it; read here as shared reference data.
FORMULARY_FILE = Path(__file__).parent / "clinical_diagnosis" / "authored" / "formulary.json"
# The domain whose built database backs the reference (through its `drug_reference_source()`).
DRUG_INTERACTION_DOMAIN = "drug_interaction"

# Words that qualify a drug name in an order without changing the drug ("heparin sc", "furosemide iv",
# "insulin regular infusion", "1 ML Morphine Sulfate 5 MG/ML Injection"), removed in two stages:
# routes, forms and units first, then salts ("metoprolol succinate", but "potassium chloride" is found
# before its salt word is removed).
_FORMS = frozenset(
    "iv im sc sq po pr sl intravenous intramuscular subcutaneous oral sublingual topical inhaled nebulised nebulized "
    "infusion drip bolus push injection injectable solution suspension tablet tablets capsule capsules cream spray "
    "inhaler patch pump extended release er xl sr hr day pack mg ml mcg g unit units actuat prefilled syringe "
    "auto-injector chewable mucosal metered dose dry powder transdermal system implant vaginal ring ophthalmic "
    "drops lozenge".split()
)
_SALTS = frozenset("sodium potassium hydrochloride hcl sulfate sulphate succinate tartrate maleate citrate besylate "
                   "calcium monohydrate bitartrate bromide acetate phosphate".split())
_NUMBER = re.compile(r"[\d.,%]+|[\d.,%]*(?:mg|ml|mcg|ug|g|units?|actuat|hr?|meq|mmol)(?:/(?:ml|actuat|hr?|kg|min|dose|l))*")
_SPLIT_COMBO = re.compile(r"\s*(?:/|\+|\band\b|-|,)\s*")


def fold(text: str) -> str:
    """Lower case, punctuation other than '-', '.', '%' and '/' to spaces, single spaces."""
    return " ".join(re.sub(r"[^a-z0-9%./\-]+", " ", str(text).lower().replace("_", " ")).split())


def _singular(word: str) -> str:
    return word[:-1] if word.endswith("s") and not word.endswith("ss") else word


@dataclass(frozen=True)
class FormularyEntry:
    name: str
    drug_class: str
    allergy_groups: tuple[str, ...]
    routes: tuple[str, ...]
    max_single_dose_mg: float | None
    aliases: tuple[str, ...]


def load_formulary(path: Path = FORMULARY_FILE) -> list[FormularyEntry]:
    raw = json.loads(path.read_text(encoding="utf-8"))["drugs"]
    return [FormularyEntry(d["name"], d["drug_class"], tuple(d.get("allergy_groups", [])), tuple(d.get("routes", [])),
                           d.get("max_single_dose_mg"), tuple(d.get("aliases", []))) for d in raw]


def _drug_interaction_module():
    from envs import registry

    return registry.domain_module(DRUG_INTERACTION_DOMAIN)


def _load_drug_interaction() -> tuple[Any, Any]:
    """The drug-interaction database (one fork, used read-only) and that domain's safety context."""
    return _drug_interaction_module().drug_reference_source()


@dataclass
class DrugReference:
    """Drug names, classes, interactions, dose caps and contraindications for the three domains."""

    formulary: list[FormularyEntry]
    loader: Callable[[], tuple[Any, Any]] = _load_drug_interaction
    status: str = "drug_interaction database not loaded yet"
    _local: dict[str, FormularyEntry] = field(default_factory=dict, repr=False)
    _di: tuple[Any, Any] | None = field(default=None, repr=False)
    _di_tried: bool = False
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    _names: dict[str, str | None] = field(default_factory=dict, repr=False)
    _combos: dict[frozenset, FormularyEntry] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        for entry in self.formulary:
            for name in (entry.name, *entry.aliases):
                self._local.setdefault(fold(name), entry)
                parts = [p for p in _SPLIT_COMBO.split(fold(name)) if p]
                if len(parts) > 1:
                    self._combos.setdefault(frozenset(parts), entry)

    # -- the drug-interaction database -------------------------------------------------------------
    def _interaction_db(self) -> tuple[Any, Any] | None:
        if not self._di_tried:
            with self._lock:
                if not self._di_tried:
                    from envs.core.db import DataFileError

                    try:
                        self._di = self.loader()
                        self.status = "drug_interaction database loaded"
                    except DataFileError as exc:  # not built: the formulary and the lexicon still answer
                        self._di = None
                        self.status = f"drug_interaction database unavailable: {exc}"
                    self._di_tried = True
        return self._di

    def _di_id(self, name: str) -> str | None:
        di = self._interaction_db()
        if di is None:
            return None
        index = di[0].name_index
        key = _drug_interaction_module().drug_name_key(name)
        return index.get(key) or (index.get(key[:-1]) if key.endswith("s") else None)

    # -- names -------------------------------------------------------------------------------------
    def resolve(self, name: str) -> str | None:
        """The canonical name: the formulary's name, else the drug-interaction drug id, else a
        combination "a-b" of resolvable parts; None for a name no source knows."""
        key = fold(name)
        if not key:
            return None
        if key not in self._names:
            self._names[key] = self._resolve(key)
        return self._names[key]

    def _single(self, key: str) -> str | None:
        if len(key) < 3:
            return None
        entry = self._local.get(key)
        if entry is not None:
            return entry.name
        parts = [p for p in _SPLIT_COMBO.split(key) if p]
        if len(parts) == 1:
            parts = key.split()
        if len(parts) > 1:  # a formulary combination written in another order or separator
            entry = self._combos.get(frozenset(parts))
            if entry is not None:
                return entry.name
        return self._di_id(key)

    def _resolve(self, key: str) -> str | None:
        words = re.sub(r"\s[/+]\s", " - ", key).split()
        no_number = [w for w in words if not _NUMBER.fullmatch(w)]
        no_form = [w for w in no_number if w not in _FORMS]
        no_salt = [w for w in no_form if w not in _SALTS]
        stages = list(dict.fromkeys(" ".join(ws) for ws in (words, no_number, no_form, no_salt)))
        for stage in stages:
            found = self._single(stage)
            if found:
                return found
        for stage in stages[-2:]:
            parts = [p for p in _SPLIT_COMBO.split(stage) if p]
            if len(parts) > 1:
                resolved = [self._single(p) or self._single(" ".join(w for w in p.split() if w not in _SALTS))
                            for p in parts]
                if all(resolved):
                    return "-".join(dict.fromkeys(resolved))  # type: ignore[arg-type]
        return None

    def entry(self, drug: str) -> FormularyEntry | None:
        return self._local.get(fold(drug))

    def components(self, drug: str) -> list[str]:
        """Drug-interaction ids of a drug (one, or one per part of a combination)."""
        entry = self.entry(drug)
        for name in [drug] + ([entry.name, *entry.aliases] if entry else []):
            found = self._di_id(name)
            if found:
                return [found]
        parts = [p for p in _SPLIT_COMBO.split(fold(entry.name if entry else drug)) if p]
        ids = [self._di_id(p) for p in parts] if len(parts) > 1 else []
        return [i for i in dict.fromkeys(ids) if i]

    # -- facts -------------------------------------------------------------------------------------
    def classes(self, drug: str) -> list[str]:
        """Most specific first: the formulary class, the ANSM classes (and the reward's class names),
        then the formulary's allergy groups."""
        out: list[str] = []
        entry = self.entry(drug)
        if entry is not None:
            out.append(entry.drug_class.lower())
        di = self._interaction_db()
        if di is not None:
            for component in self.components(drug):
                out.extend(di[1].drug_classes(component))
        if entry is not None:
            out.extend(g.lower() for g in entry.allergy_groups)
        return list(dict.fromkeys(out))

    def allergy_groups(self, substance: str) -> list[str]:
        """What a recorded allergy covers: the substance, and for a drug its most specific allergy
        group (the formulary's first group, else its first ANSM class)."""
        key = fold(substance)
        out = [key]
        drug = self.resolve(key)
        if drug is not None:
            entry = self.entry(drug)
            if entry is not None and entry.allergy_groups:
                out.append(entry.allergy_groups[0].lower())
            elif entry is None:
                classes = self.classes(drug)
                if classes:
                    out.append(classes[0])
        return list(dict.fromkeys(out))

    def allergy_conflict(self, allergies: list[str], drug: str) -> str | None:
        """The first recorded allergy that covers the drug (same drug, or its class/group), else None."""
        canonical = self.resolve(drug) or fold(drug)
        names = {_singular(fold(canonical))} | {_singular(c) for c in self.classes(canonical)}
        names |= {_singular(c) for c in self.components(canonical)}
        for allergy in allergies:
            covered_by = self.allergy_groups(allergy)
            alias = ALLERGY_ALIASES.get(fold(allergy))
            for covered in covered_by + ([alias] if alias else []):
                if _singular(covered) in names or (self.resolve(covered) or "") == canonical:
                    return allergy
        return None

    def interaction(self, drug_a: str, drug_b: str) -> tuple[str, str] | None:
        di = self._interaction_db()
        if di is None:
            return None
        order = ("contraindicated", "major", "moderate", "minor")
        best = None
        for a in self.components(drug_a):
            for b in self.components(drug_b):
                if a == b:
                    continue
                hit = di[1].interaction(a, b)
                if hit and (best is None or order.index(hit[0]) < order.index(best[0])):
                    best = hit
        return best

    def interaction_report(self, drug: str, current: list[str]) -> dict:
        """A proposed drug checked against current medications: ANSM interactions (most severe first)
        and same-class pairs of the classes where two concurrent drugs are a therapeutic duplication."""
        from envs.rewards.conventions import DEFAULT_CONVENTIONS

        order = ("contraindicated", "major", "moderate", "minor")
        name = self.resolve(drug) or fold(drug)
        mine = set(self.classes(name)) & DEFAULT_CONVENTIONS.duplication_classes
        found, same_class, unknown = [], [], []
        for med in dict.fromkeys(current):
            other = self.resolve(med)
            if other is None:
                unknown.append(med)
                continue
            if other == name:
                same_class.append({"with": med, "class": "same drug"})
                continue
            hit = self.interaction(name, other)
            if hit:
                found.append({"with": med, "severity": hit[0], "description": hit[1]})
            shared = mine & set(self.classes(other))
            if shared:
                same_class.append({"with": med, "class": sorted(shared)[0]})
        found.sort(key=lambda f: order.index(f["severity"]))
        return {"drug": name, "checked_against": list(dict.fromkeys(current)), "interactions": found,
                "highest_severity": found[0]["severity"] if found else None, "same_class": same_class,
                "not_in_reference": unknown,
                "source": "ANSM thesaurus rules of the drug_interaction database" if self._interaction_db() else
                          f"formulary only ({self.status})"}

    def max_dose_mg(self, drug: str, route: str | None = None) -> float | None:
        entry = self.entry(drug)
        if entry is not None and entry.max_single_dose_mg:
            if route is None or not entry.routes or _route(route) in {_route(r) for r in entry.routes}:
                return float(entry.max_single_dose_mg)
        di = self._interaction_db()
        if di is None:
            return None
        components = self.components(drug)
        if len(components) != 1:  # a combination's cap is not a component's cap
            return None
        value = di[1].max_dose_mg(components[0], _route(route) if route else None)
        return float(value) if value else None

    def contraindicated_conditions(self, drug: str) -> list[str]:
        di = self._interaction_db()
        if di is None:
            return []
        out: list[str] = []
        for component in self.components(drug):
            out.extend(di[1].contraindicated_conditions(component))
        return list(dict.fromkeys(out))

    def renal_thresholds(self) -> dict[str, list[float]]:
        """metric ('crcl'/'egfr') -> the 'below X' limits of the renal bands the drugs' US labels contraindicate
        (the drug-interaction renal tables checked against each label: its logic.RENAL_LABEL_RULES)."""
        di = self._interaction_db()
        out: dict[str, list[float]] = {"crcl": [], "egfr": []}
        if di is not None:
            out.update(di[1].renal_contraindication_limits())
        return out


_ROUTES = {"iv": "intravenous", "im": "intramuscular", "sc": "subcutaneous", "sq": "subcutaneous", "po": "oral",
           "sl": "sublingual", "by mouth": "oral"}


def _route(route: str) -> str:
    key = fold(route)
    return _ROUTES.get(key, key)


@lru_cache(maxsize=1)
def drug_reference() -> DrugReference:
    """The process-wide drug reference (formulary parsed once; the drug-interaction database on first need)."""
    return DrugReference(load_formulary())


def renal_conditions(reference: DrugReference, creatinine_mg_dl: float | None, age: float | None,
                     sex: str | None, weight_kg: float | None) -> list[str]:
    """'egfr < X' / 'crcl < X' for each threshold of the renal tables the patient's function is below."""
    if creatinine_mg_dl is None or not age or sex not in ("male", "female") or creatinine_mg_dl <= 0:
        return []
    from envs.calculators import calculate_ckd_epi_2021, calculate_creatinine_clearance

    values = {"egfr": calculate_ckd_epi_2021(creatinine_mg_dl, age, sex).score}
    if weight_kg:
        values["crcl"] = calculate_creatinine_clearance(age=age, weight_kg=weight_kg, creatinine_mg_dl=creatinine_mg_dl,
                                                        sex=sex).score
    out = []
    for metric, limits in reference.renal_thresholds().items():
        if metric in values:
            out += [f"{metric} < {limit:g}" for limit in limits if values[metric] < limit]
    return out


class RecordSafetyContext(BaseSafetyContext):
    """Drug facts from the shared `DrugReference`; subclasses answer the patient facts from their database."""

    use_builtin_fallback = True

    def __init__(self, get_db: Callable[[], Any], reference: DrugReference | None = None) -> None:
        self._get_db = get_db
        self.reference = reference or drug_reference()

    @property
    def db(self) -> Any:
        return self._get_db()

    def normalise_drug(self, name: str) -> str | None:
        return self.reference.resolve(name)

    def drug_classes(self, drug: str) -> list[str]:
        return self.reference.classes(drug)

    def interaction(self, drug_a: str, drug_b: str) -> tuple[str, str] | None:
        return self.reference.interaction(drug_a, drug_b)

    def max_dose_mg(self, drug: str, route: str | None = None) -> float | None:
        return self.reference.max_dose_mg(drug, route)

    def contraindicated_conditions(self, drug: str) -> list[str]:
        return self.reference.contraindicated_conditions(drug)

    def _expand_allergies(self, substances: list[str]) -> list[str]:
        out: list[str] = []
        for substance in substances:
            out.extend(self.reference.allergy_groups(substance))
        return list(dict.fromkeys(out))


_PREGNANT = re.compile(r"\bpregnan(?:t|cy)\b")
_NOT_PREGNANT = re.compile(r"\b(?:not|no|denies|negative)\b[^.;]{0,20}\bpregnan")


def pregnant_in(texts: list[str]) -> bool:
    """A stated (not negated, not 'prior') pregnancy in record texts."""
    for text in texts:
        low = text.lower()
        if _PREGNANT.search(low) and not _NOT_PREGNANT.search(low) and "prior pregnan" not in low:
            return True
    return False
