"""Pregnancy conclusions from US labels, shared by every tool that reports a drug's pregnancy data:
the drug-interaction domain (`check_pregnancy_safety`, its reward context and task oracles), the
medical_qa tools (`lookup_drug`, `compare_treatments`) and the knowledge base's drug monographs.
A shared domain library like `drug_reference`: it imports no domain.

Letter categories (A, B, C, D, X) come from the drugdose package, undated; the 2015 Pregnancy and
Lactation Labeling Rule replaced them with a risk summary in section 8.1. Where a label (or the FDA
communication that changed it) states a different conclusion, `PREGNANCY_LABEL_RULES` answers with
that wording, its section, and a letter only where the FDA assigned one, with its date.
"""

from __future__ import annotations

from dataclasses import dataclass

# drugdose's letters are package data: undated, and the 2015 Pregnancy and Lactation Labeling Rule
# (PLLR) replaces letters in US labels with a risk summary (section 8.1), so a drugdose letter is
# reported as such, never as the current label's wording.
PACKAGE_LETTER_BASIS = ("drugdose 0.1.2 package data: FDA letter category, undated and not checked against the "
                        "current label (the 2015 PLLR replaces letters with the section 8.1 risk summary)")


@dataclass(frozen=True)
class PregnancyLabelRule:
    """A drug's pregnancy conclusion as its US label (or the FDA communication that changed it) states
    it: the risk statement, the label section it comes from, and a letter only where the FDA assigned
    one that the label carries, with its date."""
    recommendation: str
    statement: str
    section: str
    letter: str | None = None
    letter_date: str | None = None
    contraindicated_for: str | None = None  # the indication a section-4 contraindication is limited to


# Drug-specific pregnancy rules from the labels' section 8.1 (PLLR risk summary), section 4 or the
# FDA safety communication that changed the label; they replace drugdose's letter for these drugs.
PREGNANCY_LABEL_RULES: dict[str, PregnancyLabelRule] = {
    "magnesium sulfate": PregnancyLabelRule(
        "limit_continuous_use_to_5_7_days",
        "continuous administration beyond 5 to 7 days (off-label tocolysis) can cause fetal hypocalcaemia and bone "
        "abnormalities (osteopenia, fractures); approved to prevent and control seizures in pre-eclampsia/eclampsia",
        "Magnesium Sulfate Injection USP 50% label: WARNINGS (fetal harm) and pregnancy subsection, as relabelled "
        "by FDA Drug Safety Communication of 30 May 2013 (category A -> D)",
        letter="D", letter_date="2013-05-30"),
    "glucose": PregnancyLabelRule(
        "not_expected_to_cause_harm",
        "appropriate administration is not expected to cause adverse developmental outcomes; maternal "
        "hyperglycaemia from glucose infusion at delivery has been associated with neonatal hypoglycaemia",
        "Dextrose Injection 50% USPI (Pfizer/Hospira) 8.1 Pregnancy, Risk Summary (PLLR format, no letter)"),
    "calcium gluconate": PregnancyLabelRule(
        "risk_not_established",
        "limited data are insufficient to inform a drug-associated risk; untreated maternal hypocalcaemia carries "
        "risks to mother and fetus (miscarriage, premature labour, neonatal hyperparathyroidism)",
        "Calcium Gluconate Injection USPI (Fresenius Kabi, NDA 208418) 8.1 Pregnancy, Risk Summary and Clinical "
        "Considerations (PLLR format, no letter)"),
    "valproic acid": PregnancyLabelRule(
        "contraindicated_for_migraine_prophylaxis",
        "contraindicated in pregnant women for the prophylaxis of migraine headaches; for epilepsy and bipolar "
        "disorder the boxed warning on fetal risk (neural tube defects, other major malformations, decreased IQ) "
        "applies: use in pregnancy only when other medications have failed or are otherwise unacceptable",
        "Depakote/valproate USPI 4 CONTRAINDICATIONS (pregnant women, migraine prophylaxis), boxed warning Fetal "
        "Risk, 5.2-5.4 and 8.1 Pregnancy; FDA Drug Safety Communication of 6 May 2013",
        contraindicated_for="migraine prophylaxis"),
}


# Other names the tools and packages use for the drugs of the table (the keys are the drug-interaction
# formulary's ids).
ALIASES: dict[str, str] = {
    "magnesium sulphate": "magnesium sulfate", "mgso4": "magnesium sulfate", "dextrose": "glucose",
    "d50": "glucose", "d50w": "glucose", "valproate": "valproic acid", "valproate sodium": "valproic acid",
    "divalproex": "valproic acid", "divalproex sodium": "valproic acid", "depakote": "valproic acid",
    "depakene": "valproic acid", "depacon": "valproic acid",
}


def label_rule(name: str) -> PregnancyLabelRule | None:
    """The label rule for a drug name (formulary id, alias or brand; case-insensitive), else None."""
    key = " ".join(str(name).lower().replace("_", " ").split())
    return PREGNANCY_LABEL_RULES.get(ALIASES.get(key, key))


def rule_report(rule: PregnancyLabelRule) -> dict:
    """What a tool reports from a label rule: its conclusion, section and basis (a letter only with its date)."""
    out = {"fda_category": rule.letter, "fda_category_date": rule.letter_date,
           "recommendation": rule.recommendation, "risk_summary": rule.statement, "label_section": rule.section,
           "basis": "US label" + (f"; letter {rule.letter} assigned {rule.letter_date}" if rule.letter
                                  else "; no letter category (PLLR risk summary)")}
    if rule.contraindicated_for:
        out["contraindicated_for"] = rule.contraindicated_for
    return out


def pregnancy_report(name: str, package_letter: str | None) -> dict:
    """What a tool reports for a drug's pregnancy data: the label rule's conclusion where the table has
    one (its letter only with the date the FDA assigned it), else the package letter named as undated
    package data, else nothing known."""
    rule = label_rule(name)
    if rule is not None:
        return rule_report(rule)
    if package_letter:
        return {"fda_category": package_letter, "fda_category_date": None, "label_section": None,
                "basis": PACKAGE_LETTER_BASIS}
    return {"fda_category": None, "fda_category_date": None, "label_section": None,
            "basis": "no pregnancy data in the sources"}


def pregnancy_sentence(name: str, package_letter: str | None) -> str | None:
    """One sentence for a text passage (the knowledge base's monographs), or None without data."""
    rule = label_rule(name)
    if rule is not None:
        letter = (f" FDA category {rule.letter} (assigned {rule.letter_date})." if rule.letter
                  else " No letter category (PLLR risk summary).")
        limited = f" Contraindicated in pregnancy for {rule.contraindicated_for} only." if rule.contraindicated_for else ""
        return f"Pregnancy (US label, {rule.section}): {rule.statement}.{limited}{letter}"
    if package_letter:
        return (f"Pregnancy category {package_letter} (drugdose package data: undated letter, not checked against the "
                f"current label).")
    return None
