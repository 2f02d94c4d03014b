"""A safety violation and the bioethical principle it offends: what the safety checks report.

Kept apart from `types.py` (whose weight and breakdown models are built from the dimension
registry) so the safety checks can import it without importing the registry.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

Principle = Literal["nonmaleficence", "beneficence", "autonomy", "justice"]


class Violation(BaseModel):
    """One safety violation found in an episode.

    `turn` is the `TurnRecord.index` of the action that caused it, or None for an omission
    judged over the whole episode (an emergency never escalated, no follow-up plan).
    """

    model_config = ConfigDict(extra="forbid")
    pattern_id: str
    severity: int = Field(ge=1, le=5)
    category: str
    principle: Principle
    description: str
    turn: int | None = None
    evidence: str = ""
