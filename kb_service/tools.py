"""Knowledge tools for agents in every domain, backed by the knowledge base.

`KnowledgeTools(backend)` takes anything with the `KnowledgeBase` interface (`search`, `get`,
`stats`, `article`): the in-process `KnowledgeBase` (the embedded default) or a
`kb_service.service.KBServiceClient` talking to Ray `KBActor` replicas. With no backend it
uses the Ray service named by ``$HCGYM_KB_SERVICE`` when set, else opens the default KB in
process (once per process).

Every result carries the passage ``doc_id`` (and the DOI when the source has one) so the reward
can tell cited evidence from fabricated evidence. If the knowledge base is not built the tools
raise `ToolError` with the build command -- never an empty list that looks like "no hits".
"""

from __future__ import annotations

import os
import threading
from typing import Any

from envs.core.tools import Toolkit, ToolError, ToolType, is_tool

MAX_RESULTS = 20
LITERATURE_MARKERS = ("pubmed", "pmc", "medcpt", "literature", "abstract", "paper")
WIKI_MARKERS = ("wiki", "encyclop", "statpearls", "textbook")
GUIDELINE_MARKERS = ("guideline", "differential")
REFERENCE_FALLBACK = ("hpo_diseases", "hpo_terms", "drugs", "icd10cm")

_DEFAULT_LOCK = threading.Lock()


def default_backend():
    """The backend tools use when none is given: `$HCGYM_KB_SERVICE` (Ray) or the in-process default KB."""
    name = os.environ.get("HCGYM_KB_SERVICE")
    with _DEFAULT_LOCK:
        if name:
            from kb_service.service import connect

            return connect(name)
        from kb_service.kb import open_shared

        return open_shared()


