"""Grading by meaning for exact-answer and short-answer tasks: when does an answer say the gold?

`match_by_meaning(answer, golds)` accepts an answer that states a gold answer (or one of the
task's `answer_aliases`) in other words, and never one that negates it:

1. **Canonical form** of both texts (`canonical`): NFKC, lower case, spelling variants
   ("pre-eclampsia", "caesarean"), abbreviations expanded ("FNA" -> "fine needle aspiration",
   "C-section", "US", "CT"; table `ABBREVIATIONS`), guideline phrasing mapped to one wording
   (`GUIDELINE_EQUIVALENTS`, each group naming the guideline it follows: "severe preeclampsia" =
   "preeclampsia with severe features", ACOG Practice Bulletin 222), number words, Roman numerals
   after "category"/"class"/"grade"/"stage", dates ("May 11, 2026" = "2026-05-11"), and
   **quantities**: a number with a unit becomes one token in a base unit ("1 g" = "1000 mg",
   "12 months" = "1 year"), an **interval** one token ("6 to 12 months" = "6-12 months" =
   "between 6 and 12 months"), rates one wording ("units/h" = "units per hour").
2. **Vocabulary**: the gold's synonyms from real vocabularies when the data is built (lazily
   loaded, cached): drug generic names, brand names and synonyms (the drug_interaction domain's
   database, plus the reward's built-in brand table), HPO term names and EXACT synonyms
   (clinical_diagnosis `hpo.json`), ICD-10-CM codes in any formatting and a code description's
   inclusion terms (`icd10cm.json`). `register_vocabulary` adds more (tests, other domains).
3. **Match**: equal canonical forms, or every content token of the gold present in a short answer
   (at most max(8, 3 x gold) tokens) whose extra tokens add no number, no quantity, no severity or
   level qualifier ("moderately severe" is not "severe", "critical high" is not "high") and no hedge
   ("or", "versus", "/") the gold does not have.
4. **Negation**: an answer with a negation cue (no, not, without, never, none, ruled out, excluded,
   absent, negative for, unlikely, non-...) the gold does not have never passes ("Not a secondary
   pneumothorax", "preeclampsia without severe features" for "... with severe features"), and an
   answer without the gold's cue never passes a negative gold ("routine follow-up" for "no routine
   follow-up").

Pure functions; the only state is the cache of loaded vocabularies.
"""

from __future__ import annotations

import json
import re
import threading
import unicodedata
from functools import lru_cache
from typing import Callable, Iterable

# -- canonical form --------------------------------------------------------------------------------
# Spelling variants first (applied to lower-cased text with punctuation still in place).
_SPELLING: list[tuple[str, str]] = [
    (r"\bpre[\s\-]+eclamp", "preeclamp"), (r"\bcaesarean\b", "cesarean"), (r"\bcaesarian\b", "cesarean"),
    (r"\bhaem", "hem"), (r"\boedema\b", "edema"), (r"\bfoetal\b", "fetal"), (r"\bfoetus\b", "fetus"),
    (r"\bfollow[\s\-]+up\b", "followup"), (r"\bfollowup\b", "followup"),
    (r"\bfine[\s\-]+needle\b", "fine needle"), (r"\bti[\s\-]?rads\b", "tirads"), (r"\bx[\s\-]ray\b", "xray"),
    (r"\bunfavourable\b", "unfavorable"), (r"\bfavourable\b", "favorable"),
    (r"\bcritically\s+(high|low)\b", r"critical \1"),
    (r"\bicd[\s\-]?10(?:[\s\-]?cm)?\b", "icd10"),                       # ICD-10-CM, ICD-10, icd10
    (r"\b12[\s\-]*leads?\s+(ecg|ekg|electrocardiogram)\b", r"\1"),       # a standard ECG has 12 leads
]

