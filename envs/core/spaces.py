"""A text space that contains any string (Unicode, newlines, JSON) and pickles small.

gymnasium's `Text` checks every character against its charset. A charset of all Unicode costs
hundreds of MB and a pickle of tens of MB (docs/benchmarks.md, "Figures behind code defaults"),
unusable across Ray; printable ASCII rejects newlines
and most clinical text. So we keep a small printable charset for *sampling* and override
`contains` to accept any `str` within the length bounds.
"""

from __future__ import annotations

import string
from typing import Any

from gymnasium.spaces import Text


class AnyText(Text):
    """Any `str` with `min_length <= len <= max_length`."""

    def __init__(self, max_length: int, *, min_length: int = 0, seed: int | None = None) -> None:
        super().__init__(max_length, min_length=min_length, charset=string.printable, seed=seed)

    def contains(self, x: Any) -> bool:
        return isinstance(x, str) and self.min_length <= len(x) <= self.max_length

    def __repr__(self) -> str:
        return f"AnyText({self.min_length}, {self.max_length})"

    def __eq__(self, other: Any) -> bool:
        return isinstance(other, AnyText) and other.min_length == self.min_length and other.max_length == self.max_length
