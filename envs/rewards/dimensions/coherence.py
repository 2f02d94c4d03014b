"""Coherence: no contradiction between what the agent found, stated and submitted
(envs/rewards/coherence.py). Always applies."""

from envs.rewards.coherence import coherence_score
from envs.rewards.dimensions.base import Dimension, scored_by

DIMENSION = Dimension(name="coherence", default_weight=0.10, position=4, grade=scored_by(coherence_score),
                      summary="no contradiction between findings, statements and the answer")
