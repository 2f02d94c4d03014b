"""Medical-QA tools: evidence look-ups over ICD-10-CM, HPO, FDA drug classes and guidelines.

Every tool computes from the reference index (`knowledge.py`) or its inputs; the per-option
evidence of `analyze_answer_options` is derived from the question text and the options exactly as
the agent sees them (no hidden answer key is read).
"""

from __future__ import annotations

import itertools
import math
from typing import Any

from envs.core.calculator_tools import calculator_method
from envs.core.common_tools import BaseDomainTools
from envs.core.fuzzy import names_starting_with
from envs.core.tools import ToolError, ToolType, is_tool
from envs.domains.medical_qa.data_model import EvidenceNote, MedicalQADB
from envs.domains.medical_qa.knowledge import ICD_CODE, MedicalKnowledge, norm, words
from envs.domains.pregnancy_labels import pregnancy_report

INHERITANCE_ROOT = "HP:0000005"


def _jaccard(a: str, b: str) -> float:
    wa, wb = set(words(a)), set(words(b))
    return round(len(wa & wb) / len(wa | wb), 3) if wa | wb else 0.0



def _label_dosing(drug: str, dosing: dict) -> dict:
    """The dosing reference with its pregnancy data from the US-label table where that table has the
    drug (magnesium sulfate: category D since 2013, not the package's A), else the package letter
    named as undated package data."""
    report = pregnancy_report(drug, dosing.get("pregnancy_category"))
    return {**dosing, "pregnancy_category": report["fda_category"], "pregnancy": report}


