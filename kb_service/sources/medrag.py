"""MedRAG's corpora as they are distributed: ``corpus/<name>/chunk/*.jsonl``.

MedRAG (github.com/Teddy-XiongGZ/MedRAG, and its Hugging Face datasets ``MedRAG/<name>``) ships
each corpus as a folder of chunk files, one JSON object per line, written by its
``src/data/<name>.py`` scripts with ``'\\n'.join(json.dumps(...))`` (ASCII-escaped, no newline
after the last line):

    {"id": "PMID:1234", "title": "...", "content": "...", "contents": "<title>. <content>"}

``id`` is ``PMID:<pmid>`` (pubmed, files ``pubmed24n0001.jsonl`` ...), ``<article>_<n>``
(statpearls, one file per article, titles ``Article -- Section -- Subsection``),
``<book>_<n>`` (textbooks, one file per book, the title is the book) or ``<wiki id>_<n>``
(wikipedia, ``wiki20220301en000.jsonl`` ...). ``contents`` is MedRAG's title + content
concatenation (what its BM25 indexes); a line without ``content`` falls back to it.

Mapping to passages: ``doc_id`` is MedRAG's id unchanged (so results cite what MedRAG and the
benchmarks built on it cite), ``source`` the corpus name, ``title`` and ``content`` as given,
``category`` the book (textbooks) or article (statpearls, the title before the first " -- ")
and empty otherwise, ``dataset_name`` ``MedRAG/<corpus>``. Each passage carries its provenance
(`MedRAGPassage.provenance`: corpus, file, line, id); the KB stores it per file (corpus,
file, dataset), the id being the doc_id (one provenance row per passage would make the KB's
provenance table as large as the corpus).

Bad rows (invalid JSON, not an object, no id, no text) are skipped and reported with the file
and the line (the build's report lists the first five per corpus and counts all), or raise
`MedRAGFormatError` naming them with ``strict=True``.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Iterator

from pydantic import BaseModel, ConfigDict

class MedRAGFormatError(ValueError):
    """A MedRAG chunk file or folder is not in MedRAG's layout (names the file and line)."""


class MedRAGPassage(BaseModel):
    """One line of a chunk file with where it came from."""

    model_config = ConfigDict(frozen=True)

    corpus: str
    file: str  # relative to the corpus root: "<corpus>/chunk/<name>.jsonl"
    line: int  # 1-based line number in the file
    id: str
    title: str
    content: str

    @property
    def provenance(self) -> dict[str, str]:
        return {"corpus": self.corpus, "file": self.file, "line": str(self.line), "id": self.id}

    def passage(self) -> dict:
        """The KB passage dict (kb_service/README.md schema), with per-file provenance."""
        if self.corpus == "textbooks":
            category = self.title
        elif self.corpus == "statpearls":
            category = self.title.split(" -- ")[0]
        else:
            category = ""
        return {"doc_id": self.id, "source": self.corpus, "title": self.title, "content": self.content,
                "category": category, "dataset_name": f"MedRAG/{self.corpus}",
                "provenance": {"dataset": f"MedRAG/{self.corpus}", "corpus": self.corpus, "file": self.file}}


class BadRow(BaseModel):
    """A line that is not a passage: where, and why."""

    corpus: str
    file: str
    line: int
    reason: str

    def __str__(self) -> str:
        return f"{self.file} line {self.line}: {self.reason}"


def find_corpora(root: str | Path) -> dict[str, list[Path]]:
    """{corpus name: its chunk files, sorted} under `root`.

    `root` is MedRAG's ``corpus/`` folder (holding ``<name>/chunk/``), one corpus folder
    (``<name>/`` holding ``chunk/``), or a ``chunk/`` folder itself (the corpus is its parent's
    name). Only ``*.jsonl`` files are chunk files, as in MedRAG's own readers.

    Raises:
        MedRAGFormatError: `root` does not exist or holds no chunk folder.
    """
    root = Path(root)
    if not root.is_dir():
        raise MedRAGFormatError(f"MedRAG corpus folder {root} does not exist (or is not a folder)")
    if root.name == "chunk":
        dirs = {root.resolve().parent.name: root}
    elif (root / "chunk").is_dir():
        dirs = {root.resolve().name: root / "chunk"}
    else:
        dirs = {d.name: d / "chunk" for d in sorted(root.iterdir()) if (d / "chunk").is_dir()}
    if not dirs:
        raise MedRAGFormatError(
            f"{root} holds no MedRAG corpus: expected <corpus>/chunk/*.jsonl under it (e.g. "
            f"{root}/pubmed/chunk/pubmed24n0001.jsonl), a <corpus>/ folder with chunk/, or a chunk/ folder")
    out = {}
    for name, d in dirs.items():
        files = sorted(p for p in d.iterdir() if p.is_file() and p.name.endswith(".jsonl"))
        if not files:
            raise MedRAGFormatError(f"{d} holds no .jsonl chunk files")
        out[name] = files
    return out


