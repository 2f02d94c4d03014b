"""ICD-10-CM passages from the tabular XML shipped in simple-icd-10-cm.

One passage per item of the classification -- chapters, blocks, categories, subcategories,
codes, and the codes formed with a 7th character -- which is exactly the package's code list
(`expected_codes` checks it). Each passage carries the description, the place in the
hierarchy, whether the code is billable, and the instructional notes (inclusion terms,
includes, excludes1/excludes2, code first, use additional code, code also, 7th characters).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Iterator

from envs.data.registry import SOURCES, Archive

from kb_service.sources.common import provenance

VERSION = "1"
PACKAGE = SOURCES["simple-icd-10-cm"]

NOTE_KINDS = [
    ("inclusionTerm", "Inclusion terms"),
    ("includes", "Includes"),
    ("excludes1", "Excludes1 (not coded here; never used together)"),
    ("excludes2", "Excludes2 (not included here; may be coded together)"),
    ("codeFirst", "Code first"),
    ("useAdditionalCode", "Use additional code"),
    ("codeAlso", "Code also"),
    ("notes", "Notes"),
]


def _notes(elem: ET.Element) -> list[str]:
    parts = []
    for tag, label in NOTE_KINDS:
        notes = [" ".join((n.text or "").split()) for e in elem.findall(tag) for n in e.findall("note")]
        notes = [n for n in notes if n]
        if notes:
            parts.append(f"{label}: " + "; ".join(notes) + ".")
    return parts


def _xml(archive: Archive) -> ET.Element:
    return ET.fromstring(archive.read_bytes(archive.find_one("simple_icd_10_cm/data/icd10c-tabular-*.xml")))


def expected_codes(archive: Archive) -> set[str]:
    """The package's own list of every item (codes without dots, blocks, chapter numbers)."""
    member = archive.find_one("simple_icd_10_cm/data/code-list-*.txt")
    return {line.strip() for line in archive.read_text(member).splitlines() if line.strip()}


def _ext_code(code: str, char: str) -> str:
    raw = code.replace(".", "")
    raw = raw.ljust(6, "X") + char
    return raw[:3] + "." + raw[3:]


def passages(archives: dict[str, Archive]) -> Iterator[dict]:
    archive = archives[PACKAGE.name]
    root = _xml(archive)
    # A few 7th-character combinations are excluded by rules stated only in prose (e.g. S06 loss
    # of consciousness); the package's code list is the authority for which codes exist.
    allowed = expected_codes(archive)
    version = (root.findtext("version") or "").strip()
    dataset = f"ICD-10-CM Tabular List {version} (CMS/CDC)"
    prov = provenance(PACKAGE, edition=f"ICD-10-CM {version}")

    def rec(doc_code: str, title: str, content: list[str], category: str) -> dict:
        return {"doc_id": f"icd10cm:{doc_code}", "source": "icd10cm", "title": title,
                "content": " ".join(content), "category": category, "dataset_name": dataset, "provenance": prov}

    for chapter in root.iter("chapter"):
        ch_num = (chapter.findtext("name") or "").strip()
        ch_desc = " ".join((chapter.findtext("desc") or "").split())
        ch_label = f"Chapter {ch_num}: {ch_desc}"
        yield rec(f"chapter-{ch_num}", f"ICD-10-CM {ch_label}",
                  [f"ICD-10-CM {ch_label}."] + _notes(chapter)
                  + ["Blocks: " + "; ".join(f"{s.get('id')} {' '.join((s.findtext('desc') or '').split())}"
                                            for s in chapter.findall("section")) + "."],
                  ch_label)
        for section in chapter.findall("section"):
            sec_id = section.get("id") or ""
            sec_desc = " ".join((section.findtext("desc") or "").split())
            cats = [f"{d.findtext('name')} {d.findtext('desc')}" for d in section.findall("diag")]
            yield rec(f"block-{sec_id}", f"ICD-10-CM block {sec_id}: {sec_desc}",
                      [f"ICD-10-CM block {sec_id}: {sec_desc}. {ch_label}."] + _notes(section)
                      + (["Categories: " + "; ".join(cats) + "."] if cats else []),
                      ch_label)
            for diag in section.findall("diag"):
                yield from _walk(diag, [], None, ch_label, f"{sec_id} {sec_desc}", rec, allowed)


def _walk(diag: ET.Element, ancestors: list[tuple[str, str]], seven: tuple[dict, str] | None, ch_label: str,
          block: str, rec, allowed: set[str]) -> Iterator[dict]:
    code = (diag.findtext("name") or "").strip()
    desc = " ".join((diag.findtext("desc") or "").split())
    children = diag.findall("diag")
    own_def = diag.find("sevenChrDef")
    if own_def is not None:
        chars = {e.get("char"): " ".join((e.text or "").split()) for e in own_def.findall("extension")}
        note = " ".join(" ".join((n.text or "").split()) for n in diag.findall("sevenChrNote/note"))
        seven = (chars, note)
    extended = seven is not None and not children
    billable = not children and not extended
    kind = "billable code" if billable else ("code requiring a 7th character" if extended else "non-billable category")
    hierarchy = " > ".join(f"{c} {d}" for c, d in ancestors)
    content = [f"ICD-10-CM {code}: {desc}. {kind.capitalize()}.", f"{ch_label}. Block {block}."]
    if hierarchy:
        content.append(f"Hierarchy: {hierarchy} > {code} {desc}.")
    content += _notes(diag)
    if children:
        content.append("Subcodes: " + "; ".join(f"{c.findtext('name')} {c.findtext('desc')}" for c in children) + ".")
    if own_def is not None and seven is not None:
        content.append("7th characters: " + "; ".join(f"{k} {v}" for k, v in seven[0].items()) + "."
                       + (f" {seven[1]}" if seven[1] else ""))
    yield rec(code, f"{code} {desc}", content, ch_label)
    path = ancestors + [(code, desc)]
    for child in children:
        yield from _walk(child, path, seven, ch_label, block, rec, allowed)
    if extended:
        chars, note = seven
        for char, meaning in chars.items():
            ext = _ext_code(code, char)
            if ext.replace(".", "") not in allowed:
                continue
            ext_desc = f"{desc}, {meaning}"
            yield rec(ext, f"{ext} {ext_desc}",
                      [f"ICD-10-CM {ext}: {ext_desc}. Billable code.", f"{ch_label}. Block {block}.",
                       f"Hierarchy: {' > '.join(f'{c} {d}' for c, d in path)} > {ext}.",
                       f"Formed from {code} with 7th character {char} ({meaning})." + (f" {note}" if note else "")],
                      ch_label)
