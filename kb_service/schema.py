"""The passage schema (the paper's six columns) and the search-result model.

A passage is what the knowledge base stores and ranks: ``doc_id, source, title, content,
category, dataset_name`` exactly as the paper's FTS5 table, plus optional provenance
(package, version, licence) that the default build fills for every record.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, field_validator


class IngestError(ValueError):
    """An input cannot be read at all (wrong format, missing table or columns), or the index built from
    it is inconsistent. Here, beside the passage schema, so the build's worker processes
    (`kb_service.parallel_build`) raise it without importing `kb_service.ingest`, which starts them."""

PASSAGE_FIELDS = ("doc_id", "source", "title", "content", "category", "dataset_name")


class PassageRecord(BaseModel):
    """One passage as ingested (a JSONL line, a Parquet row, a reference FTS5 row)."""

    model_config = ConfigDict(extra="ignore")

    doc_id: str = Field(min_length=1, max_length=512)
    source: str = Field(min_length=1, max_length=128)
    title: str = ""
    content: str = Field(min_length=1)
    category: str = ""
    dataset_name: str = ""
    provenance: dict[str, str] | None = None

    @field_validator("doc_id", "source", mode="before")
    @classmethod
    def _strip(cls, value: Any) -> Any:
        return value.strip() if isinstance(value, str) else value

    @field_validator("title", "category", "dataset_name", mode="before")
    @classmethod
    def _none_to_empty(cls, value: Any) -> Any:
        return "" if value is None else value


@dataclass(slots=True)
class Passage:
    """A passage returned by `KnowledgeBase.search` (snippet) or `KnowledgeBase.get` (content).

    A plain slotted dataclass rather than a pydantic model: a search builds ten of these per
    call and pydantic construction cost ~9 us each. `model_dump` keeps the pydantic-style API.
    """

    doc_id: str
    source: str
    title: str
    snippet: str = ""
    score: float = 0.0
    category: str = ""
    dataset_name: str = ""
    content: str | None = None
    provenance: dict[str, str] | None = None

    def model_dump(self, exclude_none: bool = False) -> dict[str, Any]:
        out = {f: getattr(self, f) for f in _PASSAGE_FIELDS}
        if exclude_none:
            out = {k: v for k, v in out.items() if v is not None}
        return out

    def brief(self) -> dict[str, Any]:
        """A compact dict for agent-facing tool results."""
        out = {
            "doc_id": self.doc_id,
            "source": self.source,
            "title": self.title,
            "snippet": self.snippet,
            "score": round(self.score, 4),
        }
        if self.category:
            out["category"] = self.category
        if self.dataset_name:
            out["dataset_name"] = self.dataset_name
        return out


_PASSAGE_FIELDS = tuple(f.name for f in fields(Passage))