def _parse(raw: bytes, corpus: str, rel: str, lineno: int) -> MedRAGPassage | BadRow:
    def bad(reason: str) -> BadRow:
        return BadRow(corpus=corpus, file=rel, line=lineno, reason=reason)

    try:
        rec = json.loads(raw.decode("utf-8").strip())
    except UnicodeDecodeError as exc:
        return bad(f"not UTF-8 (byte {exc.start})")
    except json.JSONDecodeError as exc:
        return bad(f"invalid JSON, column {exc.colno}: {exc.msg}")
    if not isinstance(rec, dict):
        return bad(f"not a JSON object ({type(rec).__name__})")
    doc_id = rec.get("id")
    if not isinstance(doc_id, str) or not doc_id.strip():
        return bad("missing or empty 'id'")
    title = rec.get("title", "")
    if not isinstance(title, str):
        return bad(f"{doc_id}: 'title' is {type(title).__name__}, not a string")
    content = rec.get("content")
    if content is None:  # fall back to MedRAG's concatenation, minus the title it starts with
        content = rec.get("contents")
        if isinstance(content, str) and title.strip():
            for prefix in (title.strip() + ". ", title.strip() + " "):
                if content.startswith(prefix):
                    content = content[len(prefix):]
                    break
    if not isinstance(content, str) or not content.strip():
        return bad(f"{doc_id}: no text ('content' and 'contents' missing or empty)")
    try:
        (doc_id + title + content).encode("utf-8")
    except UnicodeEncodeError:
        return bad(f"{doc_id}: holds a lone surrogate (e.g. a \\ud800 escape)")
    return MedRAGPassage(corpus=corpus, file=rel, line=lineno, id=doc_id.strip(), title=title.strip(), content=content)


def read_corpus(files: list[Path], corpus: str, strict: bool = False, skip: int = 0
                ) -> Iterator[MedRAGPassage | BadRow]:
    """Every non-blank line of the corpus's files, in order, as a `MedRAGPassage` or a `BadRow`,
    after the first `skip` lines (bad rows count as lines). Files are read in binary and decoded
    line by line: a bad byte sequence is one bad row, not a failed file."""
    for path in files:
        rel = f"{corpus}/chunk/{path.name}"
        with open(path, "rb") as fh:
            for lineno, raw in enumerate(fh, 1):
                if not raw.strip():
                    continue
                if skip:  # resuming: lines already ingested are counted, not parsed
                    skip -= 1
                    continue
                item = _parse(raw, corpus, rel, lineno)
                if strict and isinstance(item, BadRow):
                    raise MedRAGFormatError(f"MedRAG {corpus}: {item}")
                yield item


def medrag_inputs(root: str | Path, corpora: list[str] | None = None, strict: bool = False) -> list:
    """Build inputs (`kb_service.ingest.Input`), one per corpus, for `build_kb`.

    Resumable like any input: the build records how many lines of the corpus it consumed, and
    the fingerprint (every chunk file's name, size and mtime) restarts it if a file changed.

    Raises:
        MedRAGFormatError: the layout is wrong, a named corpus is absent, or (strict) a bad row.
    """
    from kb_service.ingest import Input, _Bad

    found = find_corpora(root)
    if corpora:
        missing = [c for c in corpora if c not in found]
        if missing:
            raise MedRAGFormatError(f"{root}: no corpus {', '.join(missing)} (found: {', '.join(found)})")
        found = {c: found[c] for c in corpora}
    inputs = []
    for corpus, files in found.items():
        h = hashlib.sha256()
        for f in files:
            st = f.stat()
            h.update(f"{f.name}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())

        def open_corpus(skip: int, files=files, corpus=corpus) -> Iterator:
            for item in read_corpus(files, corpus, strict=strict, skip=skip):
                # A bad row goes to the build's report (counted, first five listed) with file and line.
                yield _Bad(str(item)) if isinstance(item, BadRow) else item.passage()

        inputs.append(Input(f"medrag:{Path(root).resolve()}:{corpus}", f"medrag:{h.hexdigest()}", open_corpus))
    return inputs
