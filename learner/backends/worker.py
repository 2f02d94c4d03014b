"""One rank of the learner: batch -> tensors -> L_total -> backward -> optimizer step.

Every rank receives the whole batch, computes the whole-batch quantities (group advantages, token
and sequence counts, turn weights) itself, and then trains on its round-robin shard. Because the
losses are shares of the whole batch (losses.BatchNorms) and `grad_scale` undoes the cross-rank
averaging, 1 rank and N ranks produce the same update for the same batch.

Each rank counts its optimizer steps as the policy version it holds (restored from a checkpoint's
`learner_state.json`), so it can tell how many versions behind the learner each sampled token is
(`RolloutSample.policy_versions`): the lag that the off-policy metrics of losses.py report.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch

from actors.types import PendingTeacherBatch, RolloutSample, TeacherBatch, TeacherOutput
from learner.backends.base import LearnerBackend
from learner.backends.factory import make_backend
from modeling.checkpoint import capture_rng_state, read_json, restore_rng_state, write_json_atomic
from modeling.config_models import LearnerConfig
from learner.losses import (
    BatchNorms,
    LossInputs,
    combine_metric_parts,
    compute_loss,
    finalize_metrics,
    group_advantages,
    turn_weights,
)
from modeling.model import (pad_batch, packing_unsupported, packs_sequences, padding_fraction, split_batches,
                            token_stats)


@dataclass
class _Prepared:
    """Whole-batch data every rank derives identically."""

    samples: list[RolloutSample]
    advantages: torch.Tensor
    distill_weights: list[list[float]] | None
    teacher: list[TeacherOutput | None]
    norms: BatchNorms
    turns_kept: int
    turns_truncated: int


def _padded(T: int, rows: list[list[float]], dtype=torch.float32) -> torch.Tensor:
    """Right-pad per-position rows to [B, T]."""
    out = torch.zeros((len(rows), T), dtype=dtype)
    for i, row in enumerate(rows):
        out[i, : len(row)] = torch.tensor(row, dtype=dtype)
    return out


def combine_rank_metrics(results: Sequence[dict]) -> dict[str, float]:
    """Per-rank sums -> step metrics: shares of the loss add up, token sums become batch means.

    Whole-batch quantities (turn counts, advantages) and DeepSpeed's global grad norm are the same
    on every rank, so rank 0's are reported.
    """
    metrics = finalize_metrics([r["sums"] for r in results if r["sums"]])
    metrics.update(results[0]["extra"])
    metrics["learner_s"] = max(r["extra"]["learner_s"] for r in results)
    # Each rank computed its own micro-batches (summed); the teacher's outputs cover the whole batch.
    padded = sum(r["extra"].get("learner_padded_positions", 0.0) for r in results)
    computed = sum(r["extra"].get("learner_computed_positions", 0.0) for r in results)
    teacher_padded = metrics.pop("teacher_padded_positions", 0.0)
    teacher_computed = metrics.pop("teacher_computed_positions", 0.0)
    for key in ("learner_padded_positions", "learner_computed_positions"):
        metrics.pop(key, None)
    metrics["learner_padding_frac"] = padded / computed if computed else 0.0
    if teacher_computed:
        metrics["teacher_padding_frac"] = teacher_padded / teacher_computed
    return metrics


def resolve_teacher(teacher: TeacherBatch | PendingTeacherBatch | None) -> tuple[TeacherBatch | None, float]:
    """The teacher's batch, waiting for a pending one here (timed): see `PendingTeacherBatch`."""
    if isinstance(teacher, PendingTeacherBatch):
        import ray

        t0 = time.perf_counter()
        value = ray.get(teacher.ref)
        if not isinstance(value, TeacherBatch):
            raise TypeError(f"the pending teacher batch resolved to {type(value).__name__}, not TeacherBatch")
        return value, time.perf_counter() - t0
    if teacher is not None and not isinstance(teacher, TeacherBatch):
        raise TypeError(f"teacher: expected a TeacherBatch, a PendingTeacherBatch or None, got {type(teacher).__name__}")
    return teacher, 0.0


