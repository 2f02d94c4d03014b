"""Guideline summaries and differential diagnoses shipped in open-medicine.

* `guideline_passages`: the 145 markdown sections of 43 guidelines, split at their headings
  into passages of about 60-250 words; each carries the guideline's DOI in its provenance.
  `guideline_articles` assembles each guideline into one article for `browse_article`.
* `differential_passages`: for each of the 14 presenting complaints, an overview passage and
  one passage per candidate diagnosis (likelihood, key features, red flags, tests).
"""

from __future__ import annotations

import json
import re
from typing import Iterator

from envs.data.registry import SOURCES, Archive

from kb_service.sources.common import provenance

VERSION = "1"
PACKAGE = SOURCES["open-medicine"]
MAX_WORDS = 220
MIN_WORDS = 60
_HEADING = re.compile(r"^(#{1,6})\s+(.*)$")


def _registry(arch: Archive) -> list[dict]:
    return json.loads(arch.read_text(arch.find_one("open_medicine/guidelines/registry.json")))


def _section_text(arch: Archive, gid: str, section: str) -> str:
    return arch.read_text(arch.find_one(f"open_medicine/guidelines/content/{gid}/{section}.md"))


def split_markdown(text: str) -> Iterator[tuple[str, str]]:
    """(heading path, body) chunks of at most ~MAX_WORDS words, split at headings and paragraphs.

    Small consecutive sections under the same top heading are merged up to MIN_WORDS.
    """
    heads: list[str] = []
    blocks: list[tuple[str, str]] = []  # (heading path, paragraph)
    para: list[str] = []

    def end_para() -> None:
        if para:
            blocks.append((" › ".join(h for h in heads if h), "\n".join(para)))
            para.clear()

    for line in text.splitlines():
        m = _HEADING.match(line)
        if m:
            end_para()
            level = len(m.group(1))
            heads[:] = heads[: level - 1] + [""] * max(0, level - 1 - len(heads)) + [m.group(2).strip()]
            continue
        if not line.strip():
            end_para()
            continue
        para.append(line.rstrip())
    end_para()

    chunk: list[str] = []
    chunk_head = ""
    words = 0
    for head, body in blocks:
        n = len(body.split())
        new_section = head != chunk_head
        if chunk and (words + n > MAX_WORDS or (new_section and words >= MIN_WORDS)):
            yield chunk_head, "\n".join(chunk)
            chunk, words = [], 0
        if not chunk:
            chunk_head = head
        elif new_section:
            chunk.append(f"{head.split(' › ')[-1]}:")
        chunk.append(body)
        words += n
    if chunk:
        yield chunk_head, "\n".join(chunk)


def guideline_passages(archives: dict[str, Archive]) -> Iterator[dict]:
    arch = archives[PACKAGE.name]
    for g in _registry(arch):
        gid, title = g["id"], g["title"]
        prov = provenance(PACKAGE, doi=g.get("doi", ""), guideline=title)
        for section in g["sections"]:
            text = _section_text(arch, gid, section)
            for n, (head, body) in enumerate(split_markdown(text), 1):
                where = head.split(" › ", 1)[1] if " › " in head else section.replace("_", " ")
                content = f"{title} ({g.get('organization', '')}, {g.get('year', '')}). {where}.\n{body}"
                yield {"doc_id": f"guideline:{gid}/{section}#{n}", "source": "guidelines",
                       "title": f"{title} § {where}", "content": content, "category": gid,
                       "dataset_name": "open-medicine guideline summaries", "provenance": prov}


def guideline_articles(archives: dict[str, Archive]) -> Iterator[dict]:
    arch = archives[PACKAGE.name]
    for g in _registry(arch):
        parts = [f"# {g['title']}", f"{g.get('organization', '')} {g.get('year', '')}. DOI: {g.get('doi', '')}.",
                 "Topics: " + ", ".join(g.get("topics", [])) + "."]
        parts += [_section_text(arch, g["id"], s) for s in g["sections"]]
        yield {"title": g["title"], "url": f"https://doi.org/{g['doi']}" if g.get("doi") else f"guideline:{g['id']}",
               "text": "\n\n".join(parts)}


