"""The default knowledge base built by `hcgym data build` from registry packages.

These tests run when the default KB exists (CI runs `hcgym data build` before the tests); they
are skipped, with the reason shown, on a machine where it has not been built.
"""

from __future__ import annotations

import time

import pytest

from kb_service.kb import KBError, KnowledgeBase, default_kb_path

SOURCES = {"icd10cm", "hpo_terms", "hpo_diseases", "guidelines", "differentials", "drugs", "interactions",
           "healthbench"}


@pytest.fixture(scope="module")
def default_kb():
    try:
        return KnowledgeBase.open()
    except KBError as exc:
        pytest.skip(f"default KB not built ({exc})")


def test_size_sources_and_provenance(default_kb):
    stats = default_kb.stats()
    assert stats["n_passages"] >= 100_000
    assert set(stats["sources"]) == SOURCES
    assert stats["sources"]["icd10cm"] == 98_505  # every item of the ICD-10-CM April 2026 code list
    for source, provs in stats["provenance"].items():
        assert provs and all(p.get("package") and p.get("version") and p.get("license") for p in provs), source
    assert stats["articles"] >= 50


def test_real_content(default_kb):
    i509 = default_kb.get("icd10cm:I50.9")
    assert "Congestive heart failure NOS" in i509.content and i509.provenance["package"] == "simple-icd-10-cm"
    top = default_kb.search("Marfan syndrome", k=1, source="icd10cm")[0]
    assert top.doc_id == "icd10cm:Q87.4"
    hpo = default_kb.search("Marfan syndrome", k=3, source="hpo_diseases")
    assert any(h.title.startswith("Marfan syndrome (") for h in hpo)
    assert "Arachnodactyly" in default_kb.get("hpo:OMIM:154700#1").content
    qsofa = default_kb.search("qSOFA respiratory rate altered mentation systolic", k=3, source="guidelines")
    assert qsofa[0].doc_id.startswith("guideline:sepsis3_2016/") and qsofa[0].provenance["doi"]
    epi = default_kb.search("epinephrine anaphylaxis intramuscular dose", k=3, source="drugs")
    assert epi[0].doc_id == "drug:epinephrine" and "0.5 mg" in default_kb.get("drug:epinephrine").content
    assert default_kb.article("Chest Pain Differential Diagnosis").text.startswith("# Chest Pain")


def test_build_is_idempotent_and_fast(default_kb):
    from kb_service.build_default import build

    t = time.perf_counter()
    summary = build()
    assert summary["status"] == "up to date" and summary["passages"] == default_kb.n_passages
    assert time.perf_counter() - t < 10


def test_default_path_is_under_data_dir():
    from envs.core.paths import data_dir

    assert default_kb_path() == data_dir() / "kb"
