"""The EMA teacher of TT-OPD: hint-conditioned log-probs for finished trajectories, served asynchronously.

For each finished trajectory the teacher builds its privileged context (Eq. 2, s_t^+): the very
same token sequence with an outcome-conditioned hint inserted at the prompt-response boundary,
a reinforcing hint for a correct trajectory and a corrective one for an incorrect trajectory.
It returns the log-probs of exactly the student's generated tokens of every assistant turn,
mapped back to the student's positions, so the hint tokens never appear in the output
(`TeacherOutput.logprobs[p]` is about `sample.input_ids[p]`).

Asynchrony: `submit(samples)` enqueues and returns at once; a background thread computes in
batches while generation goes on; `fetch(sample_ids, timeout_s)` returns the results (computing
the requested ones first) and reports how long the caller waited. `score(samples)` is the
synchronous form. The weights follow the student by EMA (theta_T <- alpha*theta_T +
(1-alpha)*theta_S every `ema_interval` steps) with a hard copy every `hard_copy_interval` steps.

Example:
    >>> teacher = TeacherActor.options(num_cpus=0).remote(config, model_dir)
    >>> teacher.submit.remote(group_samples)                   # as each group finishes
    >>> got = ray.get(teacher.fetch.remote([s.sample_id for s in batch], 60.0))
    >>> if teacher_update_action(step, config) != "none":
    ...     teacher.update.remote(learner.get_weights.remote(), step)
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from pathlib import Path
from typing import Any

import ray
import torch
from pydantic import BaseModel, ConfigDict

from actors.types import RolloutSample, TeacherBatch, TeacherOutput
from modeling.checkpoint import load_tensors, read_json, save_tensors, write_json_atomic
from modeling.config_models import TeacherConfig, teacher_update_action
from modeling.model import (IM_START, load_policy, pad_batch, packing_unsupported, packs_sequences, split_batches,
                            token_stats)

GENERATION_PROMPT = f"{IM_START}assistant\n"


class TeacherContext(BaseModel):
    """A sample's teacher context and how its positions map back to the student's."""

    model_config = ConfigDict(extra="forbid")
    input_ids: list[int]
    hint: str
    insert_at: int        # student position where the hint tokens were inserted
    hint_tokens: int      # student position p >= insert_at is teacher position p + hint_tokens


class Teacher:
    """Holds the EMA teacher weights and serves hint-conditioned, position-aligned log-probs.

    Args:
        config: `TeacherConfig` (or its dict form).
        model_dir: Initial weights (theta_T <- theta_S at start, Algorithm 1 line 1) and tokenizer.
        seed: Seed (the teacher samples nothing; kept for symmetry and future use).
        start_worker: Start the background thread (tests of `build_context` may skip it).
    """

    def __init__(self, config: TeacherConfig | dict, model_dir: str, seed: int = 0, *, start_worker: bool = True):
        self.config = config if isinstance(config, TeacherConfig) else TeacherConfig.model_validate(config)
        torch.manual_seed(seed)
        dtype = torch.bfloat16 if self.config.dtype == "bfloat16" else torch.float32
        self.model, self.tokenizer = load_policy(model_dir, dtype=dtype)
        self.model.to(self.config.device).requires_grad_(False)
        self.pad_id = self.tokenizer.pad_token_id if self.tokenizer.pad_token_id is not None else 0
        # Forwards on real tokens only where the model's layers allow it (modeling.model.packing_unsupported).
        unsupported = packing_unsupported(self.model) if self.config.pack_sequences is True else None
        if unsupported:
            print(f"[teacher] teacher.pack_sequences: {unsupported}", flush=True)
        # EMA in fp32: alpha = 0.995 moves bf16 weights by less than their rounding step. The shadow
        # lives on the teacher's device or in host memory (ema_shadow_device); EMA and hard copies act on
        # it where it is and copy the result into the model's weights.
        self._shadow: dict[str, torch.Tensor] | None = None
        if dtype != torch.float32:
            where = self.shadow_device
            self._shadow = {k: v.detach().to(device=where, dtype=torch.float32, copy=True)
                            for k, v in self.model.state_dict().items()}
        self._version = 0
        self._history: list[dict[str, Any]] = []
        hints = self.config.hints
        self._hint_ids = {
            "reinforcing": self._encode(hints.template.format(hint=hints.reinforcing)),
            "corrective": self._encode(hints.template.format(hint=hints.corrective)),
        }
        self._gen_prompt_ids = self._encode(GENERATION_PROMPT)
        # Request bookkeeping: pending (oldest first, with its neighbours in length under batch_order: length;
        # requested ids jump the queue), done, failed.
        self._cv = threading.Condition()
        self._weights_lock = threading.RLock()
        self._pending: OrderedDict[str, RolloutSample] = OrderedDict()
        self._wanted: set[str] = set()
        self._done: dict[str, TeacherOutput] = {}
        self._failed: dict[str, str] = {}
        self._in_flight: set[str] = set()
        self._stop = False
        self._stats = {"computed": 0, "compute_s": 0.0, "fetch_wait_s": 0.0, "fetches": 0}
        self._thread = None
        if start_worker:
            self._thread = threading.Thread(target=self._worker, name="teacher-worker", daemon=True)
            self._thread.start()

    @property
    def shadow_device(self) -> torch.device:
        """Where the fp32 EMA shadow is (or would be) kept: the model's device or the CPU."""
        return torch.device("cpu") if self.config.ema_shadow_device == "cpu" else torch.device(self.config.device)

    def _encode(self, text: str) -> list[int]:
        return list(self.tokenizer.encode(text, add_special_tokens=False))

    # -- the privileged context ----------------------------------------------------------------
    def hint_kind(self, sample: RolloutSample) -> str:
        """"reinforcing" / "corrective" per the configured correctness rule, "none" when hints are off."""
        h = self.config.hints
        if not h.enabled:
            return "none"
        if h.correctness_rule == "correct_flag":
            correct = sample.correct
        else:
            correct = sample.reward > h.reward_threshold
        return "reinforcing" if correct else "corrective"

    def build_context(self, sample: RolloutSample) -> TeacherContext:
        """prompt + hint + response, with the hint before the prompt's generation header if present.

        The hint goes between the last prompt turn and `<|im_start|>assistant\\n` when the prompt ends
        with that header (so the ChatML layout stays valid), else exactly at `prompt_length`.
        """
        kind = self.hint_kind(sample)
        ids = list(sample.input_ids)
        if kind == "none":
            return TeacherContext(input_ids=ids, hint="none", insert_at=sample.prompt_length, hint_tokens=0)
        hint = self._hint_ids[kind]
        at = sample.prompt_length
        g = self._gen_prompt_ids
        if self.config.hints.before_generation_prompt and at >= len(g) and ids[at - len(g):at] == g:
            at -= len(g)
        return TeacherContext(input_ids=ids[:at] + hint + ids[at:], hint=kind, insert_at=at, hint_tokens=len(hint))

    # -- computing -------------------------------------------------------------------------------
    def compute(self, samples: list[RolloutSample]) -> list[TeacherOutput]:
        """Teacher log-probs for `samples` now (batched, by `batch_order`), in the order of `samples`,
        aligned to each student's positions."""
        contexts = [self.build_context(s) for s in samples]
        lengths = [len(c.input_ids) for c in contexts]
        results: list[TeacherOutput | None] = [None] * len(samples)
        for group in split_batches(self.config.batch_order, list(range(len(samples))), lengths,
                                   self.config.batch_size, self.config.max_tokens_per_batch):
            outs = self._compute_batch([samples[i] for i in group], [contexts[i] for i in group])
            for i, out in zip(group, outs):
                results[i] = out
        return results

    def _compute_batch(self, samples: list[RolloutSample], contexts: list | None = None) -> list[TeacherOutput]:
        t0 = time.perf_counter()
        contexts = contexts if contexts is not None else [self.build_context(s) for s in samples]
        ids, mask = pad_batch([c.input_ids for c in contexts], self.pad_id, side="right")
        # Only the student's trained tokens are served (below): the LM head runs on those alone, at
        # their positions in the teacher's context (shifted by the hint).
        wanted = torch.zeros_like(mask, dtype=torch.bool)
        for b, (s, c) in enumerate(zip(samples, contexts)):
            for p, m in enumerate(s.loss_mask):
                if m:
                    wanted[b, p + (c.hint_tokens if p >= c.insert_at else 0)] = True
        dev = self.config.device
        k = self.config.serve_topk
        packed = packs_sequences(self.config.pack_sequences, self.model, mask)
        with self._weights_lock, torch.no_grad():
            version = self._version
            stats = token_stats(self.model, ids.to(dev), mask.to(dev), temperature=self.config.temperature,
                                topk=k, chunk_size=self.config.logprob_chunk_size, positions=wanted.to(dev),
                                packed=packed)
        lp = stats.logprobs.cpu()
        tk_lp = stats.topk_logprobs.cpu() if k else None
        tk_id = stats.topk_ids.cpu() if k else None
        elapsed = time.perf_counter() - t0
        outs = []
        for b, (s, c) in enumerate(zip(samples, contexts)):
            n = len(s.input_ids)
            # Student position p -> teacher position p + shift (p is after the insertion point).
            positions = [p for p in range(n) if s.loss_mask[p]]
            if positions and positions[0] < c.insert_at:
                raise ValueError(f"sample {s.sample_id!r} has a loss-mask token at {positions[0]}, inside the "
                                 f"prompt (prompt_length={s.prompt_length})")
            shift = c.hint_tokens
            row = [0.0] * n
            idx = torch.tensor(positions, dtype=torch.long) + shift
            vals = lp[b, idx].tolist() if positions else []
            for p, v in zip(positions, vals):
                row[p] = v
            topk_ids = topk_lp = None
            if k:
                topk_ids = [[] for _ in range(n)]
                topk_lp = [[] for _ in range(n)]
                if positions:
                    ids_rows = tk_id[b, idx].tolist()
                    lp_rows = tk_lp[b, idx].tolist()
                    for p, ir, lr in zip(positions, ids_rows, lp_rows):
                        topk_ids[p] = ir
                        topk_lp[p] = lr
            length = len(c.input_ids)
            computed = length if packed else int(mask.shape[1])
            outs.append(TeacherOutput(sample_id=s.sample_id, teacher_version=version, hint=c.hint,
                                      hint_tokens=c.hint_tokens, input_length=n, logprobs=row,
                                      topk_ids=topk_ids, topk_logprobs=topk_lp,
                                      compute_s=elapsed / len(samples), computed_positions=computed,
                                      padded_positions=computed - length))
        return outs

    def score(self, samples: list[RolloutSample]) -> list[TeacherOutput]:
        """Synchronous scoring (a caller that queues Ray calls gets asynchrony from Ray's call queue)."""
        return self.compute(samples)

    # -- asynchronous service --------------------------------------------------------------------
    def submit(self, samples: list[RolloutSample]) -> int:
        """Queue samples for scoring and return at once; returns the number of queued samples.

        Re-submitting a sample id that is pending or done is a no-op (a restarted driver may resend).
        """
        with self._cv:
            for s in samples:
                if s.sample_id in self._done or s.sample_id in self._pending or s.sample_id in self._in_flight:
                    continue
                self._failed.pop(s.sample_id, None)
                self._pending[s.sample_id] = s
            self._cv.notify_all()
            return len(self._pending)

    def fetch(self, sample_ids: list[str], timeout_s: float | None = None) -> TeacherBatch:
        """Results for `sample_ids` in that order, waiting for those still being computed.

        Fetched results are removed from the teacher (each is consumed once).

        Raises:
            KeyError: An id was never submitted.
            TimeoutError: Results were still missing after `timeout_s` (names them).
            RuntimeError: Scoring of a requested sample failed (names it and the error).
        """
        t0 = time.perf_counter()
        deadline = None if timeout_s is None else t0 + timeout_s
        with self._cv:
            unknown = [i for i in sample_ids if i not in self._done and i not in self._pending
                       and i not in self._in_flight and i not in self._failed]
            if unknown:
                raise KeyError(f"teacher.fetch: never submitted (or already fetched): {unknown[:5]}")
            self._wanted.update(sample_ids)
            self._cv.notify_all()
            while True:
                failed = [i for i in sample_ids if i in self._failed]
                if failed:
                    msg = self._failed[failed[0]]
                    self._wanted.difference_update(sample_ids)
                    raise RuntimeError(f"teacher scoring failed for {failed[:5]}: {msg}")
                missing = [i for i in sample_ids if i not in self._done]
                if not missing:
                    break
                remaining = None if deadline is None else deadline - time.perf_counter()
                if remaining is not None and remaining <= 0:
                    self._wanted.difference_update(sample_ids)
                    raise TimeoutError(f"teacher.fetch: {len(missing)} result(s) not ready after {timeout_s}s: "
                                       f"{missing[:5]}")
                self._cv.wait(timeout=remaining)
            outputs = [self._done.pop(i) for i in sample_ids]
            self._wanted.difference_update(sample_ids)
            wait = time.perf_counter() - t0
            self._stats["fetch_wait_s"] += wait
            self._stats["fetches"] += 1
        return TeacherBatch(outputs=outputs, wait_s=wait)

    def _take_batch(self) -> list[RolloutSample]:
        """Up to batch_size pending samples (and max_tokens_per_batch of their tokens), the ones a caller is
        waiting for first (call under the lock). By length (`batch_order`): among those waited for (else
        all pending), the oldest with the ones nearest it in length, so no sample waits behind a stream
        of others while the forward pads little."""
        first = [i for i in self._pending if i in self._wanted]
        rest = [i for i in self._pending if i not in self._wanted]
        order = first + rest
        if self.config.batch_order == "length":
            order = first or rest
        lengths = [len(self._pending[i].input_ids) for i in order]
        groups = split_batches(self.config.batch_order, list(range(len(order))), lengths, self.config.batch_size,
                               self.config.max_tokens_per_batch)
        chosen = [order[k] for k in next(g for g in groups if 0 in g)]
        batch = [self._pending.pop(i) for i in chosen]
        self._in_flight.update(chosen)
        return batch

    def _worker(self) -> None:
        while True:
            with self._cv:
                while not self._pending and not self._stop:
                    self._cv.wait()
                if self._stop:
                    return
                batch = self._take_batch()
            t0 = time.perf_counter()
            try:
                outs = self._compute_batch(batch)
                error = None
            except Exception as exc:  # noqa: BLE001  (reported to the fetching caller, with the sample ids)
                outs, error = [], f"{type(exc).__name__}: {exc}"
            with self._cv:
                for s in batch:
                    self._in_flight.discard(s.sample_id)
                if error is not None:
                    for s in batch:
                        self._failed[s.sample_id] = error
                for o in outs:
                    self._done[o.sample_id] = o
                self._stats["computed"] += len(outs)
                self._stats["compute_s"] += time.perf_counter() - t0
                self._cv.notify_all()

    def pending(self) -> int:
        with self._cv:
            return len(self._pending) + len(self._in_flight)

    def stats(self) -> dict[str, float]:
        with self._cv:
            return {**self._stats, "queued": float(len(self._pending) + len(self._in_flight)),
                    "ready": float(len(self._done)), "teacher_version": float(self._version)}

    # -- weights ---------------------------------------------------------------------------------
    def teacher_version(self) -> int:
        return self._version

    def _check_keys(self, weights: dict[str, torch.Tensor]) -> None:
        """Student weights may be a subset of the teacher's names (a frozen vision tower left out of a
        sync, a tied lm_head.weight skipped), never a name the teacher does not have."""
        own = set(self.model.state_dict())
        extra = sorted(set(weights) - own)
        if extra:
            raise ValueError(f"student weights do not match the teacher ({type(self.model).__name__}): unknown "
                             f"name(s) {extra[:5]}{' ...' if len(extra) > 5 else ''}")
        if not weights:
            raise ValueError("student weights are empty")

    def ema_update(self, weights: dict[str, torch.Tensor], alpha: float | None = None) -> dict[str, Any]:
        """theta_T <- alpha * theta_T + (1 - alpha) * theta_S, for every tensor of the state dict."""
        a = self.config.ema_alpha if alpha is None else alpha
        if not 0.0 <= a <= 1.0:
            raise ValueError(f"EMA alpha must be in [0, 1], got {a}")
        self._check_keys(weights)
        with self._weights_lock, torch.no_grad():
            state = self.model.state_dict()
            seen: set[int] = set()
            for name, target in (self._shadow or state).items():
                if name not in weights:  # not sent (a subset): keeps its value
                    continue
                if target.data_ptr() in seen:  # a tied tensor listed under two names: update it once
                    continue
                seen.add(target.data_ptr())
                src = weights[name].to(device=target.device, dtype=target.dtype)
                target.lerp_(src, 1.0 - a)  # target + (1-a)(src - target) = a*target + (1-a)*src
                if self._shadow is not None:
                    state[name].copy_(target)
            self._version += 1
        return self._record("ema", alpha=a)

    def hard_copy(self, weights: dict[str, torch.Tensor]) -> dict[str, Any]:
        """theta_T <- theta_S."""
        self._check_keys(weights)
        with self._weights_lock, torch.no_grad():
            state = self.model.state_dict()
            for name, target in state.items():
                if name not in weights:  # not sent (a subset): keeps its value
                    continue
                target.copy_(weights[name].to(device=target.device, dtype=target.dtype))
                if self._shadow is not None:
                    self._shadow[name].copy_(weights[name].float())
            self._version += 1
        return self._record("hard_copy")

    def update(self, weights: dict[str, torch.Tensor] | None, step: int) -> dict[str, Any]:
        """Apply the schedule after learner step `step`: hard copy, EMA, or nothing.

        Returns:
            {"action": "hard_copy" | "ema" | "none", "step": step, "teacher_version": int}.
        """
        action = teacher_update_action(step, self.config)
        if action == "none":
            return {"action": "none", "step": step, "teacher_version": self._version}
        if weights is None:
            raise ValueError(f"teacher.update at step {step} needs the student's weights for a {action}")
        out = self.ema_update(weights) if action == "ema" else self.hard_copy(weights)
        out["step"] = step
        self._history[-1]["step"] = step
        return out

    def adopt(self, weights: dict[str, torch.Tensor], version: int) -> dict[str, Any]:
        """theta_T <- theta_S at the driver's confirmed `version`: how a restarted teacher is recovered
        when no EMA snapshot is kept (collective weight sync keeps none in the object store)."""
        self.hard_copy(weights)
        with self._weights_lock:
            self._version = int(version)
            self._history[-1].update(action="adopt", teacher_version=self._version)
        return dict(self._history[-1])

    def join_weight_sync(self, config: dict, rank: int, world_size: int, peer_names: list[str]) -> None:
        """Join the learner's collective weight-sync group as a receiver (GPU path)."""
        from modeling.config_models import WeightSyncConfig
        from modeling.weight_sync import WeightSyncGroup

        self._sync_group = WeightSyncGroup(rank, world_size, WeightSyncConfig.model_validate(config), peer_names,
                                           device=self.config.device)

    def receive_update(self, version: int, step: int) -> dict[str, Any]:
        """Apply the step's scheduled update from weights streamed bucket by bucket.

        The driver's collective weight sync includes the teacher in every broadcast (one group for
        the generators and the teacher), so this is called at every step: at "none" steps the stream
        is drained and dropped. EMA and hard copy act on each tensor as its bucket arrives, directly
        on the fp32 weights (the model's own when it is fp32, else the fp32 master): no full state
        dict and no second fp32 copy. Every streamed name must be a teacher weight; names not sent
        (a frozen vision tower) keep their values; a tied tensor sent under two names moves once.

        Returns:
            {"action", "step", "teacher_version", "bytes"} (bytes received).
        """
        group = getattr(self, "_sync_group", None)
        if group is None:
            raise RuntimeError("receive_update before join_weight_sync")
        action = teacher_update_action(step, self.config)
        received = 0
        if action == "none":  # outside the weights lock: scoring goes on while the stream drains
            for name, tensor in group.receive(version):
                received += tensor.numel() * tensor.element_size()
            return {"action": "none", "step": step, "teacher_version": self._version, "bytes": float(received)}
        a = self.config.ema_alpha
        with self._weights_lock, torch.no_grad():
            state = self.model.state_dict()
            targets = self._shadow or state
            seen: set[int] = set()
            for name, tensor in group.receive(version):
                if name not in targets:
                    raise ValueError(f"streamed tensor {name!r} is not a teacher weight "
                                     f"({type(self.model).__name__})")
                received += tensor.numel() * tensor.element_size()
                target = targets[name]
                if target.data_ptr() in seen:  # tied: the same storage under a second name
                    continue
                seen.add(target.data_ptr())
                src = tensor.to(device=target.device, dtype=target.dtype)  # no copy when already fp32
                if action == "ema":
                    target.lerp_(src, 1.0 - a)
                else:
                    target.copy_(src)
                if self._shadow is not None:
                    state[name].copy_(target)
            self._version += 1
        out = self._record(action, **({"alpha": a} if action == "ema" else {}))
        self._history[-1]["step"] = step
        out["step"] = step
        out["bytes"] = float(received)
        return out

    def _record(self, action: str, **extra) -> dict[str, Any]:
        entry = {"action": action, "teacher_version": self._version, **extra}
        self._history.append(entry)
        return dict(entry)

    def history(self) -> list[dict[str, Any]]:
        return list(self._history)

    def get_weights(self) -> dict[str, torch.Tensor]:
        with self._weights_lock:
            src = self._shadow or self.model.state_dict()
            return {k: v.detach().to("cpu", copy=True) for k, v in src.items()}

    # -- fault recovery and checkpoints ---------------------------------------------------------------
    def get_state(self) -> dict[str, Any]:
        """Weights (fp32 EMA master if kept) and version, for restoring a restarted teacher."""
        return {"weights": self.get_weights(), "version": self._version, "history": self.history()}

    def set_state(self, state: dict[str, Any]) -> None:
        weights = state["weights"]
        self._check_keys(weights)
        with self._weights_lock, torch.no_grad():
            model_state = self.model.state_dict()
            for name, target in model_state.items():
                target.copy_(weights[name].to(device=target.device, dtype=target.dtype))
                if self._shadow is not None:
                    self._shadow[name].copy_(weights[name].float())
            self._version = int(state["version"])
            self._history = list(state.get("history", []))

    def save(self, directory: str) -> str:
        """Write `directory/teacher/` (safetensors weights + JSON state)."""
        out = Path(directory) / "teacher"
        save_tensors(out / "teacher.safetensors", self.get_weights())
        write_json_atomic(out / "teacher_state.json", {"version": self._version, "history": self._history})
        return str(out)

    def load(self, directory: str) -> None:
        src = Path(directory) / "teacher"
        meta = read_json(src / "teacher_state.json", required={"version": int})
        self.set_state({"weights": load_tensors(src / "teacher.safetensors"), "version": meta["version"],
                        "history": meta.get("history", [])})

    def shutdown(self) -> None:
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=10)


# A threaded actor: `fetch` may block while `submit` and `update` calls keep arriving.
TeacherActor = ray.remote(max_concurrency=4)(Teacher)