#: Abbreviations expanded to the words guidelines use (whole words, case-insensitive).
ABBREVIATIONS: dict[str, str] = {
    "fna": "fine needle aspiration",            # ACR TI-RADS 2017
    "fnab": "fine needle aspiration",
    "c section": "cesarean section", "c/s": "cesarean section", "cs": "cesarean section",
    "cesarean delivery": "cesarean section",    # ACOG says "cesarean delivery"
    "us": "ultrasound", "usg": "ultrasound", "sonography": "ultrasound", "sonographic": "ultrasound",
    "ultrasonography": "ultrasound",
    "ct": "computed tomography", "cat scan": "computed tomography", "ldct": "low dose computed tomography",
    "pet ct": "pet computed tomography",
    "mri": "magnetic resonance imaging",
    "mgso4": "magnesium sulfate", "mag sulfate": "magnesium sulfate", "magnesium sulphate": "magnesium sulfate",
    "gdm": "gestational diabetes", "ghtn": "gestational hypertension", "htn": "hypertension",
    "copd": "chronic obstructive pulmonary disease", "cap": "community acquired pneumonia",
    "pe": "pulmonary embolism", "mi": "myocardial infarction", "ptx": "pneumothorax",
    "mdd": "major depressive disorder", "gad": "generalized anxiety disorder", "ptsd": "posttraumatic stress disorder",
    "scc": "squamous cell carcinoma",
    "ecg": "electrocardiogram", "ekg": "electrocardiogram", "cxr": "chest xray", "bp": "blood pressure",
    "iv": "intravenous", "im": "intramuscular", "adrenaline": "epinephrine", "noradrenaline": "norepinephrine",
    "paracetamol": "acetaminophen", "cpap": "continuous positive airway pressure",
    "emergent": "emergency", "stat": "emergency", "urgent cesarean": "emergency cesarean",
}

#: Phrasings that name the same thing, each group with the guideline that defines it.
GUIDELINE_EQUIVALENTS: list[tuple[tuple[str, ...], str]] = [
    (("preeclampsia with severe features", "severe preeclampsia", "severe features of preeclampsia"),
     "ACOG Practice Bulletin 222 (2020): 'preeclampsia with severe features' replaces 'severe preeclampsia'"),
    (("preeclampsia without severe features", "mild preeclampsia", "preeclampsia without features of severity"),
     "ACOG Practice Bulletin 222 (2020): 'preeclampsia without severe features' replaces 'mild preeclampsia'"),
    (("chronic hypertension with superimposed preeclampsia", "superimposed preeclampsia",
      "preeclampsia superimposed on chronic hypertension"),
     "ACOG Practice Bulletin 203 (2019) chronic hypertension in pregnancy"),
    (("hellp syndrome", "hellp"), "ACOG Practice Bulletin 222 (2020): HELLP syndrome"),
    (("gestational hypertension", "pregnancy induced hypertension"), "ACOG Practice Bulletin 222 (2020)"),
    (("emergency cesarean section", "emergency cesarean", "category 1 cesarean section", "crash cesarean section"),
     "NICE NG192 / RCOG urgency classification: category 1 = immediate threat to life of woman or fetus"),
    (("category 1", "category i", "normal fhr tracing", "normal tracing"), "NICHD 2008 three-tier FHR interpretation"),
    (("category 2", "category ii", "indeterminate fhr tracing", "indeterminate tracing"), "NICHD 2008 three-tier FHR interpretation"),
    (("category 3", "category iii", "abnormal fhr tracing", "abnormal tracing"), "NICHD 2008 three-tier FHR interpretation"),
    (("no routine followup", "no followup", "no further followup", "no imaging followup",
      "no routine imaging followup"),
     "Fleischner Society 2017: 'No routine follow-up' for solid nodules < 6 mm in low-risk patients"),
    (("no fine needle aspiration or followup", "no fine needle aspiration and no followup",
      "no fine needle aspiration and no followup needed", "no further evaluation"),
     "ACR TI-RADS 2017: TR1/TR2 'No FNA' (and no follow-up)"),
    (("ultrasound followup", "followup ultrasound", "surveillance ultrasound", "repeat ultrasound"),
     "ACR TI-RADS 2017: 'follow-up' = surveillance ultrasound"),
    (("fine needle aspiration", "fine needle aspiration biopsy", "ultrasound guided fine needle aspiration"),
     "ACR TI-RADS 2017: 'FNA'"),
    (("none", "no interaction", "no clinically significant interaction", "no significant interaction",
      "no known interaction", "no interaction of concern", "no relevant interaction"),
     "interaction severity scale: none"),
    (("secondary pneumothorax", "secondary spontaneous pneumothorax"), "BTS pleural disease guideline 2023"),
    (("primary pneumothorax", "primary spontaneous pneumothorax"), "BTS pleural disease guideline 2023"),
    (("community acquired pneumonia", "pneumonia acquired in the community"), "IDSA/ATS 2019 CAP guideline"),
]

