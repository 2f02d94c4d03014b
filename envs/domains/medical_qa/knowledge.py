"""The medical-QA reference index: ICD-10-CM, HPO diseases/phenotypes, FDA drug classes, guidelines.

Loaded once per process from the files `build.py` writes (read-only, shared by every episode), with
the look-up indexes the tools need so that a tool call stays within a few milliseconds:
normalised names -> ids, word -> ICD codes, phenotype -> annotated diseases, class -> drugs.
"""

from __future__ import annotations

import heapq
import json
import math
import re
import unicodedata
from collections import defaultdict
from functools import lru_cache
from pathlib import Path

import numpy as np

from envs.core.db import DataFileError
from envs.core.paths import domain_build_dir

REFERENCE_FILES = ("icd10cm.json", "hpo.json", "drugs.json", "guidelines.json")
_WORD = re.compile(r"[a-z0-9]+")
ICD_CODE = re.compile(r"\b([A-TV-Z][0-9][0-9AB](?:\.[0-9A-Z]{1,4})?)\b")
STOP = frozenset("a an and are as at be by for from has have in is it its of on or than that the this to was "
                 "were which with without what who whose not no nos other unspecified".split())
# Words that carry no meaning in an ICD description search beyond the stop words.
_MAX_NGRAM = 10
GROUP_CAP = 150


def norm(text: str) -> str:
    """Lower-case, strip accents, keep letters/digits, collapse spaces ("Type-2  DM" -> "type 2 dm")."""
    text = str(text)
    if not text.isascii():
        text = "".join(c for c in unicodedata.normalize("NFKD", text) if not unicodedata.combining(c))
    return " ".join(_WORD.findall(text.lower()))


def words(text: str) -> list[str]:
    return [w for w in norm(text).split() if w not in STOP]


