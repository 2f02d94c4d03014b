"""Fixtures for the knowledge-base tests: a small hand-made corpus with known ranking
properties plus seeded filler (so idf values are realistic), built once per session."""

from __future__ import annotations

import json
import random
from pathlib import Path

import pytest

FILLER_WORDS = (
    "patient clinical history examination treatment therapy dose hospital chronic acute pain fever "
    "blood pressure heart rate laboratory result imaging follow visit symptom sign diagnosis risk "
    "management infection medication daily week month year report normal elevated reduced mild severe "
    "headache nausea fatigue swelling rash weight appetite sleep").split()

KEY_PASSAGES = [
    # tf: 3 mentions vs 1 mention of the same rare term, equal lengths otherwise
    {"doc_id": "k:pheo3", "source": "guidelines", "title": "Adrenal tumour workup", "category": "endocrine",
     "content": "Pheochromocytoma presents with episodic headache. Pheochromocytoma is confirmed by metanephrines. "
                "Resection of a pheochromocytoma follows alpha blockade."},
    {"doc_id": "k:pheo1", "source": "guidelines", "title": "Hypertension causes", "category": "cardiology",
     "content": "Secondary hypertension has many causes including renal artery stenosis, hyperaldosteronism and "
                "rarely pheochromocytoma, which should be considered in young patients."},
    # length normalisation: same single mention, short vs long passage
    {"doc_id": "k:short", "source": "wiki", "title": "Zollinger", "category": "gastro",
     "content": "Zollinger-Ellison syndrome causes refractory ulcers."},
    {"doc_id": "k:long", "source": "wiki", "title": "Peptic ulcer disease", "category": "gastro",
     "content": "Peptic ulcer disease is common. " + " ".join(["Most ulcers are due to Helicobacter infection or "
                "nonsteroidal drugs and respond to proton pump inhibitors."] * 6) + " A rare cause is the "
                "Zollinger-Ellison syndrome."},
    # rare vs common term
    {"doc_id": "k:warfarin", "source": "drugs", "title": "Warfarin", "category": "anticoagulant",
     "content": "Warfarin is a vitamin K antagonist; monitor the INR closely."},
    # stemming
    {"doc_id": "k:cough", "source": "wiki", "title": "Pertussis", "category": "infection",
     "content": "Pertussis causes paroxysmal coughs with an inspiratory whoop in children."},
    # phrase vs scattered words
    {"doc_id": "k:hf", "source": "guidelines", "title": "Chronic heart failure", "category": "cardiology",
     "content": "In heart failure with reduced ejection fraction, start an ACE inhibitor and a beta blocker."},
    {"doc_id": "k:hf-scattered", "source": "wiki", "title": "Valve disease", "category": "cardiology",
     "content": "Failure of the mitral valve to close lets blood flow back; the heart enlarges over years."},
    # boolean
    {"doc_id": "k:asthma-steroid", "source": "guidelines", "title": "Asthma controller therapy", "category": "pulmonary",
     "content": "Inhaled corticosteroid therapy controls persistent asthma; add a long-acting bronchodilator."},
    {"doc_id": "k:asthma-only", "source": "wiki", "title": "Asthma", "category": "pulmonary",
     "content": "Asthma is reversible airway obstruction with wheeze and nocturnal symptoms."},
    {"doc_id": "k:steroid-only", "source": "drugs", "title": "Prednisolone", "category": "steroid",
     "content": "Prednisolone is an oral corticosteroid used for inflammatory disease flares."},
    # non-Latin scripts and accents
    {"doc_id": "k:greek", "source": "wiki", "title": "Πνευμονία", "category": "infection",
     "content": "Η πνευμονία είναι λοίμωξη του πνεύμονα. Pneumonia in Greek."},
    {"doc_id": "k:cafe", "source": "wiki", "title": "Café au lait macules", "category": "dermatology",
     "content": "Café au lait macules are a sign of neurofibromatosis type 1."},
    {"doc_id": "k:covid", "source": "wiki", "title": "COVID-19", "category": "infection",
     "content": "COVID-19 is caused by SARS-CoV-2; anosmia is a characteristic early symptom."},
]


def make_corpus(n_filler: int = 400, seed: int = 0) -> list[dict]:
    rng = random.Random(seed)
    docs = [dict(p, dataset_name="fixture") for p in KEY_PASSAGES]
    for i in range(n_filler):
        words = [rng.choice(FILLER_WORDS) for _ in range(rng.randint(20, 60))]
        docs.append({"doc_id": f"f:{i}", "source": rng.choice(["wiki", "guidelines", "drugs"]),
                     "title": " ".join(words[:3]).title(), "content": " ".join(words) + ".",
                     "category": rng.choice(["general", "cardiology", "pulmonary"]), "dataset_name": "filler"})
    return docs


def write_jsonl(path: Path, docs: list[dict]) -> Path:
    path.write_text("".join(json.dumps(d, ensure_ascii=False) + "\n" for d in docs), encoding="utf-8")
    return path


ARTICLES = [
    {"url": "https://en.wikipedia.org/wiki/Heart_failure", "title": "Heart failure",
     "text": "Heart failure is a syndrome caused by impaired cardiac function.\n\nSigns include dyspnea, orthopnea "
             "and peripheral oedema.\n\nTreatment: diuretics, ACE inhibitors, beta blockers and SGLT2 inhibitors."},
    {"url": "https://en.wikipedia.org/wiki/Kawasaki_disease", "title": "Kawasaki disease",
     "text": "Kawasaki disease is a vasculitis of childhood.\n\nIt is treated with intravenous immunoglobulin and aspirin."},
    {"url": "https://fr.wikipedia.org/wiki/Pneumonie", "title": "Pneumonie", "text": "La pneumonie est une infection "
             "du poumon. " * 300},
]


@pytest.fixture(scope="session")
def corpus() -> list[dict]:
    return make_corpus()


@pytest.fixture(scope="session")
def kb_dir(tmp_path_factory, corpus) -> Path:
    from kb_service.ingest import build_kb, file_input

    root = tmp_path_factory.mktemp("kb")
    src = write_jsonl(root / "passages.jsonl", corpus)
    arts = write_jsonl(root / "articles.jsonl", ARTICLES)
    out = root / "kb"
    build_kb([file_input(src), file_input(arts, articles=True, source="wikipedia")], out,
             article_files=[arts], progress=False, echo=lambda s: None)
    return out


@pytest.fixture(scope="session")
def kb(kb_dir):
    from kb_service.kb import KnowledgeBase

    return KnowledgeBase.open(kb_dir)