_NUMBER_WORDS = {
    "zero": 0, "one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "seven": 7, "eight": 8,
    "nine": 9, "ten": 10, "eleven": 11, "twelve": 12, "eighteen": 18, "twenty": 20, "twenty four": 24,
    "thirty": 30,
}
_ROMAN = {"i": 1, "ii": 2, "iii": 3, "iv": 4, "v": 5, "vi": 6}
_MONTHS = {m: i + 1 for i, m in enumerate(
    "january february march april may june july august september october november december".split())}
_MONTHS.update({m[:3]: i for m, i in list(_MONTHS.items())})

# unit -> (dimension, factor to the base unit); durations in months where a month is meant
_UNITS: dict[str, tuple[str, float]] = {
    **{u: ("mass_mg", f) for u, f in (("mcg", 1e-3), ("ug", 1e-3), ("µg", 1e-3), ("microgram", 1e-3), ("micrograms", 1e-3),
                                      ("mg", 1.0), ("milligram", 1.0), ("milligrams", 1.0), ("g", 1e3), ("gram", 1e3),
                                      ("grams", 1e3), ("kg", 1e6))},
    **{u: ("volume_ml", f) for u, f in (("ml", 1.0), ("milliliter", 1.0), ("milliliters", 1.0), ("millilitre", 1.0),
                                        ("cc", 1.0), ("dl", 100.0), ("l", 1e3), ("liter", 1e3), ("litre", 1e3))},
    **{u: ("month", f) for u, f in (("month", 1.0), ("months", 1.0), ("mo", 1.0), ("mos", 1.0), ("year", 12.0),
                                    ("years", 12.0), ("yr", 12.0), ("yrs", 12.0))},
    **{u: ("week", 1.0) for u in ("week", "weeks", "wk", "wks")},
    **{u: ("day", 1.0) for u in ("day", "days", "d")},
    **{u: ("hour", 1.0) for u in ("hour", "hours", "hr", "hrs", "h")},
    **{u: ("minute", 1.0) for u in ("minute", "minutes", "min", "mins")},
    **{u: ("mm", 1.0) for u in ("mm", "millimeter", "millimeters", "millimetre")},
    **{u: ("mm", 10.0) for u in ("cm", "centimeter", "centimeters", "centimetre")},
    **{u: ("unit", 1.0) for u in ("unit", "units", "u", "iu")},
    **{u: ("percent", 1.0) for u in ("%", "percent")},
}
_NUM = r"\d+(?:\.\d+)?"
_UNIT_ALT = "|".join(sorted((re.escape(u) for u in _UNITS), key=len, reverse=True))
_RATE = re.compile(r"\s*(?:/|\bper\b|\ban\b|\ba\b)\s*(hour|hr|h|day|d|min|minute|kg)\b")
_INTERVAL = re.compile(
    rf"(\bbetween\s+)?(?<![a-z0-9.])({_NUM})\s*(?:({_UNIT_ALT})\b\.?)?\s*(-|\bto\b|\bthrough\b|\band\b)\s*({_NUM})\s*"
    rf"(?:({_UNIT_ALT})(?![a-z0-9]))?"
)
_QUANTITY = re.compile(rf"(?<![a-z0-9.])({_NUM})\s*({_UNIT_ALT})(?![a-z0-9])")
_ISO_DATE = re.compile(r"\b(\d{4})-(\d{1,2})-(\d{1,2})\b")
_MDY = re.compile(r"\b([a-z]{3,9})\.?\s+(\d{1,2})(?:st|nd|rd|th)?,?\s+(\d{4})\b")
_DMY = re.compile(r"\b(\d{1,2})(?:st|nd|rd|th)?\s+(?:of\s+)?([a-z]{3,9})\.?,?\s+(\d{4})\b")
_ROMAN_AFTER = re.compile(r"\b(category|class|grade|stage|type|tier|level)\s+(i{1,3}|iv|v|vi)\b")
_NON_ALNUM = re.compile(r"[^0-9a-z_.]+")
_ICD_CODE = re.compile(r"^[a-z]\d{2}\.[0-9a-z]{1,4}\.?$")