class MedicalQATools(BaseDomainTools):
    """Tools of the medical-QA domain. `db` is the episode state, `kb` the shared reference index."""

    db: MedicalQADB

    def __init__(self, db: MedicalQADB, kb: MedicalKnowledge) -> None:
        super().__init__(db)
        self.kb = kb

    # -- helpers -------------------------------------------------------------------------------
    def _question(self):
        if self.db.question is None:
            raise ToolError("no question is loaded in this episode; read the task text instead")
        return self.db.question

    def _suggest(self, names: dict[str, Any], text: str, kind: str) -> str:
        key = norm(text)[:4]
        # a binary search over the cached sorted names, not a scan of tens of thousands per call
        near = names_starting_with(key, names, 8) if key else []
        return f"{kind} {text!r} not found" + (f"; similar names: {', '.join(near)}" if near else "")

    def _drug_key(self, name: str) -> str:
        if not name or not name.strip():
            raise ToolError("argument 'name' is empty: give a generic or brand drug name")
        key = self.kb.resolve_drug(name)
        if key is None:
            raise ToolError(self._suggest(self.kb.drug_by_name, name, "drug") +
                            " (the index covers drugs with an FDA Established Pharmacologic Class)")
        return key

    def _disease_ids(self, disease: str) -> list[str]:
        ids = self.kb.resolve_disease(disease)
        if not ids:
            raise ToolError(self._suggest(self.kb.disease_by_name, disease, "disease") +
                            "; use an OMIM:/ORPHA: id or search_diseases")
        return ids

    def _term(self, text: str) -> str:
        tid = self.kb.resolve_term(text)
        if tid is None:
            raise ToolError(self._suggest(self.kb.term_by_name, text, "HPO phenotype") +
                            "; give an HP:xxxxxxx id or an HPO term name or synonym")
        return tid

    # -- the question --------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def get_question(self) -> dict:
        """Return the current question's stem and lettered options."""
        q = self._question()
        return {"question_id": q.question_id, "stem": q.stem, "options": q.options}

    @is_tool(ToolType.READ)
    def extract_clinical_entities(self, text: str) -> dict:
        """Find phenotypes (HPO), diseases, drugs, drug classes and ICD-10-CM codes named in a text.

        Args:
            text: Free text, e.g. the question stem.
        """
        if not text.strip():
            raise ToolError("argument 'text' is empty")
        return self.kb.extract_entities(text[:20000])

    @is_tool(ToolType.READ)
    def analyze_answer_options(self) -> dict:
        """Compute per-option evidence for the current question from ICD-10-CM, HPO and drug-class data.

        For each option: the ICD-10-CM description of a code (and its word overlap with a quoted
        description in the stem), the coverage of the stem's phenotypes by a disease's HPO
        annotations, whether a phenotype or inheritance mode is annotated to a disease named in the
        stem, and a drug's FDA classes against the classes or drugs named in the stem.
        """
        q = self._question()
        ents = self.kb.extract_entities(q.stem)
        quoted = [part for i, part in enumerate(q.stem.split('"')) if i % 2 == 1]
        stem_terms = [e["hpo_id"] for e in ents["phenotypes"]]
        stem_diseases = [d for e in ents["diseases"] for d in e["disease_ids"]]
        stem_drugs = [self.kb.drug_by_name[norm(e["text"])] for e in ents["drugs"]]
        stem_classes = [e["drug_class"] for e in ents["drug_classes"]]
        out: dict[str, Any] = {}
        for letter, text in q.options.items():
            out[letter] = self._option_evidence(text, quoted, ents, stem_terms, stem_diseases, stem_drugs, stem_classes)
        return {
            "question_id": q.question_id,
            "stem_entities": {"phenotypes": [e["name"] for e in ents["phenotypes"]],
                              "diseases": [e["name"] for e in ents["diseases"]],
                              "drugs": [e["drug"] for e in ents["drugs"]], "drug_classes": stem_classes,
                              "icd10_codes": [e["code"] for e in ents["icd10_codes"]], "quoted": quoted},
            "options": out,
        }

    def _option_evidence(self, text: str, quoted: list[str], ents: dict, stem_terms: list[str],
                         stem_diseases: list[str], stem_drugs: list[str], stem_classes: list[str]) -> dict:
        kb = self.kb
        ev: dict[str, Any] = {"text": text}
        stripped = text.strip()
        if ICD_CODE.fullmatch(stripped.upper()):
            code = kb.canonical_code(stripped)
            if code is None:
                ev["icd10"] = {"code": stripped, "found": False}
            else:
                rec = kb.icd_codes[code]
                ev["icd10"] = {"code": code, "description": rec["desc"], "billable": rec["billable"]}
                if quoted:
                    ev["icd10"]["overlap_with_quoted"] = max(_jaccard(rec["desc"], qt) for qt in quoted)
                    ev["icd10"]["exact_match_with_quoted"] = any(norm(rec["desc"]) == norm(qt) for qt in quoted)
            return ev
        for e in ents["icd10_codes"]:
            ev.setdefault("vs_stem_codes", []).append({
                "code": e["code"], "overlap": _jaccard(text, e["description"]),
                "exact_match": norm(text) == norm(e["description"]),
                "option_codes": kb.icd_by_desc.get(norm(text), [])[:3]})
        disease_ids = kb.resolve_disease(stripped)
        if disease_ids and stem_terms:
            best = None
            for did in disease_ids:
                row = {"disease_id": did, "exact": 0, "more_specific": 0, "less_specific": 0, "unmatched": [],
                       "frequency_sum": 0.0, "excluded_in_stem": []}
                excluded = set(kb.diseases[did]["excluded"])
                for tid in stem_terms:
                    kind, _, freq = kb.phenotype_match(did, tid)
                    if kind == "none":
                        row["unmatched"].append(kb.terms[tid]["name"])
                    else:
                        row[kind.replace(" ", "_")] += 1
                        row["frequency_sum"] += freq if freq is not None else 0.5
                    if tid in excluded:
                        row["excluded_in_stem"].append(kb.terms[tid]["name"])
                row["frequency_sum"] = round(row["frequency_sum"], 3)
                row["covered"] = row["exact"] + row["more_specific"] + row["less_specific"]
                row["of"] = len(stem_terms)
                if best is None or (row["covered"], row["exact"]) > (best["covered"], best["exact"]):
                    best = row
            ev["phenotype_coverage"] = best
        tid = kb.resolve_term(stripped)
        if tid and stem_diseases:
            is_mode = INHERITANCE_ROOT in kb.ancestors(tid)
            rows = []
            for did in stem_diseases[:4]:
                if is_mode:
                    rows.append({"disease_id": did, "inheritance_annotated": kb.terms[tid]["name"] in kb.diseases[did]["inheritance"],
                                 "disease_inheritance": kb.diseases[did]["inheritance"]})
                else:
                    kind, via, freq = kb.phenotype_match(did, tid)
                    rows.append({"disease_id": did, "annotation": kind, "via": kb.terms[via]["name"] if via else None,
                                 "frequency": freq, "excluded": tid in kb.diseases[did]["excluded"]})
            ev["hpo_term"] = {"hpo_id": tid, "name": kb.terms[tid]["name"], "in_stem_diseases": rows}
        drug = kb.resolve_drug(stripped)
        if drug:
            rec = kb.drugs[drug]
            ev["drug"] = {"drug": rec["name"], "epc": rec["epc"], "moa": rec["moa"]}
            if stem_classes:
                ev["drug"]["has_stem_class"] = {c: (c in rec["epc"] or c in rec["moa"]) for c in stem_classes}
        cls = kb.resolve_class(stripped)
        if cls and stem_drugs:
            kind, label = cls
            ev["drug_class"] = {"class": label, "type": "FDA EPC" if kind == "epc" else "FDA MoA",
                                "stem_drugs_in_class": {kb.drugs[d]["name"]: label in kb.drugs[d][kind] for d in stem_drugs}}
        try:
            float(stripped.split()[0].replace(",", ""))
            ev.setdefault("numeric", True)
        except (ValueError, IndexError):
            pass
        return ev

    @is_tool(ToolType.WRITE)
    def record_evidence(self, option: str, finding: str, source: str, supports: bool) -> dict:
        """Record a piece of evidence for or against one option of the current question.

        Args:
            option: The option letter, e.g. "B".
            finding: What the evidence says, in one sentence.
            source: Where it comes from, e.g. "lookup_icd10 E11.9" or a guideline section id.
            supports: True if it supports the option, False if it argues against it.
        """
        q = self._question()
        letter = option.strip().upper()
        if letter not in q.options:
            raise ToolError(f"option {option!r} is not one of {', '.join(q.options)}")
        if not finding.strip() or not source.strip():
            raise ToolError("arguments 'finding' and 'source' must not be empty")
        self.db.evidence.append(EvidenceNote(option=letter, finding=finding.strip(), source=source.strip(),
                                             supports=supports))
        return {"recorded": len(self.db.evidence), "option": letter, "supports": supports}

    # -- ICD-10-CM -----------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def lookup_icd10(self, code: str) -> dict:
        """Look up an ICD-10-CM code: description, billability, hierarchy, inclusion and excludes notes.

        Args:
            code: An ICD-10-CM code with or without the dot, e.g. "E11.9" or "E119".
        """
        canonical = self.kb.canonical_code(code)
        if canonical is None:
            raise ToolError(f"ICD-10-CM code {code!r} not found (version {self.kb.icd_version}); "
                            "check the format (letter, two digits, optional dot and up to 4 characters)")
        rec = self.kb.icd_codes[canonical]
        chain, parent = [], rec["parent"]
        while parent:
            chain.append({"code": parent, "description": self.kb.icd_codes[parent]["desc"]})
            parent = self.kb.icd_codes[parent]["parent"]
        block = self.kb.icd_blocks[rec["block"]]
        return {
            "code": canonical, "description": rec["desc"], "billable": rec["billable"],
            "requires_7th_character": rec["requires_7th"], "parents": chain,
            "block": {"range": rec["block"], "title": block["title"]},
            "chapter": {"number": rec["chapter"], "title": self.kb.icd_chapters[rec["chapter"]]["title"]},
            "children": [{"code": c, "description": self.kb.icd_codes[c]["desc"]} for c in rec["children"][:40]],
            "inclusion_terms": rec["inclusion"], "excludes1": rec["excludes1"], "excludes2": rec["excludes2"],
            "version": self.kb.icd_version,
        }

    @is_tool(ToolType.READ)
    def search_icd10(self, query: str, limit: int = 10, billable_only: bool = True) -> dict:
        """Search ICD-10-CM descriptions by words (TF-IDF ranking); exact description matches rank first.

        Args:
            query: Diagnosis words, e.g. "type 2 diabetes with hyperglycemia".
            limit: Maximum number of codes to return (1-50).
            billable_only: Only return billable (codable) codes.
        """
        if not words(query):
            raise ToolError("argument 'query' has no searchable words")
        if not 1 <= limit <= 50:
            raise ToolError("argument 'limit' must be between 1 and 50")
        hits = self.kb.search_icd(query, limit, billable_only)
        return {"query": query, "results": [{"code": c, "description": self.kb.icd_codes[c]["desc"], "score": s}
                                            for c, s in hits]}

    @is_tool(ToolType.READ)
    def list_icd10_category(self, code: str) -> dict:
        """List the codes under an ICD-10-CM category or subcategory and the categories of its block.

        Args:
            code: A category or any code inside it, e.g. "E11" or "E11.65".
        """
        canonical = self.kb.canonical_code(code)
        if canonical is None:
            raise ToolError(f"ICD-10-CM code {code!r} not found")
        category = canonical[:3]
        rec = self.kb.icd_codes[category]
        below = [c for c in self._descendants(category) if self.kb.icd_codes[c]["billable"]]
        block = self.kb.icd_blocks[rec["block"]]
        return {
            "category": category, "description": rec["desc"],
            "billable_codes": [{"code": c, "description": self.kb.icd_codes[c]["desc"]} for c in below[:80]],
            "billable_count": len(below),
            "block": {"range": rec["block"], "title": block["title"],
                      "categories": [{"code": c, "description": self.kb.icd_codes[c]["desc"]} for c in block["categories"]]},
        }

    def _descendants(self, code: str) -> list[str]:
        out, stack = [], [code]
        while stack:
            c = stack.pop()
            out.append(c)
            stack.extend(reversed(self.kb.icd_codes[c]["children"]))
        return out

    # -- HPO -----------------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def lookup_hpo_term(self, term: str) -> dict:
        """Look up a Human Phenotype Ontology term: definition, synonyms, parents and how many diseases carry it.

        Args:
            term: An HP id ("HP:0001250") or a term name or synonym ("Seizure").
        """
        tid = self._term(term)
        t = self.kb.terms[tid]
        return {"hpo_id": tid, "name": t["name"], "definition": t["definition"], "synonyms": t["synonyms"][:15],
                "parents": [{"hpo_id": p, "name": self.kb.terms[p]["name"]} for p in t["parents"] if p in self.kb.terms],
                "children": [self.kb.terms[c]["name"] for c in self.kb.children.get(tid, [])[:25]],
                "annotated_diseases": len(self.kb.annotated.get(tid, [])), "version": self.kb.hpo_version}

    @is_tool(ToolType.READ)
    def lookup_disease_phenotypes(self, disease: str, min_frequency: float = 0.0, limit: int = 60) -> dict:
        """Return a disease's HPO phenotype annotations (with frequencies), excluded features and inheritance.

        Args:
            disease: An OMIM/ORPHA id ("OMIM:154700") or the disease name ("Marfan syndrome").
            min_frequency: Only list phenotypes annotated at least this frequent (0-1); phenotypes
                without a stated frequency are always listed.
            limit: Maximum number of phenotypes per disease (1-300).
        """
        if not 0.0 <= min_frequency <= 1.0:
            raise ToolError("argument 'min_frequency' must be between 0 and 1")
        if not 1 <= limit <= 300:
            raise ToolError("argument 'limit' must be between 1 and 300")
        out = []
        for did in self._disease_ids(disease)[:3]:
            d = self.kb.diseases[did]
            rows = [{"hpo_id": h, "name": self.kb.terms[h]["name"], "frequency": f}
                    for h, f in d["phenotypes"] if f is None or f >= min_frequency]
            rows.sort(key=lambda r: (-(r["frequency"] if r["frequency"] is not None else 0.5), r["name"]))
            out.append({"disease_id": did, "name": d["name"], "inheritance": d["inheritance"],
                        "phenotype_count": len(d["phenotypes"]), "phenotypes": rows[:limit],
                        "excluded_phenotypes": [self.kb.terms[h]["name"] for h in d["excluded"]]})
        return {"diseases": out, "version": self.kb.hpo_version}

    @is_tool(ToolType.READ)
    def search_diseases_by_phenotypes(self, phenotypes: list[str], limit: int = 10) -> dict:
        """Rank HPO-annotated diseases by how well they explain a set of phenotypes (information-content weighted).

        Args:
            phenotypes: HPO term names, synonyms or HP ids observed in the patient.
            limit: Maximum number of diseases (1-50).
        """
        if not phenotypes:
            raise ToolError("argument 'phenotypes' is empty: give at least one HPO term")
        if not 1 <= limit <= 50:
            raise ToolError("argument 'limit' must be between 1 and 50")
        resolved, unknown = [], []
        for p in phenotypes[:30]:
            tid = self.kb.resolve_term(p)
            (resolved if tid else unknown).append(tid or p)
        if not resolved:
            raise ToolError(f"none of the phenotypes were recognised as HPO terms: {unknown[:5]}")
        resolved = list(dict.fromkeys(resolved))
        return {"phenotypes": [{"hpo_id": t, "name": self.kb.terms[t]["name"]} for t in resolved],
                "unrecognised": unknown, "results": self.kb.rank_diseases(resolved, limit)}

    @is_tool(ToolType.READ)
    def search_diseases(self, query: str, limit: int = 10) -> dict:
        """Find HPO-annotated diseases (OMIM/Orphanet) whose name contains the query words.

        Args:
            query: Words of the disease name, e.g. "marfan".
            limit: Maximum number of diseases (1-50).
        """
        q = words(query)
        if not q:
            raise ToolError("argument 'query' has no searchable words")
        if not 1 <= limit <= 50:
            raise ToolError("argument 'limit' must be between 1 and 50")
        postings = [set(self.kb.disease_words.get(w, ())) for w in q]
        hits = set.intersection(*postings) if all(postings) else set()
        ranked = sorted(hits, key=lambda d: (len(self.kb.diseases[d]["name"]), d))[:limit]
        return {"query": query, "total": len(hits),
                "results": [{"disease_id": d, "name": self.kb.diseases[d]["name"],
                             "phenotype_count": len(self.kb.diseases[d]["phenotypes"])} for d in ranked]}

    # -- drugs ---------------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def lookup_drug(self, name: str) -> dict:
        """Look up a drug (generic or brand name): FDA pharmacologic class, mechanism, routes, brands, dosing.

        Args:
            name: Generic or brand name, e.g. "lisinopril" or "Zestril".
        """
        key = self._drug_key(name)
        rec = self.kb.drugs[key]
        out = {"query": name, "drug": rec["name"], "established_pharmacologic_class": rec["epc"],
               "mechanism_of_action": rec["moa"], "physiologic_effect": rec["pe"], "chemical_class": rec["chemical"],
               "routes": rec["routes"], "dosage_forms": rec["dosage_forms"], "brand_names": rec["brands"],
               "dea_schedule": rec["dea_schedule"], "drugbank_id": rec["drugbank_id"], "mesh_id": rec["mesh_id"],
               "class_members": {c: len(self.kb.class_members[c]) for c in rec["epc"]}}
        if "dosing" in rec:
            out["dosing"] = _label_dosing(key, rec["dosing"])
        return out

    @is_tool(ToolType.READ)
    def list_drug_class_members(self, drug_class: str, limit: int = 60) -> dict:
        """List the drugs in an FDA Established Pharmacologic Class or mechanism-of-action class.

        Args:
            drug_class: Class name, e.g. "Angiotensin Converting Enzyme Inhibitor".
            limit: Maximum number of drugs (1-300).
        """
        if not 1 <= limit <= 300:
            raise ToolError("argument 'limit' must be between 1 and 300")
        found = self.kb.resolve_class(drug_class)
        if found is None:
            raise ToolError(self._suggest(self.kb.class_by_name, drug_class, "drug class") +
                            " (FDA Established Pharmacologic Class or MoA names)")
        kind, label = found
        members = self.kb.class_members[label] if kind == "epc" else self.kb.moa_members[label]
        names = sorted(self.kb.drugs[m]["name"] for m in members)
        return {"drug_class": label, "type": "FDA EPC" if kind == "epc" else "FDA MoA", "count": len(names),
                "members": names[:limit]}

    @is_tool(ToolType.READ)
    def compare_treatments(self, treatments: list[str]) -> dict:
        """Compare drugs side by side: classes, mechanisms, routes, dose ranges, shared classes and interactions.

        Args:
            treatments: Two to six generic or brand drug names.
        """
        if not 2 <= len(treatments) <= 6:
            raise ToolError("argument 'treatments' must list 2 to 6 drugs")
        keys = [self._drug_key(t) for t in treatments]
        if len(set(keys)) < len(keys):
            raise ToolError("argument 'treatments' names the same drug twice (brand and generic?)")
        rows = []
        for key in keys:
            rec = self.kb.drugs[key]
            row = {"drug": rec["name"], "epc": rec["epc"], "moa": rec["moa"], "routes": rec["routes"],
                   "dea_schedule": rec["dea_schedule"]}
            if "dosing" in rec:
                d = _label_dosing(key, rec["dosing"])
                row["dose_ranges"] = [{k: r[k] for k in ("route", "dose_min", "dose_max", "dose_unit", "max_single_dose_mg")}
                                      for r in d["routes"]]
                row["pregnancy_category"] = d["pregnancy_category"]
                row["pregnancy"] = d["pregnancy"]
                row["contraindications"] = d["contraindications"]
            rows.append(row)
        pairs = []
        for a, b in itertools.combinations(keys, 2):
            ra, rb = self.kb.drugs[a], self.kb.drugs[b]
            inter = self.kb.interactions.get(frozenset((a, b)))
            pairs.append({
                "drugs": [ra["name"], rb["name"]],
                "shared_classes": sorted(set(ra["epc"]) & set(rb["epc"])),
                "shared_mechanisms": sorted(set(ra["moa"]) & set(rb["moa"])),
                "emergency_drug_interaction": ({k: inter.get(k) for k in ("severity", "description", "management")}
                                               if inter else None),
                "ansm_rules": self.kb.ansm_rules(a, b),
            })
        return {"treatments": rows, "pairs": pairs,
                "sources": {"emergency_drug_interaction": self.kb.interaction_source,
                            "ansm_rules": self.kb.ansm["source"] if self.kb.ansm else "drug_interaction domain not built"}}

    # -- guidelines ----------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def search_guideline_sections(self, query: str, limit: int = 5) -> dict:
        """Search the clinical guideline sections (BM25) and return section ids with a matching excerpt.

        Args:
            query: Words to search for, e.g. "AKI staging creatinine".
            limit: Maximum number of sections (1-20).
        """
        if not words(query):
            raise ToolError("argument 'query' has no searchable words")
        if not 1 <= limit <= 20:
            raise ToolError("argument 'limit' must be between 1 and 20")
        n = len(self.kb.guidelines)
        idf = {w: math.log(1 + n / len(self.kb.guideline_words[w])) for w in set(words(query)) if w in self.kb.guideline_words}
        results = []
        for sid, score in self.kb.search_guidelines(query, limit):
            sec = self.kb.guidelines[sid]
            # The excerpt is the body line sharing the rarest query words (headings only break ties).
            best = max(self.kb.guideline_lines[sid],
                       key=lambda item: (sum(idf.get(w, 0.0) for w in item[0]), not item[1].startswith("#")),
                       default=(None, ""))[1]
            results.append({"section_id": sid, "title": sec["title"], "guideline": sec["guideline"],
                            "year": sec["year"], "score": score, "excerpt": best[:400]})
        return {"query": query, "results": results}

    @is_tool(ToolType.READ)
    def read_guideline_section(self, section_id: str, offset: int = 0) -> dict:
        """Read a guideline section's text (12,000 characters per call; page with offset).

        Args:
            section_id: A section id from search_guideline_sections, e.g. "kdigo_aki_2012/definition_and_staging".
            offset: Character offset to start reading from.
        """
        sec = self.kb.guidelines.get(section_id.strip())
        if sec is None:
            near = [s for s in self.kb.guidelines if s.split("/")[0] == section_id.split("/")[0]]
            raise ToolError(f"guideline section {section_id!r} not found" +
                            (f"; sections of that guideline: {', '.join(near)}" if near else "; use search_guideline_sections"))
        if offset < 0 or offset > len(sec["text"]):
            raise ToolError(f"argument 'offset' must be between 0 and {len(sec['text'])}")
        chunk = sec["text"][offset:offset + 12000]
        nxt = offset + len(chunk)
        return {"section_id": section_id, "guideline": sec["guideline"], "doi": sec["doi"], "year": sec["year"],
                "text": chunk, "next_offset": nxt if nxt < len(sec["text"]) else None}

    # -- calculators for vignettes (envs.calculators, unchanged signatures) ---------------------
    calculate_anion_gap = calculator_method("calculate_anion_gap")
    calculate_corrected_calcium = calculator_method("calculate_corrected_calcium")
    calculate_corrected_sodium = calculator_method("calculate_corrected_sodium")
    calculate_serum_osmolality = calculator_method("calculate_serum_osmolality")
    calculate_bmi = calculator_method("calculate_bmi")
    calculate_creatinine_clearance = calculator_method("calculate_creatinine_clearance")
    calculate_ckd_epi_2021 = calculator_method("calculate_ckd_epi_2021")
    calculate_meld_na = calculator_method("calculate_meld_na")
    calculate_cha2ds2_vasc = calculator_method("calculate_cha2ds2_vasc")
    calculate_curb65 = calculator_method("calculate_curb65")
    calculate_wells_pe = calculator_method("calculate_wells_pe")
    calculate_qtc = calculator_method("calculate_qtc")