def _differentials(arch: Archive) -> list[dict]:
    return [json.loads(arch.read_text(m)) for m in sorted(arch.find("open_medicine/mcp/differentials/data/*.json"))]


def _label(value: str | None) -> str:
    return (value or "").replace("_", " ")


def differential_passages(archives: dict[str, Archive]) -> Iterator[dict]:
    arch = archives[PACKAGE.name]
    for d in _differentials(arch):
        did, title = d["differential_id"], d["title"]
        prov = provenance(PACKAGE, doi=d.get("source_doi", ""), reference=d.get("source_description", ""))
        names = [x["name"] for x in d.get("diagnoses", [])]
        overview = [f"{title}. {d.get('description', '')}", "Diagnoses considered: " + "; ".join(names) + "."]
        also = d.get("also_consider") or []
        if also:
            overview.append("Also consider: " + "; ".join(f"{a['name']} ({a.get('rationale', '')})" for a in also))
        if d.get("clinical_reasoning_prompt"):
            overview.append(str(d["clinical_reasoning_prompt"]))
        if d.get("source_description"):
            overview.append(f"Source: {d['source_description']}")
        yield {"doc_id": f"differential:{did}", "source": "differentials", "title": title,
               "content": "\n".join(overview), "category": did, "dataset_name": "open-medicine differentials",
               "provenance": prov}
        for dx in d.get("diagnoses", []):
            body = [f"{dx['name']} in the differential diagnosis of {title.replace(' Differential Diagnosis', '').lower()}"
                    f" (likelihood: {_label(dx.get('likelihood'))})."]
            for key, label in (("key_features", "Key features"), ("red_flags", "Red flags"),
                               ("recommended_tests", "Recommended tests")):
                if dx.get(key):
                    body.append(f"{label}: " + "; ".join(dx[key]) + ".")
            for key, label in (("age_modifier", "Age"), ("sex_modifier", "Sex")):
                if dx.get(key):
                    body.append(f"{label}: {_label(dx[key])}.")
            if dx.get("related_guidelines"):
                body.append("Related guidelines: " + ", ".join(dx["related_guidelines"]) + ".")
            slug = re.sub(r"[^a-z0-9]+", "-", dx["name"].lower()).strip("-")
            yield {"doc_id": f"differential:{did}/{slug}", "source": "differentials",
                   "title": f"{title} § {dx['name']}", "content": " ".join(body), "category": did,
                   "dataset_name": "open-medicine differentials", "provenance": prov}


def differential_articles(archives: dict[str, Archive]) -> Iterator[dict]:
    arch = archives[PACKAGE.name]
    for d in _differentials(arch):
        parts = [f"# {d['title']}", d.get("description", "")]
        for dx in d.get("diagnoses", []):
            parts.append(f"## {dx['name']} ({_label(dx.get('likelihood'))})")
            for key in ("key_features", "red_flags", "recommended_tests"):
                if dx.get(key):
                    parts.append(f"{key.replace('_', ' ').capitalize()}: " + "; ".join(dx[key]))
        for a in d.get("also_consider") or []:
            parts.append(f"Also consider {a['name']}: {a.get('rationale', '')}")
        if d.get("source_description"):
            parts.append(f"Source: {d['source_description']} DOI: {d.get('source_doi', '')}")
        yield {"title": d["title"], "url": f"https://doi.org/{d['source_doi']}#{d['differential_id']}"
               if d.get("source_doi") else f"differential:{d['differential_id']}", "text": "\n\n".join(parts)}


def renal_dose_passages(archives: dict[str, Archive]) -> Iterator[dict]:
    """Renal dose adjustment tables (23 drugs), used by the drug monograph source."""
    arch = archives[PACKAGE.name]
    data = json.loads(arch.read_text(arch.find_one("open_medicine/mcp/calculators/data/renal_dose_adjustments.json")))
    for key, d in data.items():
        yield key, d
