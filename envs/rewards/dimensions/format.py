"""Format: well-formed tool calls and a conclusion, gated by a real attempt at an answer
(envs/rewards/format.py). Always applies."""

from envs.rewards.dimensions.base import Dimension, scored_by
from envs.rewards.format import format_score

DIMENSION = Dimension(name="format", default_weight=0.10, position=3, grade=scored_by(format_score),
                      summary="well-formed calls and a real attempt at an answer")
