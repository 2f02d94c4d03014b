"""ICD-10-CM: parse the CMS tabular XML shipped in simple-icd-10-cm (build) and look codes up (runtime).

Build: :func:`parse_tabular` walks chapters -> sections (blocks such as "E08-E13") -> categories ->
subcodes and returns one record per item with its description, parent, kind, whether it is billable
(a leaf code with no 7th-character extension required), inclusion terms and Excludes1 notes.

Runtime: :class:`ICD10Index` loads that JSON once per process; `get` returns a code with its
hierarchy, `search` ranks codes for free text with a word index (prefix matching), preferring
billable codes whose description or inclusion terms cover every query word.

Shared by domains: clinical_diagnosis builds the index (`icd10cm.json` in its build folder);
ehr_management reads that built file through `built_icd10_index("clinical_diagnosis")`, a built-data
dependency it declares in its `build.py` (`BUILD_REQUIRES`). Both get the same parsed index.
"""

from __future__ import annotations

import bisect
import json
import re
import xml.etree.ElementTree as ET
from collections import defaultdict
from functools import lru_cache
from pathlib import Path

from envs.core.db import DataFileError
from envs.core.frozen import frozen
from envs.core.paths import domain_build_dir

ICD10_INDEX_FILE = "icd10cm.json"

_WORD = re.compile(r"[a-z0-9]+")
_STOP = {"of", "the", "and", "or", "with", "without", "in", "to", "a", "an", "for", "by", "due", "not", "other",
         "unspecified", "on", "as", "at"}


def normalise_code(code: str) -> str:
    """'e11.21' / 'E1121' -> 'E11.21' (dot after the third character)."""
    raw = re.sub(r"[^A-Za-z0-9]", "", code).upper()
    return raw if len(raw) <= 3 else raw[:3] + "." + raw[3:]


def parse_tabular(xml_text: str) -> dict[str, dict]:
    """The tabular list -> {code: {desc, parent, kind, billable, chapter, block, includes, excludes1}}."""
    root = ET.fromstring(xml_text)
    items: dict[str, dict] = {}

    def notes(elem: ET.Element, tag: str) -> list[str]:
        return [n.text.strip() for sub in elem.findall(tag) for n in sub.findall("note") if n.text]

    def walk_diag(elem: ET.Element, parent: str, chapter: str, block: str, seventh: bool) -> None:
        code = elem.findtext("name").strip()
        children = elem.findall("diag")
        has_seventh = seventh or elem.find("sevenChrDef") is not None
        items[code] = {
            "desc": (elem.findtext("desc") or "").strip(), "parent": parent,
            "kind": "category" if len(code) == 3 else "subcode",
            "billable": not children and not has_seventh, "chapter": chapter, "block": block,
            "includes": notes(elem, "inclusionTerm"), "excludes1": notes(elem, "excludes1"),
        }
        for child in children:
            walk_diag(child, code, chapter, block, has_seventh)

    for chapter in root.findall("chapter"):
        number = chapter.findtext("name").strip()
        chap_id = f"Chapter {number}"
        items[chap_id] = {"desc": (chapter.findtext("desc") or "").strip(), "parent": None, "kind": "chapter",
                          "billable": False, "chapter": chap_id, "block": None, "includes": [], "excludes1": []}
        for section in chapter.findall("section"):
            block = section.get("id")
            items[block] = {"desc": (section.findtext("desc") or "").strip(), "parent": chap_id, "kind": "block",
                            "billable": False, "chapter": chap_id, "block": block, "includes": [], "excludes1": []}
            for diag in section.findall("diag"):
                walk_diag(diag, block, chap_id, block, False)
    return items


def _words(text: str) -> list[str]:
    return [w for w in _WORD.findall(text.lower()) if w not in _STOP]


