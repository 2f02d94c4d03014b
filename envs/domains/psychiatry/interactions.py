"""One interaction scale with the drug_interaction domain.

A pair of formulary drugs is graded, in this order:
1. by the drug_interaction domain, wherever it grades the pair: its US overlay's level where a rule of
   the overlay covers the pair (each rule names its label and section), else its ANSM thesaurus level.
   The build asks that domain through the shared drug reference (`envs.domains.drug_reference`, the
   same answer every other domain's reward gets for the pair) and stores the answers in the database
   (`PsychiatryDB.label_graded_pairs`), so a pair never gets two severities in two domains;
2. else by the authored rules of `interaction_rules.json` (PIR-xx, each naming the label section or
   guideline it follows), between the formulary groups of the two drugs.

The task generator, the `check_psych_med_interactions` tool and the reward's safety context all
grade through `pair_findings`, so a gold answer is exactly what the tool reports.
"""

from __future__ import annotations

import itertools
from typing import Iterable, Mapping

from envs.domains.psychiatry.data_model import InteractionRule, LabelGradedPair

SEVERITY_ORDER = {"none": 0, "minor": 1, "moderate": 2, "major": 3, "contraindicated": 4}
LABEL_SOURCE = "drug_interaction domain (US overlay rule where one covers the pair, else the ANSM thesaurus)"


def pair_key(a: str, b: str) -> tuple[str, str]:
    return (a, b) if a <= b else (b, a)


def label_graded_pairs(drugs: Iterable[str], reference) -> list[LabelGradedPair]:
    """The drug_interaction domain's severity for every pair of formulary drugs it grades.

    Args:
        drugs: Formulary drug names.
        reference: A `envs.domains.drug_reference.DrugReference` whose drug_interaction database is built.
    """
    names = sorted(set(drugs))
    for name in names:  # the first look-up loads the database; a drug it does not know has no pair graded there
        reference.components(name)
    if reference.status != "drug_interaction database loaded":
        raise RuntimeError(f"psychiatry build: the drug_interaction database is needed to grade the formulary's "
                           f"pairs on its scale ({reference.status}); build the drug_interaction domain first")
    out = []
    for a, b in itertools.combinations(names, 2):
        hit = reference.interaction(a, b)
        if hit is not None:
            rule, _, summary = hit[1].partition(": ")
            out.append(LabelGradedPair(a=a, b=b, severity=hit[0], rule=rule, summary=summary or hit[1]))
    return out


def rule_matches(rule: InteractionRule, groups_a: set[str], groups_b: set[str]) -> bool:
    if rule.group_b is None:
        return rule.group_a in groups_a and rule.group_a in groups_b
    return ((rule.group_a in groups_a and rule.group_b in groups_b)
            or (rule.group_a in groups_b and rule.group_b in groups_a))


def pair_findings(a: str, b: str, groups: Mapping[str, Iterable[str]], rules: Iterable[InteractionRule],
                  label_pairs: Mapping[tuple[str, str], LabelGradedPair]) -> list[dict]:
    """The findings for one pair of formulary drugs: the drug_interaction domain's grade where it has one
    (one finding), else every authored rule between their groups."""
    graded = label_pairs.get(pair_key(a, b))
    if graded is not None:
        return [{"drugs": [a, b], "rule": graded.rule, "name": f"{a} + {b}", "severity": graded.severity,
                 "mechanism": graded.summary, "management": graded.summary,
                 "reference": f"drug_interaction rule {graded.rule}", "source": LABEL_SOURCE}]
    ga, gb = set(groups[a]), set(groups[b])
    return [{"drugs": [a, b], "rule": r.id, "name": r.name, "severity": r.severity, "mechanism": r.mechanism,
             "management": r.management, "reference": r.reference, "source": "psychiatry interaction_rules.json"}
            for r in rules if rule_matches(r, ga, gb)]


def pair_severity(findings: list[dict]) -> str:
    return max((f["severity"] for f in findings), key=SEVERITY_ORDER.__getitem__, default="none")


def label_index(pairs: Iterable[LabelGradedPair]) -> dict[tuple[str, str], LabelGradedPair]:
    return {pair_key(p.a, p.b): p for p in pairs}
