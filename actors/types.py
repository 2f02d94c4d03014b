"""Data that crosses actor boundaries during training (pydantic, so it validates and pickles).

A `RolloutSample` is one finished multi-turn episode in token space, built token-in/token-out:
`input_ids` is the prompt rendered once by the chat template, then for every turn the generated
ids followed by the tokenized tool result. Nothing is ever re-rendered, so the learner trains on
exactly the tokens the generator sampled.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, model_validator

from envs.core.trajectory import Trajectory


class TurnSpan(BaseModel):
    """Token positions [start, end) of one assistant turn's generated tokens in `input_ids`."""

    model_config = ConfigDict(extra="forbid")
    start: int = Field(ge=0)
    end: int = Field(ge=0)
    truncated: bool = False  # the turn hit the token limit


class RolloutSample(BaseModel):
    """One episode of one prompt, ready for the loss."""

    model_config = ConfigDict(extra="forbid")
    sample_id: str                        # unique: f"{task_id}:{group_index}:{seed}"
    task_id: str
    domain: str
    group_id: str                          # samples of the same prompt share it (GRPO group)
    seed: int
    prompt_length: int                     # tokens of the rendered prompt
    input_ids: list[int]                   # prompt + all turns + tool results
    loss_mask: list[int]                   # 1 on generated (assistant) tokens, 0 elsewhere
    sampling_logprobs: list[float]         # generator log-prob per position (0.0 where mask is 0)
    policy_versions: list[int]             # policy version that sampled each position (-1 where mask 0)
    turns: list[TurnSpan] = Field(default_factory=list)
    # What the env said, set once by the agent loop from the episode's final info:
    env_reward: float = 0.0                # the env's 5D total
    env_correct: bool = False              # the env's grader: the task's accuracy criterion met
    reward_components: dict[str, float] = Field(default_factory=dict)
    # What training uses, set by `learner.batching.score_sample` from the run's reward config (the
    # agent loop starts them at the env's values, which is what they stay outside training):
    reward: float = 0.0                    # the RL reward (5D total or cosine length reward)
    correct: bool = False                  # outcome used for hints, dynamic sampling and accuracy
    truncated: bool = False                # episode hit a turn or token limit
    num_tool_calls: int = 0
    response_tokens: int = 0               # assistant tokens over all turns (the L of Eq. 4)
    metadata: dict[str, Any] = Field(default_factory=dict)
    # The env's episode record (tool calls with arguments, observations, parse errors, the submitted
    # answer, the reward's reasons and safety violations), for people reading a run (`hcgym view`);
    # never used by the loss. Without the system prompt (one per domain) and wall-clock durations, so
    # a re-run of the same episode gives the same record.
    episode: Trajectory | None = None

    @model_validator(mode="after")
    def _aligned(self) -> "RolloutSample":
        n = len(self.input_ids)
        for name in ("loss_mask", "sampling_logprobs", "policy_versions"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name} has {len(getattr(self, name))} entries but input_ids has {n}")
        for span in self.turns:
            if not (self.prompt_length <= span.start <= span.end <= n):
                raise ValueError(f"turn span [{span.start}, {span.end}) outside the response of length {n}")
        return self

    @property
    def min_policy_version(self) -> int:
        versions = [v for v in self.policy_versions if v >= 0]
        return min(versions) if versions else -1


class TeacherOutput(BaseModel):
    """The EMA teacher's log-probs for one `RolloutSample`, aligned to the student's positions.

    `logprobs[p]` is the teacher's log-prob of `input_ids[p]` at every position p where the sample's
    `loss_mask` is 1 (the student's generated tokens of every assistant turn), computed on the teacher
    context `prompt + hint + response`; the hint tokens themselves never appear. Every other position
    holds 0.0, so `len(logprobs) == len(input_ids)` and position p means the same token for the
    student and the teacher. With top-k serving, `topk_ids[p]` / `topk_logprobs[p]` are the teacher's
    k most likely next tokens for position p (a list of length k per position: the ragged sequence
    dimension comes first, the candidate dimension last), empty lists where the mask is 0.
    """

    model_config = ConfigDict(extra="forbid")
    sample_id: str
    teacher_version: int                   # increments at every EMA update or hard copy
    hint: str = "none"                     # "reinforcing", "corrective" or "none"
    hint_tokens: int = 0                   # tokens inserted into the teacher context
    input_length: int                      # len(sample.input_ids), checked by the learner
    logprobs: list[float]
    topk_ids: list[list[int]] | None = None
    topk_logprobs: list[list[float]] | None = None
    compute_s: float = 0.0                 # teacher forward time for this sample's batch share
    computed_positions: int = 0            # decoder positions its teacher forward computed for this sample
    padded_positions: int = 0              # of which padding (0 when the teacher packs sequences)

    @model_validator(mode="after")
    def _aligned(self) -> "TeacherOutput":
        if len(self.logprobs) != self.input_length:
            raise ValueError(f"teacher logprobs has {len(self.logprobs)} entries, expected input_length={self.input_length}")
        for name in ("topk_ids", "topk_logprobs"):
            value = getattr(self, name)
            if value is not None and len(value) != self.input_length:
                raise ValueError(f"teacher {name} has {len(value)} positions, expected input_length={self.input_length}")
        return self


class TeacherBatch(BaseModel):
    """The teacher's outputs for a training batch (what `Teacher.fetch` returns and what the
    learner's `train_step` / `evaluate_loss` take), and how long the caller waited for them."""

    model_config = ConfigDict(extra="forbid")
    outputs: list[TeacherOutput]
    wait_s: float = 0.0

    def by_sample(self) -> dict[str, TeacherOutput]:
        return {o.sample_id: o for o in self.outputs}


@dataclass(frozen=True)
class PendingTeacherBatch:
    """A Ray ref to a `TeacherBatch` still being computed (`teacher.fetch.remote(...)`).

    Ray resolves a ref passed as a top-level argument before the call starts; wrapped, it stays a
    ref, so the learner can run its reference and old-policy forwards first and wait for the
    teacher only when it needs the log-probs (the wait is reported as `teacher_wait_s`)."""

    ref: Any