def _fmt(value: float) -> str:
    return f"{value:g}"


def _quantity_token(value: float, unit: str) -> str:
    dim, factor = _UNITS[unit]
    return f"q{_fmt(value * factor)}{dim}"


def _date(y: str, m: int | None, d: str) -> str | None:
    if not m or not (1 <= m <= 12) or not (1 <= int(d) <= 31):
        return None
    return f"date{int(y):04d}{m:02d}{int(d):02d}"


@lru_cache(maxsize=8192)
def canonical(text: str) -> str:
    """The canonical wording of a short answer (see the module docstring, step 1)."""
    s = unicodedata.normalize("NFKC", text).lower()
    s = s.replace("\u2013", "-").replace("\u2014", "-")
    s = _ISO_DATE.sub(lambda m: _date(m.group(1), int(m.group(2)), m.group(3)) or m.group(0), s)
    s = _MDY.sub(lambda m: _date(m.group(3), _MONTHS.get(m.group(1)), m.group(2)) or m.group(0), s)
    s = _DMY.sub(lambda m: _date(m.group(3), _MONTHS.get(m.group(2)), m.group(1)) or m.group(0), s)
    for pattern, repl in _SPELLING:
        s = re.sub(pattern, repl, s)
    for word, number in sorted(_NUMBER_WORDS.items(), key=lambda kv: -len(kv[0])):
        s = re.sub(rf"\b{word}\b", str(number), s)
    s = re.sub(r"\b(?:a|one)\s+year\b", "12 months", s)
    s = re.sub(r"\bhalf\s+a\s+year\b", "6 months", s)
    s = _ROMAN_AFTER.sub(lambda m: f"{m.group(1)} {_ROMAN[m.group(2)]}", s)
    s = _RATE.sub(lambda m: " per " + {"hr": "hour", "h": "hour", "d": "day", "min": "minute"}.get(m.group(1), m.group(1)), s)

    def interval(m: re.Match[str]) -> str:
        between, low, unit_low, sep, high, unit_high = m.groups()
        unit = unit_high or unit_low
        if sep == "and" and not between:
            return m.group(0)  # "3 and 6" without "between" is a list, not an interval
        if unit_low and unit_high and _UNITS[unit_low][0] != _UNITS[unit_high][0]:
            return m.group(0)  # "3 months to 2 cm": two quantities, not an interval
        if unit:
            dim, factor = _UNITS[unit]
            lo = float(low) * (_UNITS[unit_low][1] if unit_low else factor)
            return f" r{_fmt(lo)}to{_fmt(float(high) * factor)}{dim} "
        return f" r{low}to{high} "

    s = _INTERVAL.sub(interval, s)
    s = _QUANTITY.sub(lambda m: " " + _quantity_token(float(m.group(1)), m.group(2)) + " ", s)
    s = _NON_ALNUM.sub(" ", s.replace("/", " / "))
    # ICD-10-CM codes compare without their dot ("E11.10" = "E1110")
    s = " " + " ".join(w.strip(".").replace(".", "") if _ICD_CODE.match(w) else w.strip(".") for w in s.split()) + " "
    # ACR TI-RADS levels: "TI-RADS 5", "TI-RADS category TR5", "TR 5" -> "tr5"
    s = re.sub(r" tirads (?:category )?(?:tr ?)?([1-5]) ", r" tr\1 ", s)
    s = re.sub(r" tr ([1-5]) ", r" tr\1 ", s)
    for short, full in sorted(ABBREVIATIONS.items(), key=lambda kv: -len(kv[0])):
        key = " " + _NON_ALNUM.sub(" ", short).strip() + " "
        while key in s:
            s = s.replace(key, " " + full + " ")
    # every phrase of a group, longest first, becomes the group's marker, then the marker its head
    # (so a variant inside the head, "hellp" in "hellp syndrome", is not replaced twice)
    for phrase, marker in _GROUP_PHRASES:
        while phrase in s:
            s = s.replace(phrase, marker)
    for marker, head in _GROUP_HEADS.items():
        s = s.replace(marker, " " + head + " ")
    return " ".join(s.split())