class MedicalKnowledge:
    """Read-only reference data with indexes. Build it with :func:`load_knowledge`."""

    def __init__(self, icd: dict, hpo: dict, drugs: dict, guidelines: dict, interactions: list[dict],
                 interaction_source: str, ansm: dict | None = None) -> None:
        self.icd_version = icd["version"]
        self.icd_codes: dict[str, dict] = icd["codes"]
        self.icd_blocks: dict[str, dict] = icd["blocks"]
        self.icd_chapters: dict[str, dict] = icd["chapters"]
        self.icd_words: dict[str, list[str]] = defaultdict(list)
        self.icd_by_desc: dict[str, list[str]] = defaultdict(list)
        self.icd_norm: dict[str, str] = {}
        self.icd_len: dict[str, int] = {}
        for code, rec in self.icd_codes.items():
            key = norm(rec["desc"])
            self.icd_norm[code] = key
            self.icd_by_desc[key].append(code)
            ws = [w for w in key.split() if w not in STOP]
            self.icd_len[code] = len(ws) or 1
            for w in set(ws):
                self.icd_words[w].append(code)
        self.hpo_version = hpo["version"]
        self.terms: dict[str, dict] = hpo["terms"]
        self.diseases: dict[str, dict] = hpo["diseases"]
        self.term_by_name: dict[str, list[str]] = defaultdict(list)
        self.children: dict[str, list[str]] = defaultdict(list)
        for tid, term in self.terms.items():
            for name in [term["name"], *term["synonyms"]]:
                key = norm(name)
                if tid not in self.term_by_name[key]:
                    self.term_by_name[key].append(tid)
            for parent in term["parents"]:
                self.children[parent].append(tid)
        self.disease_by_name: dict[str, list[str]] = defaultdict(list)
        self.annotated: dict[str, list[tuple[str, float | None]]] = defaultdict(list)
        self.disease_words: dict[str, list[str]] = defaultdict(list)
        self.disease_pheno: dict[str, dict[str, float | None]] = {}
        for did, dis in self.diseases.items():
            self.disease_by_name[norm(dis["name"])].append(did)
            self.disease_pheno[did] = {h: f for h, f in dis["phenotypes"]}
            for hid, freq in dis["phenotypes"]:
                self.annotated[hid].append((did, freq))
            for w in set(words(dis["name"])):
                self.disease_words[w].append(did)
        # Every term's ancestors, precomputed once so that phenotype matching is a set lookup.
        self.term_ancestors: dict[str, frozenset[str]] = {}
        for tid in self.terms:
            self._ancestors_of(tid)
        n = max(len(self.diseases), 1)
        # Information content of a term from the diseases annotated with it (or a descendant is not
        # counted: direct annotation keeps the index small and the score monotone).
        self.term_ic = {h: math.log(n / len(d)) for h, d in self.annotated.items()}
        self.max_ic = math.log(n)
        # Per annotation: information content x (0.5 + 0.5 x frequency), the disease-ranking weight.
        # Stored as numpy arrays per term (disease index, weight) so that ranking is vectorised.
        self.disease_ids: list[str] = sorted(self.diseases)
        index = {d: i for i, d in enumerate(self.disease_ids)}
        self.annotated_arrays: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for h, ds in self.annotated.items():
            idx = np.fromiter((index[d] for d, _ in ds), dtype=np.int32, count=len(ds))
            val = np.fromiter((self.term_ic[h] * (0.5 + 0.5 * (f if f is not None else 0.5)) for _, f in ds),
                              dtype=np.float64, count=len(ds))
            self.annotated_arrays[h] = (idx, val)
        self._desc_cache: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.drugs: dict[str, dict] = drugs
        self.drug_by_name: dict[str, str] = {}
        self.class_members: dict[str, list[str]] = defaultdict(list)
        self.moa_members: dict[str, list[str]] = defaultdict(list)
        for key, rec in drugs.items():
            for name in [key, rec["name"], *rec.get("variants", []), *rec.get("brands", [])]:
                self.drug_by_name.setdefault(norm(name), key)
            for cls in rec["epc"]:
                self.class_members[cls].append(key)
            for moa in rec["moa"]:
                self.moa_members[moa].append(key)
        self.class_by_name = {norm(c): c for c in self.class_members}
        self.moa_by_name = {norm(c): c for c in self.moa_members}
        self.guidelines: dict[str, dict] = guidelines
        self.guideline_words: dict[str, dict[str, int]] = defaultdict(dict)
        self.guideline_len: dict[str, int] = {}
        self.guideline_lines: dict[str, list[tuple[frozenset[str], str]]] = {}
        for sid, sec in guidelines.items():
            self.guideline_lines[sid] = [(frozenset(words(line)), line.strip()) for line in sec["text"].splitlines()
                                         if line.strip()]
            toks = words(sec["guideline"] + " " + sec["title"] + " " + sec["text"])
            self.guideline_len[sid] = len(toks)
            for w in toks:
                self.guideline_words[w][sid] = self.guideline_words[w].get(sid, 0) + 1
        self.avg_guideline_len = sum(self.guideline_len.values()) / max(len(self.guideline_len), 1)
        self.interactions: dict[frozenset, dict] = {}
        for item in interactions:
            a, b = self.resolve_drug(item["drug_a"]) or norm(item["drug_a"]), self.resolve_drug(item["drug_b"]) or norm(item["drug_b"])
            self.interactions[frozenset((a, b))] = item
        self.interaction_source = interaction_source
        self.ansm = ansm

    def ansm_rules(self, a: str, b: str) -> list[dict]:
        """ANSM thesaurus rules (from the drug-interaction build) whose parties cover drugs a and b,
        at substance or class level."""
        if not self.ansm:
            return []
        def keys(d: str) -> list[str]:
            return [f"drug:{d}"] + [f"class:{c}" for c in self.ansm["drug_classes"].get(d, [])]
        keys_b = set(keys(b))
        found: dict[str, dict] = {}
        for key in keys(a):
            for rid in self.ansm["party_index"].get(key, []):
                rule = self.ansm["rules"][rid]
                ka, kb = rule["party_a"], rule["party_b"]
                if (ka == key and kb in keys_b) or (kb == key and ka in keys_b):
                    found[rid] = {"rule_id": rid, **{k: rule[k] for k in ("severity", "severity_level", "summary")}}
        return [found[k] for k in sorted(found)]

    # -- ICD -----------------------------------------------------------------------------------
    def icd(self, code: str) -> dict | None:
        code = code.strip().upper()
        if code in self.icd_codes:
            return self.icd_codes[code]
        if len(code) > 3 and "." not in code:  # "E119" -> "E11.9"
            dotted = code[:3] + "." + code[3:]
            return self.icd_codes.get(dotted)
        return None

    def canonical_code(self, code: str) -> str | None:
        code = code.strip().upper()
        if code in self.icd_codes:
            return code
        if len(code) > 3 and "." not in code and code[:3] + "." + code[3:] in self.icd_codes:
            return code[:3] + "." + code[3:]
        return None

    def _posting_set(self, word: str) -> frozenset[str]:
        cache = self.__dict__.setdefault("_posting_sets", {})
        found = cache.get(word)
        if found is None:
            found = cache[word] = frozenset(self.icd_words[word])
        return found

    def search_icd(self, query: str, limit: int, billable_only: bool) -> list[tuple[str, float]]:
        q = list(dict.fromkeys(words(query)))
        if not q:
            return []
        total = len(self.icd_codes)
        weighted = sorted(((math.log(1 + total / len(self.icd_words[w])), w) for w in q if w in self.icd_words),
                          reverse=True)
        if not weighted:
            return []
        # Candidates must contain one of the two rarest query words; the commonest words
        # ("bilateral", "other") then only re-rank, which keeps a search to a few thousand codes.
        candidates: set[str] = set()
        for _, w in weighted[:2]:
            candidates.update(self.icd_words[w])
        scores = dict.fromkeys(candidates, 0.0)
        for weight, w in weighted:
            posting = self.icd_words[w]
            if len(posting) > len(candidates):
                posting_set = self._posting_set(w)  # O(1) membership instead of re-splitting descriptions
                for code in candidates:
                    if code in posting_set:
                        scores[code] += weight
            else:
                for code in posting:
                    if code in scores:
                        scores[code] += weight
        qn = norm(query)
        ranked = []
        for code, score in scores.items():
            if billable_only and not self.icd_codes[code]["billable"]:
                continue
            bonus = 5.0 if self.icd_norm[code] == qn else 0.0
            ranked.append((code, round(score / math.sqrt(self.icd_len[code]) + bonus, 4)))
        return heapq.nsmallest(limit, ranked, key=lambda x: (-x[1], x[0]))

    # -- HPO -----------------------------------------------------------------------------------
    def resolve_term(self, text: str) -> str | None:
        text = text.strip()
        if text.upper().startswith("HP:"):
            return text.upper() if text.upper() in self.terms else None
        ids = self.term_by_name.get(norm(text))
        return ids[0] if ids else None

    def resolve_disease(self, text: str) -> list[str]:
        text = text.strip()
        if ":" in text and text.split(":")[0].upper() in ("OMIM", "ORPHA", "DECIPHER"):
            key = text.split(":")[0].upper() + ":" + text.split(":", 1)[1].strip()
            return [key] if key in self.diseases else []
        return list(self.disease_by_name.get(norm(text), []))

    def _ancestors_of(self, tid: str) -> frozenset[str]:
        cached = self.term_ancestors.get(tid)
        if cached is not None:
            return cached
        out: set[str] = set()
        for parent in self.terms.get(tid, {}).get("parents", []):
            if parent in self.terms:
                out.add(parent)
                out |= self._ancestors_of(parent)
        self.term_ancestors[tid] = frozenset(out)
        return self.term_ancestors[tid]

    def ancestors(self, tid: str) -> frozenset[str]:
        return self.term_ancestors.get(tid, frozenset())

    def descendants(self, tid: str, cap: int = 5000) -> set[str]:
        seen: set[str] = set()
        stack = list(self.children.get(tid, []))
        while stack and len(seen) < cap:
            t = stack.pop()
            if t not in seen:
                seen.add(t)
                stack.extend(self.children.get(t, []))
        return seen

    def phenotype_match(self, disease_id: str, tid: str) -> tuple[str, str | None, float | None]:
        """How a disease's annotations cover a phenotype: ("exact"|"more specific"|"less specific"|"none",
        the annotated term that matched, its frequency)."""
        pheno = self.disease_pheno[disease_id]
        if tid in pheno:
            return "exact", tid, pheno[tid]
        for h, f in pheno.items():
            if tid in self.term_ancestors.get(h, ()):
                return "more specific", h, f
        anc = self.ancestors(tid)
        for h, f in pheno.items():
            if h in anc and h not in _ROOT_TERMS:
                return "less specific", h, f
        return "none", None, None

    def rank_diseases(self, term_ids: list[str], limit: int) -> list[dict]:
        """Diseases ranked by the information content of the query phenotypes they are annotated
        with (exactly or through a more specific term), weighted by annotation frequency."""
        n = len(self.disease_ids)
        total = np.zeros(n)
        hits = np.zeros((len(term_ids), n), dtype=bool)
        for row, tid in enumerate(term_ids):
            idx, val = self._group_arrays(tid)
            if not len(idx):
                continue
            best = np.zeros(n)
            np.maximum.at(best, idx, val)
            total += best
            hits[row] = best > 0
        if limit < n:
            top = np.argpartition(-total, limit)[:limit]
        else:
            top = np.arange(n)
        ranked = sorted((i for i in top.tolist() if total[i] > 0), key=lambda i: (-total[i], self.disease_ids[i]))
        out = []
        for i in ranked:
            did = self.disease_ids[i]
            matched = [self.terms[t]["name"] for row, t in enumerate(term_ids) if hits[row, i]]
            out.append({"disease_id": did, "name": self.diseases[did]["name"], "score": round(float(total[i]), 3),
                        "matched": len(matched), "of": len(term_ids), "matched_phenotypes": matched})
        return out

    def _group_arrays(self, tid: str) -> tuple[np.ndarray, np.ndarray]:
        """(disease index, weight) of the annotations with the term or one of its descendants."""
        cached = self._desc_cache.get(tid)
        if cached is None:
            below = self.descendants(tid, cap=GROUP_CAP)
            # A very general term (subtree larger than the cap) matches its exact annotations only:
            # expanding it would match most diseases and cost tens of milliseconds.
            group = [tid] if len(below) >= GROUP_CAP else [tid, *sorted(below)]
            parts = [self.annotated_arrays[h] for h in group if h in self.annotated_arrays]
            if parts:
                cached = (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))
            else:
                cached = (np.zeros(0, dtype=np.int32), np.zeros(0))
            if len(self._desc_cache) < 20000:
                self._desc_cache[tid] = cached
        return cached

    # -- drugs ---------------------------------------------------------------------------------
    def resolve_drug(self, text: str) -> str | None:
        key = norm(text)
        if key in self.drug_by_name:
            return self.drug_by_name[key]
        stripped = " ".join(w for w in key.split() if w not in _SALTS)
        return self.drug_by_name.get(stripped)

    def resolve_class(self, text: str) -> tuple[str, str] | None:
        key = norm(text)
        if key in self.class_by_name:
            return "epc", self.class_by_name[key]
        if key in self.moa_by_name:
            return "moa", self.moa_by_name[key]
        return None

    # -- guidelines ----------------------------------------------------------------------------
    def search_guidelines(self, query: str, limit: int) -> list[tuple[str, float]]:
        q = list(dict.fromkeys(words(query)))
        n = len(self.guidelines)
        scores: dict[str, float] = defaultdict(float)
        for w in q:
            posting = self.guideline_words.get(w)
            if not posting:
                continue
            idf = math.log(1 + (n - len(posting) + 0.5) / (len(posting) + 0.5))
            for sid, tf in posting.items():
                denom = tf + 1.2 * (0.25 + 0.75 * self.guideline_len[sid] / self.avg_guideline_len)
                scores[sid] += idf * tf * 2.2 / denom
        return sorted(((s, round(v, 3)) for s, v in scores.items()), key=lambda x: (-x[1], x[0]))[:limit]

    # -- entity extraction ---------------------------------------------------------------------
    def extract_entities(self, text: str) -> dict[str, list[dict]]:
        """Longest-match dictionary extraction of phenotypes, diseases, drugs, drug classes and ICD codes."""
        found: dict[str, list[dict]] = {"phenotypes": [], "diseases": [], "drugs": [], "drug_classes": [],
                                        "icd10_codes": []}
        for code in dict.fromkeys(ICD_CODE.findall(text)):
            canonical = self.canonical_code(code)
            if canonical:
                found["icd10_codes"].append({"code": canonical, "description": self.icd_codes[canonical]["desc"]})
        seen: set[tuple[str, str]] = set()
        for line in re.split(r"[\n;]|(?<=[a-z])\.\s", text):
            toks = norm(line).split()
            i = 0
            while i < len(toks):
                hit = None
                for n in range(min(_MAX_NGRAM, len(toks) - i), 0, -1):
                    phrase = " ".join(toks[i:i + n])
                    if n == 1 and (phrase in STOP or len(phrase) < 3):
                        continue
                    kinds = []
                    if phrase in self.term_by_name and self.term_by_name[phrase][0] not in _ROOT_TERMS:
                        kinds.append("phenotypes")
                    if phrase in self.disease_by_name and n >= 2:
                        kinds.append("diseases")
                    if not kinds and (phrase in self.class_by_name or phrase in self.moa_by_name):
                        kinds.append("drug_classes")
                    if not kinds and phrase in self.drug_by_name:
                        kinds.append("drugs")
                    if kinds:
                        hit = (kinds, phrase, n)
                        break
                if hit is None:
                    i += 1
                    continue
                kinds, phrase, n = hit
                for kind in kinds:
                    if (kind, phrase) not in seen:
                        seen.add((kind, phrase))
                        found[kind].append(self._entity(kind, phrase))
                i += n
        return found

    def _entity(self, kind: str, phrase: str) -> dict:
        if kind == "phenotypes":
            tid = self.term_by_name[phrase][0]
            return {"text": phrase, "hpo_id": tid, "name": self.terms[tid]["name"]}
        if kind == "diseases":
            ids = self.disease_by_name[phrase]
            return {"text": phrase, "disease_ids": ids, "name": self.diseases[ids[0]]["name"]}
        if kind == "drugs":
            key = self.drug_by_name[phrase]
            return {"text": phrase, "drug": self.drugs[key]["name"], "classes": self.drugs[key]["epc"]}
        label = self.class_by_name.get(phrase) or self.moa_by_name.get(phrase)
        return {"text": phrase, "drug_class": label}


