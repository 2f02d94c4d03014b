"""The initial policy: build the tiny model (or point at a pretrained one), then warm-start it.

`prepare_policy(cfg, run_dir)` returns the directory the learner, the generators and the teacher
all load. For `model.kind: tiny` it trains a BPE tokenizer on the task corpus and builds a
Qwen-architecture model from a config (nothing is downloaded); with `sft.enabled` it then runs
supervised fine-tuning on gold-replay trajectories, so that RL starts from a policy that emits
valid tool calls.

Gold replay: for each training task, the scripted `GoldReplayPolicy` "generates" the task's
expected tool calls and finally `submit_answer` with the gold answer; the real environment
executes them, so the tool results are real, and the same TITO agent loop that RL uses lays out
the tokens. SFT trains on exactly the assistant tokens (loss mask 1) of those episodes: the
warm start sees the very token layout RL will sample in.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from actors.agent_loop import AgentLoop, EpisodeSpec, GoldReplayPolicy, LocalEnv, RolloutLimits, gold_turn_actions
from actors.types import RolloutSample

POLICY_RECORD = "policy.json"


def task_corpus(domains: list[str], split: str | None, pattern: str | None = None) -> list[str]:
    """Text for the tokenizer: each domain's system prompts (full and compact), the tickets, the
    gold actions and the real tool results of gold replays."""
    from actors.agent_loop import compact_system_prompt
    from envs import registry
    from envs.env import build_system_prompt, render_ticket
    from envs.validate import gold_replay

    texts: list[str] = []
    for domain in domains:
        domain_env = registry.get_environment(domain)
        texts.append(build_system_prompt(domain_env))
        texts.append(compact_system_prompt(domain_env.toolkit.schemas()))
        for task in registry.get_tasks(domain, split):
            if pattern is not None and not re.search(pattern, task.id):
                continue
            texts.append(render_ticket(task))
            trajectory, _ = gold_replay(task, domain)
            for turn in trajectory.turns:
                texts.append(turn.action)
                texts.append(turn.observation)
    return texts


def gold_replay_samples(tokenizer, refs: list[tuple[str, str, str | None]], limits: RolloutLimits,
                        *, prompt_style: str = "env", log: Callable[[str], None] = print) -> list[RolloutSample]:
    """Run the gold solution of each (domain, task_id, split) through the TITO agent loop.

    Returns only the episodes the grader counts as correct (a gold answer the env rejects would
    teach the wrong thing; such tasks are reported).
    """
    from envs import registry

    loop = AgentLoop(tokenizer, limits, prompt_style)
    tasks = {}
    for domain, task_id, split in refs:
        key = (domain, split)
        if key not in tasks:
            tasks[key] = {t.id: t for t in registry.get_tasks(domain, split)}
    actions = {task_id: gold_turn_actions(tasks[(d, s)][task_id], limits.max_turns) for d, task_id, s in refs}
    policy = GoldReplayPolicy(tokenizer, actions)
    env = LocalEnv(limits.max_turns)

    async def run_all() -> list[RolloutSample]:
        out = []
        for index, (domain, task_id, split) in enumerate(refs):
            spec = EpisodeSpec(sample_id=f"{task_id}:0:{index}", task_id=task_id, domain=domain, split=split,
                               group_id=f"sft:{task_id}", seed=index)
            out.append(await loop.run(spec, env, policy))
        return out

    samples = asyncio.run(run_all())
    good = [s for s in samples if s.correct]
    if len(good) < len(samples):
        bad = [s.task_id for s in samples if not s.correct]
        log(f"[sft] {len(bad)} gold replays were not graded correct and are left out: {bad[:5]}")
    return good


@dataclass
class SFTExample:
    """Token ids and the mask of the positions trained on (the assistant tokens)."""

    input_ids: list[int]
    loss_mask: list[int]


def hinted_example(sample: RolloutSample, tokenizer, hints, kind: str) -> SFTExample:
    """The sample with a privileged hint inserted where the TT-OPD teacher inserts it.

    Mirrors `actors.teacher.Teacher.build_context`: the hint turn (`hints.template` around the
    reinforcing or corrective text) goes before the prompt's trailing generation header
    `<|im_start|>assistant\n` when `before_generation_prompt` is set and the prompt ends with it,
    else at `prompt_length`. The hint tokens are not trained on.

    Why: a policy warm-started without ever seeing such a turn treats the teacher's hinted context
    as out of distribution; on the tiny model that alone put KL(student || teacher) at 0.35-0.55
    nats/token at step 1 and the distillation term pulled the student toward broken outputs.
    """
    from modeling.model import IM_START

    text = hints.template.format(hint=hints.reinforcing if kind == "reinforcing" else hints.corrective)
    hint = list(tokenizer.encode(text, add_special_tokens=False))
    header = list(tokenizer.encode(f"{IM_START}assistant\n", add_special_tokens=False))
    ids, mask, at = list(sample.input_ids), list(sample.loss_mask), sample.prompt_length
    if hints.before_generation_prompt and at >= len(header) and ids[at - len(header):at] == header:
        at -= len(header)
    return SFTExample(ids[:at] + hint + ids[at:], mask[:at] + [0] * len(hint) + mask[at:])


def run_sft(model_dir: str | Path, output_dir: str | Path, samples: list[RolloutSample | SFTExample], *, epochs: float,
            lr: float, batch_size: int, seed: int, weight_decay: float = 0.0, warmup_frac: float = 0.05,
            max_grad_norm: float = 1.0, train_vision_tower: bool = False, max_shard_size: str | int = "5GB",
            log: Callable[[str], None] = print) -> dict[str, Any]:
    """Next-token cross-entropy on the assistant tokens (loss mask 1) of `samples`.

    AdamW with linear warmup and cosine decay. The model is loaded through the one loading path
    (`modeling.hf_checkpoint`); a multimodal checkpoint's vision tower stays frozen unless
    `train_vision_tower`. `output_dir` receives a Hugging Face checkpoint (sharded safetensors +
    index, config, tokenizer) that `from_pretrained`, vLLM and the learner load unchanged.

    Returns:
        {"steps", "first_loss", "last_loss", "seconds"}.
    """
    import numpy as np
    import torch

    from modeling.hf_checkpoint import freeze_vision_tower, save_sharded_checkpoint
    from modeling.model import load_policy, pad_batch, per_token_logprobs

    if not samples:
        raise ValueError("run_sft: no training samples (no gold replay was graded correct)")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    model, tokenizer = load_policy(model_dir)
    freeze_vision_tower(model, train_vision_tower=train_vision_tower)
    model.train()
    trainable = [p for p in model.parameters() if p.requires_grad]
    optim = torch.optim.AdamW(trainable, lr=lr, weight_decay=weight_decay)
    batches_per_epoch = math.ceil(len(samples) / batch_size)
    total = max(1, int(round(epochs * batches_per_epoch)))
    warmup = int(warmup_frac * total)

    def lr_at(step: int) -> float:
        if step < warmup:
            return lr * (step + 1) / warmup
        progress = (step - warmup) / max(1, total - warmup)
        return lr * 0.5 * (1 + math.cos(math.pi * progress))

    pad = tokenizer.pad_token_id if tokenizer.pad_token_id is not None else 0
    started = time.perf_counter()
    losses: list[float] = []
    order: list[int] = []
    for step in range(total):
        if not order:
            order = rng.permutation(len(samples)).tolist()
        batch = [samples[i] for i in order[:batch_size]]
        order = order[batch_size:]
        ids, mask = pad_batch([s.input_ids for s in batch], pad, side="right")
        loss_mask, _ = pad_batch([s.loss_mask for s in batch], 0, side="right")
        logp = per_token_logprobs(model, ids, mask)
        weight = loss_mask.float()
        loss = -(logp * weight).sum() / weight.sum().clamp(min=1.0)
        for group in optim.param_groups:
            group["lr"] = lr_at(step)
        optim.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(trainable, max_grad_norm)
        optim.step()
        losses.append(float(loss.detach()))
        if step == 0 or (step + 1) % max(1, total // 10) == 0 or step + 1 == total:
            log(f"[sft] step {step + 1}/{total} loss {losses[-1]:.4f} lr {lr_at(step):.2e} "
                f"({time.perf_counter() - started:.0f}s)")
    model.eval()
    out = Path(output_dir)
    out.mkdir(parents=True, exist_ok=True)
    # Config, generation config and tokenizer files are copied from `model_dir`.
    save_sharded_checkpoint(out, model.state_dict(), source_dir=model_dir, max_shard_size=max_shard_size)
    return {"steps": total, "first_loss": losses[0], "last_loss": losses[-1],
            "seconds": time.perf_counter() - started, "samples": len(samples)}


def policy_fingerprint(cfg) -> str:
    """Hash of everything that determines the initial policy (model, SFT, data, prompt, seed)."""
    import hashlib

    parts = {"model": cfg.model.model_dump(mode="json"), "sft": cfg.sft.model_dump(mode="json"),
             "data": cfg.data.model_dump(mode="json"), "seed": cfg.seed,
             "rollout": {k: getattr(cfg.rollout, k) for k in ("max_turns", "max_observation_chars", "system_prompt",
                                                               "max_new_tokens_per_turn", "max_response_tokens")},
             "hints": cfg.teacher.hints.model_dump(mode="json") if cfg.teacher.enabled else None}
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()[:16]


def prepare_policy(cfg, run_dir: str | Path, *, log: Callable[[str], None] = print) -> Path:
    """The initial policy directory of a run (built once; a resumed run finds the record).

    Args:
        cfg: `RunConfig`.
        run_dir: The run directory; everything is written under `run_dir/model/`.
    """
    from actors.env_actor import register_domains
    from modeling.model import build_tiny_model, load_tokenizer, train_tokenizer
    from learner.tasks import load_task_refs

    register_domains(cfg.data.domain_modules)
    root = Path(run_dir) / "model"
    record = root / POLICY_RECORD
    fingerprint = policy_fingerprint(cfg)
    if record.exists():
        recorded = json.loads(record.read_text())
        path = Path(recorded["policy_dir"])
        if recorded.get("fingerprint") == fingerprint and (path / "config.json").exists():
            log(f"[model] reusing {path}")
            return path
        log(f"[model] {record} was built from another config: rebuilding")
    root.mkdir(parents=True, exist_ok=True)
    info: dict[str, Any] = {}
    if cfg.model.kind == "pretrained":
        from modeling.hf_checkpoint import resolve_model_path

        try:  # a local folder, or a hub id already in the Hugging Face cache (never downloaded here)
            base = resolve_model_path(cfg.model.path, revision=cfg.model.revision)
        except (FileNotFoundError, ValueError) as exc:
            raise type(exc)(f"model.path: {exc}") from exc
    else:
        t0 = time.perf_counter()
        tiny = cfg.model.tiny
        corpus = task_corpus(cfg.data.domains, cfg.data.train_split, cfg.data.task_id_pattern)
        tok_dir = train_tokenizer(corpus, tiny.vocab_size, root / "tokenizer",
                                  include_stdlib=tiny.include_stdlib_corpus, max_stdlib_files=tiny.max_stdlib_files)
        base = build_tiny_model(root / "init", tok_dir, architecture=tiny.architecture, seed=cfg.seed,
                                **tiny.overrides)
        info["build_s"] = time.perf_counter() - t0
        log(f"[model] tokenizer ({len(load_tokenizer(tok_dir))} tokens, {len(corpus)} corpus texts) and tiny "
            f"{tiny.architecture} model built in {info['build_s']:.1f}s")
    policy = base
    if cfg.sft.enabled:
        tokenizer = load_tokenizer(base)
        limits = RolloutLimits(**{k: getattr(cfg.rollout, k) for k in RolloutLimits.model_fields})
        refs = [(r.domain, r.task_id, r.split)
                for r in load_task_refs(cfg.data.domains, cfg.data.train_split, cfg.sft.max_tasks,
                                        cfg.data.task_id_pattern)]
        t0 = time.perf_counter()
        samples = gold_replay_samples(tokenizer, refs, limits, prompt_style=cfg.rollout.system_prompt, log=log)
        log(f"[sft] {len(samples)} gold-replay trajectories in {time.perf_counter() - t0:.1f}s")
        s = cfg.sft
        examples: list = list(samples)
        if s.hint_fraction > 0 and cfg.teacher.enabled and cfg.teacher.hints.enabled:
            import random

            rng = random.Random(cfg.seed)
            chosen = [i for i in range(len(samples)) if rng.random() < s.hint_fraction]
            for i in chosen:  # replaced, not added: the same number of SFT steps
                examples[i] = hinted_example(samples[i], tokenizer, cfg.teacher.hints,
                                             rng.choice(["reinforcing", "corrective"]))
            log(f"[sft] {len(chosen)} of {len(samples)} examples carry a teacher hint turn")
        info["sft"] = run_sft(base, root / "sft", examples, epochs=s.epochs, lr=s.lr, batch_size=s.batch_size,
                              seed=cfg.seed, weight_decay=s.weight_decay, warmup_frac=s.warmup_frac,
                              max_grad_norm=s.max_grad_norm, train_vision_tower=cfg.learner.train_vision_tower,
                              log=log)
        policy = root / "sft"
    record.write_text(json.dumps({"policy_dir": str(policy.resolve()), "fingerprint": fingerprint, **info}, indent=1))
    return policy.resolve()