def _plain(phrase: str) -> str:
    """A table phrase in the canonical alphabet (tables are written in canonical spelling)."""
    return " ".join(_NON_ALNUM.sub(" ", phrase.lower()).split())


_GROUP_HEADS = {f" zzgroup{i}zz ": _plain(group[0]) for i, (group, _) in enumerate(GUIDELINE_EQUIVALENTS)}
_GROUP_PHRASES = sorted(((f" {_plain(p)} ", f" zzgroup{i}zz ") for i, (group, _) in enumerate(GUIDELINE_EQUIVALENTS)
                         for p in group), key=lambda pm: -len(pm[0]))


# -- tokens, negation, qualifiers ------------------------------------------------------------------
#: Words that carry no meaning of their own in a short answer.
FILLER = frozenset(
    "a an the of at in on by is are be was it this that its for as to recommended recommend recommendation "
    "needed required necessary indicated advised suggested routine further final answer diagnosis likely "
    "most probable consistent patient patients plan management do perform obtain repeat identified detected "
    "found noted present seen".split()
) - {"with"}
NEGATION_CUES = frozenset("no not without never none neither nor non excluded exclude excludes absent negative "
                          "unlikely denies denied ruled rule against avoid avoided stop stopped discontinue "
                          "discontinued withhold withheld hold held cease".split())
#: Severity, level and scale words: an extra one changes the category ("moderately severe").
QUALIFIERS = frozenset(
    "mild mildly moderate moderately severe severely minimal minor major critical critically high low "
    "borderline possible probable likely unlikely early late partial complete total acute chronic "
    "primary secondary superimposed atypical risk".split()
)
_MAX_SHORT_ANSWER = 2_000
_PAREN = re.compile(r"\([^()]*\)")
_HEDGES = frozenset({"or", "either", "versus", "vs", "/"})
_NUMBER_CONTEXT = frozenset({"score", "total", "value", "points", "result", "equals", "approximately", "about"})


def content(canon: str) -> list[str]:
    """Meaningful tokens of a canonical text."""
    return [t for t in canon.split() if t not in FILLER]


def _is_number(token: str) -> bool:
    return bool(re.fullmatch(r"\d+(?:\.\d+)?|q\d\S*|r\d\S*to\S+|date\d+", token))


def negation_conflict(answer_canon: str, gold_canon: str) -> bool:
    """True when the answer has a negation cue the gold lacks, or lacks one the gold has."""
    a = {t for t in answer_canon.split() if t in NEGATION_CUES}
    g = {t for t in gold_canon.split() if t in NEGATION_CUES}
    return bool(a - g) or bool(g - a)


# -- vocabularies ----------------------------------------------------------------------------------
SynonymGroups = list[list[str]]
_vocab_lock = threading.Lock()
_loaders: dict[str, Callable[[], SynonymGroups]] = {}
_loaded: dict[str, dict[str, tuple[str, ...]]] = {}
_status: dict[str, str] = {}


