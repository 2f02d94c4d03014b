"""The medical-QA database: the question being answered and the evidence the agent consulted.

The large reference tables (ICD-10-CM, HPO, drug classes, guidelines) are read-only and shared by
every episode (`knowledge.py`); the per-episode database is small so that a reset stays fast and
its content hash is cheap: the current question (set on reset from the task) and an evidence log
that the agent's `record_evidence` calls append to.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from envs.core.db import DB


class QAQuestion(BaseModel):
    """The multiple-choice question of the episode, as the agent was shown it."""

    model_config = ConfigDict(extra="forbid")
    question_id: str
    stem: str
    options: dict[str, str] = Field(default_factory=dict)
    category: str | None = None


class EvidenceNote(BaseModel):
    """One piece of evidence the agent recorded for an option."""

    model_config = ConfigDict(extra="forbid")
    option: str
    finding: str
    source: str
    supports: bool


class MedicalQADB(DB):
    """Per-episode state; the reference versions record what the tools read."""

    question: QAQuestion | None = None
    evidence: list[EvidenceNote] = Field(default_factory=list)
    reference_versions: dict[str, str] = Field(default_factory=dict)