class RankWorker:
    """Runs the shared training logic on one backend rank (in-process, or as a Ray actor).

    Args:
        config: Learner settings.
        model_dir: Initial policy directory.
        seed: Seed.
        rank: This rank.
        world_size: Number of ranks.
        master_port: Rendezvous port for multi-rank backends.
    """

    def __init__(self, config: LearnerConfig | dict, model_dir: str, seed: int = 0, rank: int = 0,
                 world_size: int = 1, master_port: int | None = None):
        self.config = config if isinstance(config, LearnerConfig) else LearnerConfig.model_validate(config)
        self.rank = rank
        self.world_size = world_size
        self.backend: LearnerBackend = make_backend(self.config, model_dir, seed, rank, world_size, master_port)
        from modeling.model import load_tokenizer

        tokenizer = load_tokenizer(model_dir)
        self.pad_id = tokenizer.pad_token_id if tokenizer.pad_token_id is not None else 0
        # The policy, reference and pi_old forwards run on real tokens only where the model allows it.
        unsupported = packing_unsupported(self.backend.policy) if self.config.pack_sequences is True else None
        if unsupported and rank == 0:
            print(f"[learner] learner.pack_sequences: {unsupported}", flush=True)
        # The version of the weights this rank holds (batches trained so far): the same count as
        # LearnerActor's policy_version, against which the tokens' sampling versions are lagged.
        self.policy_version = 0

    def ready(self) -> int:
        return self.rank

    # -- batch preparation -------------------------------------------------------------------------
    def _prepare(self, samples: list[RolloutSample]) -> _Prepared:
        """Whole-batch quantities that do not need the teacher."""
        if not samples:
            raise ValueError("train_step got an empty batch")
        ids = [s.sample_id for s in samples]
        if len(set(ids)) != len(ids):
            dup = sorted({i for i in ids if ids.count(i) > 1})
            raise ValueError(f"duplicate sample_id(s) in the batch: {dup[:5]}")
        cfg = self.config.loss
        adv = group_advantages([s.reward for s in samples], [s.group_id for s in samples],
                               scale=cfg.grpo.scale_advantages, eps=cfg.grpo.advantage_eps)
        if cfg.grpo.negative_advantage_weight != 1.0:
            adv = torch.where(adv < 0, adv * cfg.grpo.negative_advantage_weight, adv)
        weights = None
        kept = dropped = 0
        if cfg.distill.enabled:
            weights = []
            for s in samples:
                tw = turn_weights(s, cfg.distill)
                weights.append(tw.weights)
                kept += len(tw.kept_turns)
                dropped += len(tw.dropped_turns)
        num_tokens = float(sum(sum(s.loss_mask) for s in samples))
        norms = BatchNorms(num_tokens=max(num_tokens, 1.0), num_sequences=float(len(samples)))
        return _Prepared(samples, adv, weights, [None] * len(samples), norms, kept, dropped)

    def _attach_teacher(self, prep: _Prepared, teacher) -> None:
        """Check the teacher's outputs against the samples and keep them in batch order."""
        cfg = self.config.loss
        if not cfg.distill.enabled:
            return
        by_id = teacher.by_sample() if teacher is not None else {}
        outputs: list[TeacherOutput | None] = []
        for s in prep.samples:
            out = by_id.get(s.sample_id)
            if out is None:
                raise ValueError(f"loss.distill.enabled but no teacher output for sample {s.sample_id!r}")
            if out.input_length != len(s.input_ids):
                raise ValueError(
                    f"teacher output for {s.sample_id!r} covers {out.input_length} positions, "
                    f"the sample has {len(s.input_ids)}"
                )
            if cfg.distill.estimator == "topk" and (out.topk_ids is None or out.topk_logprobs is None):
                raise ValueError(f"estimator 'topk' but the teacher served no top-k for {s.sample_id!r} "
                                 "(set teacher.serve_topk >= loss.distill.topk)")
            outputs.append(out)
        prep.teacher = outputs

    def _micro_batches(self, prep: _Prepared) -> list[list[int]]:
        """This rank's sample indices split into micro-batches (by count, or by token budget; sorted by
        length first with `optim.micro_batch_order: length`); every rank gets the same count: each works
        out every rank's split and pads to the longest. Which micro-batch a sample is in does not change
        the update: every loss term is a share of the whole batch (BatchNorms)."""
        optim = self.config.optim
        lengths = [len(s.input_ids) for s in prep.samples]
        splits = [split_batches(optim.micro_batch_order, list(range(rank, len(lengths), self.world_size)), lengths,
                                optim.micro_batch_size, optim.max_tokens_per_micro_batch)
                  for rank in range(self.world_size)]
        count = max(1, max(len(split) for split in splits))
        mine = splits[self.rank]
        return mine + [[] for _ in range(count - len(mine))]  # empty lists: padding steps that keep collectives in lockstep

    def _tensors(self, prep: _Prepared, idx: list[int]) -> dict[str, torch.Tensor]:
        dev = self.backend.device
        samples = [prep.samples[i] for i in idx]
        ids, attn = pad_batch([s.input_ids for s in samples], self.pad_id, side="right")
        T = ids.shape[1]

        t = {
            "input_ids": ids,
            "attention_mask": attn,
            "loss_mask": _padded(T, [s.loss_mask for s in samples]),
            "rollout_logprobs": _padded(T, [s.sampling_logprobs for s in samples]),
            "advantages": prep.advantages[idx],
            # Versions behind these weights each generated token was sampled (0 off the mask).
            "policy_lag": _padded(T, [[float(self.policy_version - v) if m else 0.0
                                       for v, m in zip(s.policy_versions, s.loss_mask)] for s in samples]),
        }
        if self.config.loss.distill.enabled:
            t["distill_weights"] = _padded(T, [prep.distill_weights[i] for i in idx])
        return {k: v.to(dev) for k, v in t.items()}

    def _teacher_tensors(self, prep: _Prepared, idx: list[int], T: int) -> dict[str, torch.Tensor]:
        """The teacher's outputs for a micro-batch, padded to [B, T] (or [B, T, K] for top-k)."""
        dev = self.backend.device
        samples = [prep.samples[i] for i in idx]
        t: dict[str, torch.Tensor] = {}

        d = self.config.loss.distill
        if d.enabled:
            outs = [prep.teacher[i] for i in idx]
            if d.estimator == "topk":
                K = d.topk
                tid = torch.zeros((len(idx), T, K), dtype=torch.long)
                tlp = torch.zeros((len(idx), T, K), dtype=torch.float32)
                for b, (s, out) in enumerate(zip(samples, outs)):
                    for p, m in enumerate(s.loss_mask):
                        if not m:
                            continue
                        row_ids, row_lp = out.topk_ids[p], out.topk_logprobs[p]
                        if len(row_ids) < K:
                            raise ValueError(f"teacher served top-{len(row_ids)} at position {p} of "
                                             f"{s.sample_id!r}, loss.distill.topk needs {K}")
                        tid[b, p] = torch.tensor(row_ids[:K])
                        tlp[b, p] = torch.tensor(row_lp[:K])
                t["teacher_topk_ids"] = tid
                t["teacher_topk_logprobs"] = tlp
            else:
                t["teacher_logprobs"] = _padded(T, [o.logprobs for o in outs])
        return {k: v.to(dev) for k, v in t.items()}

    def _dummy_loss(self) -> torch.Tensor:
        """A zero loss through the whole model: a rank without samples still joins ZeRO-3's collectives."""
        ids = torch.full((1, 2), self.pad_id, dtype=torch.long, device=self.backend.device)
        self.backend.begin_forward()
        stats = token_stats(self.backend.policy, ids, torch.ones_like(ids))
        return stats.logprobs.sum() * 0.0

    def _pad_forwards(self, *, old: bool) -> None:
        """A padding micro-batch's share of the no-grad forwards the other ranks run on real ones:
        the reference's (when there is one) and pi_old's (`old`, with several updates per batch).
        Under ZeRO-3 every forward gathers each module's parameters collectively, so a rank that
        skipped them would pair its next gather with another rank's reference gather."""
        ids = torch.full((1, 2), self.pad_id, dtype=torch.long, device=self.backend.device)
        with torch.no_grad(), self.backend.autocast():
            if self.backend.reference is not None and self.config.loss.grpo.kl_beta > 0:
                token_stats(self.backend.reference, ids, torch.ones_like(ids))
            if old:
                self.backend.begin_forward()
                token_stats(self.backend.policy, ids, torch.ones_like(ids))

    # -- the step ------------------------------------------------------------------------------
    def _packed(self, t: dict[str, torch.Tensor]) -> bool:
        """Whether this micro-batch's forwards run packed (`learner.pack_sequences`)."""
        return packs_sequences(self.config.pack_sequences, self.backend.policy, t["attention_mask"])

    def _forward(self, t: dict[str, torch.Tensor], *, grad: bool):
        d = self.config.loss.distill
        self.backend.begin_forward()
        with torch.set_grad_enabled(grad), self.backend.autocast():
            return token_stats(
                self.backend.policy, t["input_ids"], t["attention_mask"],
                temperature=self.config.temperature, with_entropy=True,
                gather_ids=t.get("teacher_topk_ids") if d.enabled and d.estimator == "topk" else None,
                chunk_size=self.config.logprob_chunk_size,
                entropy_requires_grad=grad and self.config.loss.entropy_coef > 0,
                # Every loss term reads only the trained tokens: the LM head runs on those alone.
                positions=t["loss_mask"] > 0, packed=self._packed(t),
            )

    def _reference_logprobs(self, t: dict[str, torch.Tensor]) -> torch.Tensor | None:
        ref = self.backend.reference
        if ref is None or self.config.loss.grpo.kl_beta <= 0:
            return None
        with torch.no_grad(), self.backend.autocast():
            return token_stats(ref, t["input_ids"], t["attention_mask"], temperature=self.config.temperature,
                               chunk_size=self.config.logprob_chunk_size, positions=t["loss_mask"] > 0,
                               packed=self._packed(t)).logprobs

    def _run(self, samples: list[RolloutSample], teacher, *, update: bool) -> dict[str, float]:
        t0 = time.perf_counter()
        prep = self._prepare(samples)
        batches = self._micro_batches(prep)
        n_updates = self.config.optim.updates_per_batch if update else 1
        cache: list[dict] = []
        ref_s = 0.0  # where the step's time goes: reference forwards vs the policy's forward/backward
        padded = computed = 0  # decoder positions of this rank's micro-batches, and how many are padding
        for idx in batches:
            if not idx:
                self._pad_forwards(old=n_updates > 1)
                cache.append({})
                continue
            t = self._tensors(prep, idx)
            pad, total = padding_fraction(t["attention_mask"], self._packed(t))
            padded, computed = padded + pad, computed + total
            t_ref = time.perf_counter()
            entry = {"t": t, "idx": idx, "ref": self._reference_logprobs(t)}
            ref_s += time.perf_counter() - t_ref
            if n_updates > 1:  # pi_old must stay fixed across the updates of this batch
                entry["old"] = self._forward(t, grad=False).logprobs.detach()
            cache.append(entry)
        # Only now wait for the teacher: its last results had the forwards above to arrive.
        teacher, teacher_wait = resolve_teacher(teacher)
        self._attach_teacher(prep, teacher)
        for entry in cache:
            if entry:
                entry["t"].update(self._teacher_tensors(prep, entry["idx"], entry["t"]["input_ids"].shape[1]))

        sums: dict[str, float] = {}
        grad_norms = []
        t_update = time.perf_counter()
        for _ in range(n_updates):
            parts = []
            for entry in cache:
                if not entry:
                    if update:
                        self.backend.backward(self._dummy_loss())
                    else:  # evaluate: the other ranks' policy forwards gather too
                        with torch.no_grad():
                            self._dummy_loss()
                    continue
                t = entry["t"]
                stats = self._forward(t, grad=update)
                old = entry.get("old", stats.logprobs.detach())
                inputs = LossInputs(
                    logprobs=stats.logprobs, old_logprobs=old, rollout_logprobs=t["rollout_logprobs"],
                    loss_mask=t["loss_mask"], advantages=t["advantages"], ref_logprobs=entry["ref"],
                    entropy=stats.entropy if self.config.loss.entropy_coef > 0 else stats.entropy.detach(),
                    teacher_logprobs=t.get("teacher_logprobs"), distill_weights=t.get("distill_weights"),
                    student_topk_logprobs=stats.gathered, teacher_topk_logprobs=t.get("teacher_topk_logprobs"),
                    policy_lag=t["policy_lag"],
                )
                out = compute_loss(inputs, self.config.loss, prep.norms)
                if update:
                    self.backend.backward(out.loss * self.backend.grad_scale)
                parts.append(out.metrics)
            if update:
                grad_norms.append(self.backend.step())
            # The metrics describe the last update of the batch (the only one when updates_per_batch=1).
            sums = combine_metric_parts(parts)
        extra = {
            "turns_truncated": float(prep.turns_truncated),
            "turns_kept": float(prep.turns_kept),
            "advantage_abs_mean": float(prep.advantages.abs().mean()),
            "learner_s": time.perf_counter() - t0,
            "learner_ref_s": ref_s,
            "learner_forward_backward_s": time.perf_counter() - t_update,
            "teacher_wait_s": teacher_wait,
            # Padding share of the decoder positions the policy (and the reference and pi_old, same
            # layout) computed on; the teacher's, of its forwards for this batch.
            "learner_padded_positions": float(padded),
            "learner_computed_positions": float(computed),
        }
        if prep.teacher and prep.teacher[0] is not None:
            extra["teacher_padded_positions"] = float(sum(o.padded_positions for o in prep.teacher))
            extra["teacher_computed_positions"] = float(sum(o.computed_positions for o in prep.teacher))
        if update:
            extra["grad_norm"] = float(grad_norms[-1])
            self.policy_version += 1
        return {"sums": sums, "extra": extra}

    def train_step(self, samples: list[RolloutSample], teacher=None) -> dict:
        """One batch: `optim.updates_per_batch` optimizer updates; returns this rank's metric sums.

        Combine the ranks' results with `combine_rank_metrics`.
        """
        return self._run(samples, teacher, update=True)

    def evaluate(self, samples: list[RolloutSample], teacher=None) -> dict:
        """The loss and metrics of a batch without updating (replay / debugging / backend parity)."""
        return self._run(samples, teacher, update=False)

    # -- weights and checkpoints ---------------------------------------------------------------
    def full_state_dict(self) -> dict[str, torch.Tensor] | None:
        return self.backend.full_state_dict()

    def load_full_state_dict(self, state: dict[str, torch.Tensor] | None) -> None:
        self.backend.load_full_state_dict(state or {})

    def join_weight_sync(self, config: dict, world_size: int, peer_names: list[str]) -> dict[str, str] | None:
        """Rank 0 joins the private weight-sync group as its sender (blocks until every member joined);
        returns the transport the group chose and why (None on the other ranks)."""
        if self.rank != 0:
            return None
        from modeling.config_models import WeightSyncConfig
        from modeling.weight_sync import WeightSyncGroup

        device = "cuda" if self.config.device == "cuda" else "cpu"
        self._sync_group = WeightSyncGroup(0, world_size, WeightSyncConfig.model_validate(config), peer_names,
                                           device=device)
        return {"transport": self._sync_group.transport, "reason": self._sync_group.transport_reason}

    def broadcast_weights(self, version: int) -> dict[str, float] | None:
        """Every rank walks the model module by module (ZeRO-3 gathers are collective); rank 0 sends."""
        if self.rank != 0:
            for _ in self.backend.iter_full_parameters():
                pass
            return None
        group = getattr(self, "_sync_group", None)
        if group is None:
            raise RuntimeError("broadcast_weights before join_weight_sync")
        from modeling.weight_sync import manifest_from_tensors

        manifest = manifest_from_tensors(self.backend.parameter_specs(), version,
                                         int(group.config.bucket_mb * 2**20))
        return group.send(manifest, self.backend.iter_full_parameters())

    def save_rank_state(self, directory: str) -> None:
        directory = Path(directory)
        self.backend.save_state(directory)
        write_json_atomic(directory / f"rng_rank{self.rank}.json", capture_rng_state())

    def load_rank_state(self, directory: str) -> None:
        directory = Path(directory)
        self.backend.load_state(directory)
        rng_file = directory / f"rng_rank{self.rank}.json"
        restore_rng_state(read_json(rng_file), source=rng_file)
        # LearnerActor.save_checkpoint writes the version next to the rank states.
        learner_state = directory / "learner_state.json"
        if learner_state.exists():
            self.policy_version = read_json(learner_state, required={"policy_version": int})["policy_version"]

    def shutdown(self) -> None:
        self.backend.shutdown()