def _key(phrase: str) -> str:
    """The cheap lookup key of a vocabulary phrase (vocabularies hold ~10^5 phrases: only the
    gold's own group is put in canonical form, when it is graded)."""
    return " ".join(_NON_ALNUM.sub(" ", unicodedata.normalize("NFKC", phrase).lower().replace(".", " ")).split())


def _index(groups: Iterable[Iterable[str]]) -> dict[str, tuple[str, ...]]:
    """lookup key -> the phrases of its group (synonyms of one concept); a phrase in several
    groups keeps all of them."""
    out: dict[str, tuple[str, ...]] = {}
    for group in groups:
        phrases = tuple(dict.fromkeys(g for g in group if g and isinstance(g, str)))
        if len(phrases) < 2:
            continue
        for p in phrases:
            k = _key(p)
            if k:
                out[k] = out[k] + phrases if k in out else phrases
    return out


def register_vocabulary(name: str, loader: Callable[[], SynonymGroups]) -> None:
    """Add a vocabulary: `loader()` returns groups of synonymous phrases; called once, lazily."""
    with _vocab_lock:
        _loaders[name] = loader
        _loaded.pop(name, None)
        _status.pop(name, None)
    _gold_equivalents.cache_clear()


def unregister_vocabulary(name: str) -> None:
    with _vocab_lock:
        _loaders.pop(name, None)
        _loaded.pop(name, None)
        _status.pop(name, None)
    _gold_equivalents.cache_clear()


def vocabulary_status() -> dict[str, str]:
    """Per vocabulary: 'loaded N phrases', 'not loaded', or why it is unavailable."""
    return {name: _status.get(name, "not loaded") for name in _loaders}


def _vocabulary(name: str) -> dict[str, tuple[str, ...]]:
    if name not in _loaded:
        with _vocab_lock:
            if name not in _loaded:
                try:
                    index = _index(_loaders[name]())
                    _status[name] = f"loaded {len(index)} phrases"
                except (OSError, ValueError, KeyError, TypeError) as exc:  # not built here: grade without it
                    index = {}
                    _status[name] = f"unavailable ({type(exc).__name__}: {str(exc)[:120]})"
                _loaded[name] = index
    return _loaded[name]


def hpo_groups(data: dict) -> SynonymGroups:
    """HPO `hpo.json` (the clinical_diagnosis build: terms with name and EXACT synonyms)."""
    return [[t.get("name", ""), *t.get("synonyms", [])] for t in data.get("terms", {}).values()]


def drug_groups(db: dict) -> SynonymGroups:
    """The drug_interaction `db.json` drugs: generic name, id, brand names and synonyms."""
    return [[d.get("name", ""), d.get("id", ""), *d.get("brand_names", []), *d.get("synonyms", [])]
            for d in db.get("drugs", {}).values()]


def icd10_groups(items: dict) -> SynonymGroups:
    """ICD-10-CM `icd10cm.json`: a billable code in its written forms ("E11.10", "E1110"), and a
    code's description with its inclusion terms."""
    groups: SynonymGroups = []
    for code, item in items.items():
        if not item.get("billable"):
            continue
        groups.append([code, code.replace(".", "")])
        if item.get("includes"):
            groups.append([item.get("desc", ""), *item["includes"]])
    return groups


def builtin_drug_groups() -> SynonymGroups:
    from envs.rewards.safety_lexicon import BRANDS

    by_generic: dict[str, list[str]] = {}
    for brand, generic in BRANDS.items():
        by_generic.setdefault(generic, [generic]).append(brand)
    return list(by_generic.values())


def _built_json(domain: str, name: str) -> dict:
    from envs.core.paths import domain_build_dir

    path = domain_build_dir(domain) / name
    with open(path, encoding="utf-8") as handle:
        return json.load(handle)


def _install_defaults() -> None:
    _loaders.setdefault("drugs_builtin", builtin_drug_groups)
    _loaders.setdefault("drugs", lambda: drug_groups(_built_json("drug_interaction", "db.json")))
    _loaders.setdefault("hpo", lambda: hpo_groups(_built_json("clinical_diagnosis", "hpo.json")))
    _loaders.setdefault("icd10cm", lambda: icd10_groups(_built_json("clinical_diagnosis", "icd10cm.json")))


