"""Shared helpers of the learner-side tests: a tiny model and synthetic multi-turn samples.

The tiny model and tokenizer are built once per test process (cached in a temp directory).
Samples are multi-turn episodes in token space: prompt, then per turn the generated tokens
(loss mask 1) followed by tool-result tokens (mask 0), with the sampling log-probs of the
initial policy, so the train-vs-rollout difference starts at zero.
"""

from __future__ import annotations

import functools
import random
import tempfile
from pathlib import Path

import torch

from actors.types import RolloutSample, TurnSpan

CORPUS = [
    "Check the interaction between warfarin and aspirin before prescribing.",
    "The patient is a 64-year-old man with chest pain radiating to the left arm.",
    "Answer: B. Revisit the differential diagnosis: pulmonary embolism versus myocardial infarction.",
    '<tool_call>\n{"name": "search_drug", "arguments": {"name": "metformin"}}\n</tool_call>',
    "Creatinine clearance is 45 mL/min; reduce the dose of enoxaparin accordingly.",
] * 40


@functools.cache
def tiny_model_dir(hidden: int = 64, layers: int = 2, vocab: int = 2048, seed: int = 0) -> str:
    """Build (once per process) a tiny Qwen3 model plus tokenizer; returns its directory."""
    from modeling.model import build_tiny_model, train_tokenizer

    root = Path(tempfile.mkdtemp(prefix="t1_tiny_"))
    tok = train_tokenizer(CORPUS, vocab, root / "tok", max_stdlib_files=60)
    heads = 4
    out = build_tiny_model(root / "model", tok, seed=seed, hidden_size=hidden, intermediate_size=2 * hidden,
                           num_hidden_layers=layers, num_attention_heads=heads, num_key_value_heads=2,
                           head_dim=hidden // heads)
    return str(out)


def make_sample(
    rng: random.Random,
    *,
    group_id: str,
    index: int,
    prompt_len: int,
    turn_lens: list[int],
    tool_len: int = 5,
    vocab: int = 2048,
    reward: float = 0.0,
    correct: bool = False,
    truncated_turns: tuple[int, ...] = (),
) -> RolloutSample:
    """A synthetic episode: prompt, then turns of generated tokens separated by tool-result tokens."""
    ids = [rng.randrange(10, vocab) for _ in range(prompt_len)]
    mask = [0] * prompt_len
    turns = []
    for t, n in enumerate(turn_lens):
        start = len(ids)
        ids += [rng.randrange(10, vocab) for _ in range(n)]
        mask += [1] * n
        turns.append(TurnSpan(start=start, end=len(ids), truncated=t in truncated_turns))
        if t < len(turn_lens) - 1:
            ids += [rng.randrange(10, vocab) for _ in range(tool_len)]
            mask += [0] * tool_len
    n = len(ids)
    return RolloutSample(
        sample_id=f"{group_id}:{index}", task_id=group_id, domain="synthetic", group_id=group_id, seed=index,
        prompt_length=prompt_len, input_ids=ids, loss_mask=mask, sampling_logprobs=[0.0] * n,
        policy_versions=[0 if m else -1 for m in mask], turns=turns, reward=reward,
        reward_components={"accuracy": float(correct), "total": reward}, correct=correct,
        response_tokens=sum(turn_lens),
    )


def with_policy_logprobs(samples: list[RolloutSample], model_dir: str, temperature: float = 1.0) -> list[RolloutSample]:
    """Fill `sampling_logprobs` with the model's own log-probs (what an exact generator would report)."""
    from modeling.model import load_policy, pad_batch, per_token_logprobs

    model, tok = load_policy(model_dir)
    ids, mask = pad_batch([s.input_ids for s in samples], tok.pad_token_id)
    with torch.no_grad():
        lp = per_token_logprobs(model, ids, mask, temperature=temperature)
    out = []
    for i, s in enumerate(samples):
        row = [float(lp[i, p]) if s.loss_mask[p] else 0.0 for p in range(len(s.input_ids))]
        out.append(s.model_copy(update={"sampling_logprobs": row}))
    return out


def make_batch(seed: int = 0, groups: int = 2, group_size: int = 3, model_dir: str | None = None) -> list[RolloutSample]:
    """Groups of unequal-length multi-turn samples with mixed rewards."""
    rng = random.Random(seed)
    samples = []
    for g in range(groups):
        for i in range(group_size):
            turns = [rng.randint(3, 9) for _ in range(rng.randint(1, 3))]
            correct = (i + g) % 2 == 0
            samples.append(make_sample(rng, group_id=f"g{g}", index=i, prompt_len=rng.randint(6, 12),
                                       turn_lens=turns, reward=1.0 if correct else rng.choice([0.0, 0.25]),
                                       correct=correct))
    if model_dir is not None:
        samples = with_policy_logprobs(samples, model_dir)
    return samples
