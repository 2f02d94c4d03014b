"""French -> English for the ANSM thesaurus: text folding, severity labels, substance names.

Everything here is deterministic. Substance names go through, in order: the committed authored
table of irregular names (`substance_names.json`), the name itself, the French
"acide X-ique" -> "X-ic acid" pattern, the French "cation (anion de)" salt pattern, and the
French suffix rule (a final mute "e" is dropped: warfarine -> warfarin, naproxene -> naproxen,
isoniazide -> isoniazid). A candidate is accepted only if it is a name (generic, brand or synonym)
in the drug-named-entity-recognition vocabulary; the English name is that entry's canonical name.
Names that no rule maps are reported as unmatched by the build, never guessed.
"""

from __future__ import annotations

import itertools
import re
import unicodedata
from dataclasses import dataclass

# ANSM severity labels -> (English label, normalised level used by the reward).
SEVERITY_LABELS: dict[str, tuple[str, str]] = {
    "contre-indication": ("contraindicated", "contraindicated"),
    "association deconseillee": ("not recommended", "major"),
    "precaution d'emploi": ("precaution for use", "moderate"),
    "a prendre en compte": ("take into account", "minor"),
    # One entry of the 2020 thesaurus words the lowest level this way.
    "il convient de prendre en compte": ("take into account", "minor"),
}
SEVERITY_RANK: dict[str, int] = {"none": 0, "minor": 1, "moderate": 2, "major": 3, "contraindicated": 4}
ENGLISH_TO_LEVEL: dict[str, str] = {english: level for english, level in SEVERITY_LABELS.values()}
LEVEL_TO_ENGLISH: dict[str, str] = {level: english for english, level in SEVERITY_LABELS.values()}

# French words inside salt names ("sodium (chlorure de)") -> English.
_SALT_WORDS: dict[str, str] = {
    "chlorure": "chloride", "bicarbonate": "bicarbonate", "citrate": "citrate", "docusate": "docusate",
    "nitroprussiate": "nitroprusside", "picosulfate": "picosulfate", "oxybate": "oxybate",
    "hydroxyde": "hydroxide", "trisilicate": "trisilicate", "ricinoleate": "ricinoleate",
    "citrate diacide": "citrate",
}
# Salt / form qualifiers dropped to reach the active moiety ("dalteparine sodique" -> dalteparin).
_QUALIFIERS = {"sodique", "calcique", "potassique", "trometamol", "tert-butylamine", "betadex", "recombinante",
               "biosynthetique", "humaine", "zinc", "cristalline", "isophane", "biphasique", "de", "potassium"}


def fold(text: str) -> str:
    """Lowercase, strip accents and ligatures, normalise quotes, hyphen breaks and spaces."""
    text = text.replace("\u0153", "oe").replace("\u0152", "oe").replace("\u00e6", "ae").replace("\u00c6", "ae")
    text = text.replace("\u2019", "'").replace("\u2018", "'")
    text = "".join(c for c in unicodedata.normalize("NFKD", text) if not unicodedata.combining(c)).lower()
    text = re.sub(r"-\s+", "-", text)
    return re.sub(r"\s+", " ", text).strip()


def translate_severity(label_fr: str) -> tuple[str, str]:
    """ANSM level label -> (English label, normalised level); unknown labels raise ValueError."""
    key = fold(label_fr)
    if key not in SEVERITY_LABELS:
        raise ValueError(f"unknown ANSM severity label {label_fr!r} (known: {sorted(SEVERITY_LABELS)})")
    return SEVERITY_LABELS[key]


def _drop_final_e(word: str) -> str:
    return word[:-1] if len(word) > 4 and word.endswith("e") and not word.endswith("ee") else word


def candidate_names(name_fr: str) -> list[tuple[str, str]]:
    """Ordered (candidate English name, rule) pairs for a folded French substance name."""
    name = fold(name_fr)
    out: list[tuple[str, str]] = [(name, "identical")]
    acid = re.fullmatch(r"acide ([a-z]+)ique(?: (.+))?", name)
    if acid:
        out.append((f"{acid.group(1)}ic acid", "rule:acide-ique"))
    salt = re.fullmatch(r"([a-z]+) \((.+?) de\)", name)
    if salt and salt.group(2) in _SALT_WORDS:
        out.append((f"{salt.group(1)} {_SALT_WORDS[salt.group(2)]}", "rule:salt"))
    words = name.split(" ")
    variants = [sorted({w, _drop_final_e(w)}, key=lambda v: (v == w, v)) for w in words]
    for combo in itertools.islice(itertools.product(*variants), 16):
        out.append((" ".join(combo), "rule:final-e"))
    core = [w for w in re.sub(r"\(.*?\)", " ", name).split() if w not in _QUALIFIERS]
    if core and core != words and not salt:  # "sodium (ricinoleate de)" is not sodium
        stripped = " ".join(core)
        out.append((stripped, "rule:strip-salt"))
        out.append((" ".join(_drop_final_e(w) for w in core), "rule:strip-salt+final-e"))
    seen: set[str] = set()
    unique = []
    for cand, rule in out:
        if cand not in seen:
            seen.add(cand)
            unique.append((cand, rule))
    return unique


@dataclass(frozen=True)
class NameMatch:
    """How one French substance name was mapped to an English vocabulary drug."""

    name_fr: str
    drug_id: str | None
    matched_variant: str | None
    rule: str


def translate_substance(name_fr: str, vocabulary: dict[str, str], authored: dict[str, str]) -> NameMatch:
    """Map a French INN to the canonical English name of the vocabulary (variant -> canonical).

    Args:
        name_fr: The French substance name as printed in the thesaurus.
        vocabulary: Folded English name variant -> canonical English drug name.
        authored: Folded French name -> English name (the committed irregular-name table).
    """
    key = fold(name_fr)
    if key in authored:
        english = fold(authored[key])
        if english in vocabulary:
            return NameMatch(name_fr, vocabulary[english], english, "authored")
        return NameMatch(name_fr, None, None, "authored-unmatched")
    for cand, rule in candidate_names(key):
        if cand in vocabulary:
            return NameMatch(name_fr, vocabulary[cand], cand, rule)
    return NameMatch(name_fr, None, None, "unmatched")