_install_defaults()


@lru_cache(maxsize=4096)
def _gold_equivalents(gold: str) -> frozenset[str]:
    """The gold and its synonyms from every vocabulary (canonical forms)."""
    out = {canonical(gold)}
    key = _key(gold)
    for name in list(_loaders):
        out.update(canonical(p) for p in _vocabulary(name).get(key, ()))
    return frozenset(o for o in out if o)


def gold_equivalents(gold: str) -> frozenset[str]:
    return _gold_equivalents(gold)


# -- the match -------------------------------------------------------------------------------------
def _stated(answer_canon: str, gold_canon: str) -> bool:
    g = content(gold_canon)
    a = content(answer_canon)
    if not g or not a:
        return False
    if len(a) > max(8, 3 * len(g)):
        return False
    a_set, g_set = set(a), set(g)
    if not g_set <= a_set:
        return False
    # the gold's words must appear in the answer in the gold's order (a phrase, gaps allowed)
    position = 0
    for token in g:
        try:
            position = a.index(token, position) + 1
        except ValueError:
            return False
    extra = a_set - g_set
    if extra & _HEDGES or extra & QUALIFIERS:
        return False
    # a bare number ("1") is not stated by a value on another scale ("ESI 1" for a HEART score)
    if all(_is_number(t) for t in g) and extra - _NUMBER_CONTEXT:
        return False
    # a gold with a number or quantity ("CT at 3 months") is contradicted by any other one in the
    # answer ("CT at 3 months, then 12 months"); a gold without one allows a dose ("metformin 500 mg")
    if any(_is_number(t) for t in g) and any(_is_number(t) for t in extra):
        return False
    return True


def match_by_meaning(answer: str, golds: list[str]) -> tuple[str, str] | None:
    """(matched gold, how) when the answer states a gold by meaning; None otherwise.

    `how` is "equivalent" (same canonical form), "synonym" (a vocabulary synonym of the gold,
    stated) or "stated" (the gold's words, in order, in a short answer that adds nothing that
    changes its meaning)."""
    if len(answer) > _MAX_SHORT_ANSWER:  # no short answer: cannot equal or state a gold (and is not cached)
        return None
    answer_canon = canonical(answer)
    if not answer_canon:
        return None
    # a parenthesised gloss in the gold is optional: "secondary pneumothorax (COPD)"
    golds = list(dict.fromkeys([*golds, *(_PAREN.sub(" ", g).strip() for g in golds if "(" in g)]))
    for gold in golds:
        gold_canon = canonical(gold)
        if not gold_canon:
            continue
        if negation_conflict(answer_canon, gold_canon):
            continue
        if answer_canon == gold_canon:
            return gold, "equivalent"
        if _stated(answer_canon, gold_canon):
            return gold, "stated"
    for gold in golds:
        gold_canon = canonical(gold)
        for synonym in sorted(gold_equivalents(gold) - {gold_canon}):
            if negation_conflict(answer_canon, synonym):
                continue
            if answer_canon == synonym or _stated(answer_canon, synonym):
                return gold, "synonym"
    return None


def answer_negates(answer: str, gold: str) -> bool:
    """True when the answer states the gold's words under a negation the gold lacks."""
    answer_canon, gold_canon = canonical(answer), canonical(gold)
    g = [t for t in content(gold_canon) if t not in NEGATION_CUES]
    return bool(g) and set(g) <= set(content(answer_canon)) and negation_conflict(answer_canon, gold_canon)


__all__ = ["ABBREVIATIONS", "GUIDELINE_EQUIVALENTS", "canonical", "match_by_meaning", "answer_negates",
           "gold_equivalents", "register_vocabulary", "unregister_vocabulary", "vocabulary_status",
           "hpo_groups", "drug_groups", "icd10_groups", "negation_conflict"]
