"""The reward: the 5D score of the paper (+ assertions), safety penalties, and Eq. 4.

Training and evaluation use the same function, computed from what the agent actually did:

    >>> from envs.rewards import score_episode, RewardWeights
    >>> breakdown = score_episode(trajectory, task)            # doctest: +SKIP
    >>> breakdown.total, breakdown.components()                # doctest: +SKIP

One module per dimension: `accuracy`, `process`, `safety` (+ `checks/`), `format`,
`coherence`, `assertions`; `score` combines them, `cosine` is Eq. 4, `adapters` wraps the reward
for TRL and verl. The extension contract is in `envs/rewards/README.md`, the definitions in
`docs/rewards.md`.
"""

from envs.rewards.choice import extract_choice
from envs.rewards.conventions import DEFAULT_CONVENTIONS, ToolConventions
from envs.rewards.cosine import assistant_tokens, cosine_length_reward, episode_cosine_reward
from envs.rewards.safety import (
    BaseSafetyContext,
    SafetyContext,
    StaticSafetyContext,
    detect_violations,
    safety_check,
)
from envs.rewards.safety_patterns import PATTERNS, Pattern, register_pattern
from envs.rewards.score import score_episode, score_episodes
from envs.rewards.types import DEFAULT_WEIGHTS, RewardBreakdown, RewardWeights, Violation

# The built-in safety checks register themselves with `safety_check` when imported. Importing them
# here (any import of envs.rewards.* runs this file first) keeps the dependency one way:
# checks -> safety, never safety -> checks.
from envs.rewards import checks  # noqa: F401  isort: skip

__all__ = [
    "score_episode", "score_episodes", "RewardWeights", "RewardBreakdown", "Violation", "cosine_length_reward", "extract_choice",
    "SafetyContext", "BaseSafetyContext", "StaticSafetyContext", "detect_violations", "safety_check",
    "PATTERNS", "Pattern", "register_pattern", "ToolConventions", "DEFAULT_CONVENTIONS", "DEFAULT_WEIGHTS",
    "assistant_tokens", "episode_cosine_reward",
]
