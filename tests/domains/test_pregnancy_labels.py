"""One source of pregnancy truth: the drug-interaction tool, the medical_qa tools and the knowledge
base's drug monographs report the US label's conclusion (`envs/domains/pregnancy_labels.py`), not
drugdose's undated letters (magnesium sulfate "A": category D since the FDA's 2013 relabelling)."""

from __future__ import annotations

import pytest

from envs.domains import pregnancy_labels as P


def test_label_rule_answers_by_any_name_and_dates_its_letter():
    for name in ("magnesium sulfate", "Magnesium Sulfate", "magnesium_sulfate", "MgSO4", "magnesium sulphate"):
        out = P.pregnancy_report(name, "A")
        assert out["fda_category"] == "D" and out["fda_category_date"] == "2013-05-30", name
        assert "5 to 7 days" in out["risk_summary"] and "2013" in out["label_section"]
    for name in ("glucose", "dextrose", "calcium gluconate"):
        out = P.pregnancy_report(name, "A")
        assert out["fda_category"] is None and "8.1" in out["label_section"], name
    for name in ("valproate", "Depakote", "divalproex sodium"):
        out = P.pregnancy_report(name, None)
        assert out["contraindicated_for"] == "migraine prophylaxis" and "4 CONTRAINDICATIONS" in out["label_section"]
    # a drug without a label rule keeps its package letter, named as undated package data
    out = P.pregnancy_report("midazolam", "D")
    assert out == {"fda_category": "D", "fda_category_date": None, "label_section": None, "basis": P.PACKAGE_LETTER_BASIS}
    assert P.pregnancy_sentence("magnesium sulfate", "A").startswith("Pregnancy (US label, Magnesium Sulfate Injection")
    assert "FDA category D (assigned 2013-05-30)" in P.pregnancy_sentence("magnesium sulfate", "A")
    assert "Pregnancy category A" not in P.pregnancy_sentence("magnesium sulfate", "A")
    assert "undated" in P.pregnancy_sentence("midazolam", "D") and P.pregnancy_sentence("x", None) is None


def test_the_drug_interaction_tool_reads_the_same_table():
    from envs.domains.drug_interaction import logic as L

    assert L.PREGNANCY_LABEL_RULES is P.PREGNANCY_LABEL_RULES


def test_knowledge_base_monograph_carries_the_label_sentence():
    from envs.data.registry import open_package
    from kb_service.sources import drugs

    try:
        archives = {src.name: open_package(src, offline=True) for src in (drugs.NER, drugs.ANSM, drugs.DOSE, drugs.OPENMED)}
    except Exception as exc:  # downloaded by `hcgym data build`
        pytest.skip(f"drug packages unavailable: {type(exc).__name__}: {exc}")
    try:
        passage = next(p for p in drugs.monograph_passages(archives) if p["doc_id"] == "drug:magnesium sulfate")
    finally:
        for arch in archives.values():
            arch.close()
    # drugdose names it "magnesium_sulfate": its dose data reach the vocabulary's "magnesium sulfate"
    assert "Doses by route:" in passage["content"]
    assert "Pregnancy (US label, Magnesium Sulfate Injection" in passage["content"]
    assert "FDA category D (assigned 2013-05-30)" in passage["content"]
    assert "Pregnancy category A" not in passage["content"]
