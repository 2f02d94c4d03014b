"""The cosine length-controlled reward of TT-OPD (paper Eq. 4).

    R_cos(c, L) = R_max - 1/2 (R_max - R_min)(1 - cos(pi L / L_max))   if correct
                = -1/2 |R_min| (1 - cos(pi L / L_max))                  if incorrect
                = R_penalty                                             if truncated

L counts the tokens of all assistant turns of the episode (`assistant_tokens`); L is clipped
to [0, L_max]. Correct answers earn R_max when short and R_min at L_max; wrong answers lose
more the longer they are, down to -|R_min| at L_max.
"""

from __future__ import annotations

import math
from typing import Any, Callable

from envs.core.trajectory import Trajectory


def cosine_length_reward(correct: bool, length: int | float, max_length: int | float, truncated: bool = False,
                         r_max: float = 1.1, r_min: float = 0.7, r_penalty: float = -0.5) -> float:
    """Paper Eq. 4.

    Args:
        correct: Whether the episode's answer is correct (`RewardBreakdown.is_correct`).
        length: L, tokens of all assistant turns.
        max_length: L_max (> 0).
        truncated: The episode hit the token or turn limit: returns `r_penalty`.

    Example:
        >>> cosine_length_reward(True, 0, 100), cosine_length_reward(True, 100, 100)
        (1.1, 0.7)
        >>> round(cosine_length_reward(False, 50, 100), 6), cosine_length_reward(True, 10, 100, truncated=True)
        (-0.35, -0.5)
    """
    if max_length <= 0:
        raise ValueError(f"max_length must be > 0, got {max_length!r}")
    if length < 0:
        raise ValueError(f"length must be >= 0, got {length!r}")
    if truncated:
        return float(r_penalty)
    shape = 1.0 - math.cos(math.pi * min(float(length), float(max_length)) / float(max_length))
    if correct:
        return float(r_max - 0.5 * (r_max - r_min) * shape)
    return float(-0.5 * abs(r_min) * shape)


def assistant_tokens(trajectory: Trajectory, tokenizer: Any = None,
                     count: Callable[[str], int] | None = None) -> int:
    """Tokens of all assistant turns (each turn's raw action text).

    Uses `count(text)` when given, else `len(tokenizer.encode(text, add_special_tokens=False))`,
    else whitespace-separated words (an approximation; pass the policy's tokenizer in training,
    or take `RolloutSample.response_tokens`, which counts the generated ids exactly).
    """
    if count is None:
        if tokenizer is not None:
            def count(text: str) -> int:
                try:
                    return len(tokenizer.encode(text, add_special_tokens=False))
                except TypeError:
                    return len(tokenizer.encode(text))
        else:
            def count(text: str) -> int:
                return len(text.split())
    return sum(count(turn.action) for turn in trajectory.turns)


def episode_cosine_reward(trajectory: Trajectory, correct: bool, max_length: int, *, tokenizer: Any = None,
                          truncated: bool | None = None, **params: float) -> float:
    """Eq. 4 for a finished episode: L from its assistant turns; `truncated` defaults to the
    record's (the episode ended at the turn limit without an answer)."""
    cut = trajectory.truncated if truncated is None else truncated
    return cosine_length_reward(correct, assistant_tokens(trajectory, tokenizer), max_length, truncated=cut, **params)