# The ontology's roots: "matching" through them says nothing.
_ROOT_TERMS = frozenset({"HP:0000001", "HP:0000118", "HP:0000005", "HP:0012823", "HP:0040279", "HP:0031797"})
_SALTS = frozenset("sodium potassium calcium hydrochloride hcl sulfate tartrate succinate maleate mesylate besylate "
                   "citrate acetate fumarate phosphate".split())


def _read(path: Path):
    if not path.exists():
        raise DataFileError(f"{path}: medical_qa reference file missing (run `hcgym data build`)")
    return json.loads(path.read_text(encoding="utf-8"))


@lru_cache(maxsize=2)
def load_knowledge(build_dir: str | None = None) -> MedicalKnowledge:
    """Load the reference files once per process (keyed by folder)."""
    root = Path(build_dir) if build_dir else domain_build_dir("medical_qa")
    icd, hpo, drugs, guidelines = (_read(root / name) for name in REFERENCE_FILES)
    inter = _read(root / "interactions.json") if (root / "interactions.json").exists() else {"source": "none", "pairs": []}
    return MedicalKnowledge(icd, hpo, drugs, guidelines, inter["pairs"], inter["source"], load_ansm_rules())


def load_ansm_rules(path: Path | None = None) -> dict | None:
    """The ANSM interaction rules of the drug-interaction build (`domain_build_dir("drug_interaction")/db.json`),
    reduced to what pair look-ups need; None when that domain has not been built."""
    path = path or domain_build_dir("drug_interaction") / "db.json"
    if not path.exists():
        return None
    db = json.loads(path.read_text(encoding="utf-8"))

    def key(party: dict) -> str:
        return f"{'drug' if party['kind'] == 'substance' else 'class'}:{party.get('id')}"

    rules = {rid: {"party_a": key(r["party_a"]), "party_b": key(r["party_b"]), "severity": r["severity"],
                   "severity_level": r["severity_level"], "summary": r["summary"]["text"]}
             for rid, r in db["interactions"].items()}
    return {"source": f"ANSM thesaurus via the drug_interaction build ({path})",
            "drug_classes": {d: rec.get("class_ids", []) for d, rec in db["drugs"].items()},
            "party_index": db["party_index"], "rules": rules}