class KnowledgeTools(Toolkit):
    """Medical knowledge search tools (BM25 over the knowledge base)."""

    def __init__(self, backend: Any = None) -> None:
        super().__init__(db=None)
        self._backend = backend
        self._sources: list[str] | None = None

    # ------------------------------------------------------------------------------ plumbing
    @property
    def backend(self) -> Any:
        if self._backend is None:
            try:
                self._backend = default_backend()
            except Exception as exc:  # KBNotBuiltError / KBCorruptError / Ray lookup failures
                raise ToolError(f"knowledge base unavailable: {exc}") from None
        return self._backend

    def available_sources(self) -> list[str]:
        if self._sources is None:
            try:
                self._sources = sorted(self.backend.stats()["sources"])
            except ToolError:
                raise
            except Exception as exc:
                raise ToolError(f"knowledge base unavailable: {exc}") from None
        return self._sources

    def _pick(self, markers: tuple[str, ...], fallback: tuple[str, ...] = ()) -> tuple[list[str], bool]:
        present = self.available_sources()
        hit = [s for s in present if any(m in s.lower() for m in markers)]
        if hit:
            return hit, True
        return [s for s in fallback if s in present], False

    def _search(self, query: str, k: int, sources: list[str] | None, excerpt_chars: int = 0) -> list[dict]:
        k = max(1, min(int(k), MAX_RESULTS))
        try:
            hits = self.backend.search(query, k=k, source=sources)
        except ToolError:
            raise
        except ValueError as exc:  # unknown source
            raise ToolError(str(exc)) from None
        except Exception as exc:
            raise ToolError(f"knowledge search failed: {type(exc).__name__}: {exc}") from None
        out = []
        for p in hits:
            item = p.brief()
            doi = (p.provenance or {}).get("doi")
            if doi:
                item["doi"] = doi
            if excerpt_chars:
                full = self.backend.get(p.doc_id)
                item["text"] = (full.content or "")[:excerpt_chars]
            out.append(item)
        return out

    @staticmethod
    def _result(query: str, sources: list[str] | None, results: list[dict], note: str = "") -> dict:
        out: dict[str, Any] = {"query": query, "sources_searched": sources or "all", "results": results}
        if not results:
            note = (note + " " if note else "") + "No passage matched this query; try other or fewer words."
        if note:
            out["note"] = note
        return out

    # ------------------------------------------------------------------------------ tools
    @is_tool(ToolType.READ)
    def search(self, query: str, source: str | None = None, k: int = 5) -> dict:
        """Search the whole medical knowledge base (BM25); cite results by their doc_id.

        Args:
            query: Words to search for. Plain words are OR-ed and ranked by BM25; "quoted phrases",
                AND, OR, NOT, +required and -excluded words are supported.
            source: Optional source to restrict to (e.g. icd10cm, hpo_diseases, drugs, guidelines).
            k: Number of results (1-20).
        """
        sources = [source] if source else None
        if source and source not in self.available_sources():
            raise ToolError(f"unknown source {source!r}; available: {', '.join(self.available_sources())}")
        return self._result(query, sources, self._search(query, k, sources))

    @is_tool(ToolType.READ)
    def search_pubmed(self, query: str, k: int = 5) -> dict:
        """Search the biomedical literature sources of the knowledge base; returns doc ids, never invented PMIDs.

        Args:
            query: Words to search for (BM25; phrases and AND/OR/NOT supported).
            k: Number of results (1-20).
        """
        sources, found = self._pick(LITERATURE_MARKERS, ("guidelines",))
        note = "" if found else (
            "No PubMed/PMC data is installed in this knowledge base; searched the evidence-based guideline "
            "summaries instead (cite their doc_id or DOI, not a PMID).")
        if not sources:
            raise ToolError("no literature or guideline source in this knowledge base; use `search` instead")
        return self._result(query, sources, self._search(query, k, sources), note)

    @is_tool(ToolType.READ)
    def retrieve_evidence(self, query: str, k: int = 3) -> dict:
        """Retrieve the best evidence passages for a clinical question, with their text, from all sources.

        Args:
            query: The clinical question or claim to find evidence for.
            k: Number of passages (1-20).
        """
        return self._result(query, None, self._search(query, k, None, excerpt_chars=1200))

    @is_tool(ToolType.READ)
    def search_medical_wiki(self, query: str, k: int = 5) -> dict:
        """Search encyclopedic medical articles (disease, phenotype, drug and code references); browse hits with browse_article.

        Args:
            query: Words to search for (BM25; phrases and AND/OR/NOT supported).
            k: Number of results (1-20).
        """
        sources, found = self._pick(WIKI_MARKERS, REFERENCE_FALLBACK)
        note = "" if found else (
            "No Wikipedia-style articles are installed; searched the reference sources: " + ", ".join(sources) + ".")
        if not sources:
            raise ToolError("no encyclopedic source in this knowledge base; use `search` instead")
        return self._result(query, sources, self._search(query, k, sources), note)

    @is_tool(ToolType.READ)
    def search_guidelines(self, query: str, k: int = 5) -> dict:
        """Search clinical practice guideline summaries and differential-diagnosis references.

        Args:
            query: Words to search for (BM25; phrases and AND/OR/NOT supported).
            k: Number of results (1-20).
        """
        sources, _ = self._pick(GUIDELINE_MARKERS)
        if not sources:
            raise ToolError("this knowledge base has no guideline source; use `search` instead")
        return self._result(query, sources, self._search(query, k, sources))

    @is_tool(ToolType.READ)
    def browse_article(self, title: str, offset: int = 0, max_chars: int = 6000) -> dict:
        """Read a full article (guideline, differential, or imported Wikipedia page) by its title or URL.

        Args:
            title: The article title (a search hit's title, with or without its "§ section" part) or URL.
            offset: Character offset to continue reading a long article from.
            max_chars: Maximum characters to return (500-20000).
        """
        try:
            art = self.backend.article(title)
        except ToolError:
            raise
        except KeyError as exc:
            raise ToolError(str(exc.args[0]) if exc.args else "article not found") from None
        except Exception as exc:
            raise ToolError(f"article lookup failed: {type(exc).__name__}: {exc}") from None
        max_chars = max(500, min(int(max_chars), 20000))
        offset = max(0, int(offset))
        text = art.text[offset : offset + max_chars]
        out = {"title": art.title, "url": art.url, "offset": offset, "text": text, "length": len(art.text)}
        if offset + max_chars < len(art.text):
            out["next_offset"] = offset + max_chars
        return out

    @is_tool(ToolType.READ)
    def get_passage(self, doc_id: str) -> dict:
        """Read the full text of one knowledge-base passage by its doc_id.

        Args:
            doc_id: A doc_id returned by a search tool.
        """
        try:
            p = self.backend.get(doc_id)
        except ToolError:
            raise
        except KeyError as exc:
            raise ToolError(str(exc.args[0]) if exc.args else f"unknown doc_id {doc_id!r}") from None
        except Exception as exc:
            raise ToolError(f"passage lookup failed: {type(exc).__name__}: {exc}") from None
        out = {"doc_id": p.doc_id, "source": p.source, "title": p.title, "category": p.category,
               "dataset_name": p.dataset_name, "content": p.content}
        if p.provenance:
            out["provenance"] = p.provenance
        return out