class ICD10Index:
    """Read-only ICD-10-CM lookup over the compiled JSON."""

    def __init__(self, items: dict[str, dict]) -> None:
        self.items = items
        self.children: dict[str, list[str]] = defaultdict(list)
        for code, item in items.items():
            if item["parent"]:
                self.children[item["parent"]].append(code)
        self._index: dict[str, set[str]] | None = None
        self._tokens: list[str] = []
        self._hits_cache: dict[str, set[str]] = {}

    def _build_index(self) -> None:
        index: dict[str, set[str]] = defaultdict(set)
        for code, item in self.items.items():
            if item["kind"] in ("chapter", "block"):
                continue
            for text in [item["desc"], *item["includes"]]:
                for word in _words(text):
                    index[word].add(code)
        self._index = dict(index)
        self._tokens = sorted(index)

    def get(self, code: str) -> dict | None:
        """One code (any kind) with its hierarchy, children and notes; None when unknown."""
        key = code.strip()
        item = self.items.get(key) or self.items.get(normalise_code(key))
        if item is None:
            return None
        key = key if key in self.items else normalise_code(key)
        lineage = []
        parent = item["parent"]
        while parent:
            lineage.append({"code": parent, "description": self.items[parent]["desc"]})
            parent = self.items[parent]["parent"]
        return {"code": key, "description": item["desc"], "kind": item["kind"], "billable": item["billable"],
                "hierarchy": lineage[::-1],
                "children": [{"code": c, "description": self.items[c]["desc"], "billable": self.items[c]["billable"]}
                             for c in self.children.get(key, [])][:40],
                "inclusion_terms": item["includes"], "excludes1": item["excludes1"]}

    def _word_hits(self, word: str) -> set[str]:
        """Codes with a word equal to `word` (short words) or starting with it (longer words)."""
        cached = self._hits_cache.get(word)
        if cached is not None:
            return cached
        if len(word) <= 3:
            hits = set(self._index.get(word, ()))
        else:
            lo = bisect.bisect_left(self._tokens, word)
            hi = bisect.bisect_left(self._tokens, word + "\uffff")
            if hi - lo > 40:  # a very common prefix: match the whole word only
                hits = set(self._index.get(word, ()))
            else:
                hits = set().union(*(self._index[t] for t in self._tokens[lo:hi]))
        if len(self._hits_cache) > 20000:
            self._hits_cache.clear()
        self._hits_cache[word] = hits
        return hits

    def search(self, text: str, limit: int = 10, billable_only: bool = False) -> list[dict]:
        """Codes whose description or inclusion terms contain every query word (as a word prefix)."""
        if self._index is None:
            self._build_index()
        words = _words(text)
        if not words:
            return []
        hit_sets = sorted((self._word_hits(w) for w in dict.fromkeys(words)), key=len)
        found = set(hit_sets[0])
        for hits in hit_sets[1:]:
            found &= hits
            if not found:
                return []
        if not found:
            return []
        if billable_only:
            found = {c for c in found if self.items[c]["billable"]}
        query = " ".join(_WORD.findall(text.lower()))

        def rank(code: str) -> tuple:
            item = self.items[code]
            texts = [item["desc"], *item["includes"]]
            exact = any(" ".join(_WORD.findall(t.lower())) == query for t in texts)
            extra = min(len(_words(t)) for t in texts) - len(words)
            return (not exact, not item["billable"], extra, code)

        out = []
        for code in sorted(found, key=rank)[:limit]:
            item = self.items[code]
            matched_term = next((t for t in item["includes"] if all(w in _words(t) or any(x.startswith(w) for x in _words(t))
                                                                  for w in words)), None)
            row = {"code": code, "description": item["desc"], "billable": item["billable"]}
            if matched_term and matched_term != item["desc"]:
                row["matched_inclusion_term"] = matched_term
            out.append(row)
        return out

    def siblings(self, code: str) -> list[str]:
        parent = self.items[code]["parent"]
        return [c for c in self.children.get(parent, []) if c != code]


@lru_cache(maxsize=2)
def _index_at(path: Path) -> ICD10Index:
    index = ICD10Index(json.loads(path.read_text(encoding="utf-8")))
    index.search("warm up")  # builds the word index now, not inside the first agent call
    return frozen(index)


def built_icd10_index(domain: str) -> ICD10Index:
    """The ICD-10-CM index a domain's build wrote (`<build folder>/icd10cm.json`), parsed once per
    process (and kept out of the garbage collector's scans).

    Args:
        domain: The domain whose build folder holds the index, e.g. "clinical_diagnosis".
    """
    path = domain_build_dir(domain) / ICD10_INDEX_FILE
    if not path.exists():
        raise DataFileError(f"{path}: missing built knowledge file (run `hcgym data build {domain}`)")
    return _index_at(path)
