"""The LearnerActor: one per run; trains the policy on batches of `RolloutSample`s.

`Learner` is a plain class (tests use it in-process); `LearnerActor = ray.remote(Learner)` is the
actor the driver creates. With `backend: torch`, or `deepspeed` with `world_size: 1`, the policy
lives inside this process. With DeepSpeed and `world_size: N > 1` the learner starts N rank actors
(`RankWorker`, one process each, torch.distributed over gloo on CPU or NCCL on GPUs) and fans
every call out to all of them: ZeRO-3 needs every rank in every forward, backward and gather.

Example:
    >>> learner = LearnerActor.options(num_cpus=1).remote(config, model_dir, seed=0)
    >>> metrics = ray.get(learner.train_step.remote(samples, teacher_outputs, step=1))
    >>> weights_ref = learner.get_weights.remote()      # pass the ref on to generators / teacher
"""

from __future__ import annotations

import socket
import time
from pathlib import Path
from typing import Any

import ray
import torch

from actors.types import RolloutSample, TeacherOutput
from learner.backends.worker import RankWorker, combine_rank_metrics
from learner.checkpoint import load_tensors, read_json, save_tensors, write_json_atomic
from learner.config_models import LearnerConfig

LEARNER_SUBDIR = "learner"


def free_port() -> int:
    """An unused TCP port on this host for a torch.distributed rendezvous."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class Learner:
    """Trains the policy: GRPO + TT-OPD losses, optimizer steps, weights out, checkpoints.

    Args:
        config: `LearnerConfig` or its dict form.
        model_dir: The initial policy (also the frozen KL reference unless
            `config.reference_model_dir` names another).
        seed: Seed for every rank.
    """

    def __init__(self, config: LearnerConfig | dict, model_dir: str, seed: int = 0):
        self.config = config if isinstance(config, LearnerConfig) else LearnerConfig.model_validate(config)
        self.model_dir = str(model_dir)
        self.seed = seed
        self._version = 0
        self._step = 0
        ws = self.config.deepspeed.world_size if self.config.backend == "deepspeed" else 1
        self.world_size = ws
        if ws == 1:
            self._local: RankWorker | None = RankWorker(self.config, self.model_dir, seed, 0, 1,
                                                        self.config.deepspeed.master_port or free_port())
            self._remote: list = []
        else:
            self._local = None
            self._remote = self._start_ranks(ws)

    def _start_ranks(self, ws: int) -> list:
        port = self.config.deepspeed.master_port or free_port()
        ds = self.config.deepspeed
        cls = ray.remote(RankWorker).options(num_cpus=ds.num_cpus_per_rank, num_gpus=ds.num_gpus_per_rank,
                                             max_restarts=0)
        workers = [cls.remote(self.config, self.model_dir, self.seed, r, ws, port) for r in range(ws)]
        # Wait for every rank: the process group forms only when all have joined. A rank that never
        # comes up is named instead of hanging the run.
        refs = [w.ready.remote() for w in workers]
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=ds.timeout_s)
        missing = [r for r, ref in enumerate(refs) if ref not in ready]
        if missing:
            for w in workers:
                ray.kill(w)
            raise TimeoutError(f"DeepSpeed rank(s) {missing} of {ws} did not start within {ds.timeout_s:.0f}s "
                               f"(rendezvous {ds.master_addr}:{port})")
        ray.get(refs)  # re-raise a rank's start-up error, if any
        return workers

    def _all(self, method: str, *args) -> list[Any]:
        """Call `method` on every rank at once (collectives need all ranks), return their results."""
        if self._local is not None:
            return [getattr(self._local, method)(*args)]
        return ray.get([getattr(w, method).remote(*args) for w in self._remote])

    # -- training ------------------------------------------------------------------------------
    def train_step(
        self,
        samples: list[RolloutSample],
        teacher: list[TeacherOutput] | dict[str, TeacherOutput] | None = None,
        step: int | None = None,
    ) -> dict[str, float]:
        """One optimizer update (or `optim.updates_per_batch`) on a batch of whole GRPO groups.

        Args:
            samples: The batch.
            teacher: Teacher outputs for the samples (list, dict by sample id, or `TeacherFetch`);
                required when `loss.distill.enabled`. May also be `[ref]`, a one-element list holding
                the Ray ref of `teacher.fetch.remote(...)`: the learner then runs its reference (and
                pi_old) forwards first and blocks on the teacher only afterwards, reporting the time
                as `teacher_wait_s`.
            step: The driver's step number, echoed into the metrics (defaults to the learner's count).

        Returns:
            Metrics: policy_loss, kl_ref_loss, distill_loss, loss, kl_ref, kl_teacher, entropy,
            clip_frac, grad_norm, logprob_diff (train minus rollout log-prob on sampled tokens),
            logprob_abs_diff, turns_truncated, turns_kept, train_tokens, distill_tokens,
            learner_s, teacher_wait_s, policy_version.
        """
        t0 = time.perf_counter()
        metrics = combine_rank_metrics(self._all("train_step", samples, teacher))
        self._step += 1
        self._version += 1
        metrics["policy_version"] = float(self._version)
        metrics["learner_step"] = float(step if step is not None else self._step)
        metrics["learner_call_s"] = time.perf_counter() - t0
        return metrics

    def evaluate_loss(
        self, samples: list[RolloutSample], teacher: list[TeacherOutput] | dict[str, TeacherOutput] | None = None
    ) -> dict[str, float]:
        """The same metrics as `train_step` without updating (replaying stored trajectories)."""
        return combine_rank_metrics(self._all("evaluate", samples, teacher))

    def policy_version(self) -> int:
        """Version of the current weights: 0 at start, +1 per `train_step`."""
        return self._version

    def step_count(self) -> int:
        return self._step

    # -- weights -------------------------------------------------------------------------------
    def get_state_dict(self) -> dict[str, torch.Tensor]:
        """Full CPU weights (ZeRO-3: gathered module by module, never the whole model at once)."""
        return self._all("full_state_dict")[0]

    get_weights = get_state_dict

    def get_weights_versioned(self) -> tuple[dict[str, torch.Tensor], int]:
        return self.get_state_dict(), self._version

    def set_weights(self, state: dict[str, torch.Tensor]) -> None:
        """Overwrite the policy weights (the optimizer state is kept)."""
        self._all("load_full_state_dict", state)

    def join_weight_sync(self, config: dict, world_size: int, peer_names: list[str]) -> None:
        """Join a collective weight-sync group as its sender (call while the receivers join theirs).

        Args:
            config: `WeightSyncConfig` fields (backend, bucket_mb, timeout_s, master_addr, master_port).
            world_size: 1 + number of receivers.
            peer_names: Readable names for error messages, rank 0 (this learner) first.
        """
        self._all("join_weight_sync", dict(config), world_size, list(peer_names))

    def broadcast_weights(self) -> dict[str, float]:
        """Send the current weights (version = policy_version) through the group; receivers call
        `WeightSyncGroup.receive_into(model, version)` at the same time."""
        results = self._all("broadcast_weights", self._version)
        out = dict(results[0])
        out["version"] = float(self._version)
        return out

    # -- checkpoints ---------------------------------------------------------------------------
    def save_checkpoint(self, directory: str) -> str:
        """Write weights (safetensors), optimizer and RNG states of every rank, step and version.

        Args:
            directory: The step's checkpoint directory; the learner writes `directory/learner/`.

        Returns:
            The learner subdirectory written.
        """
        out = Path(directory) / LEARNER_SUBDIR
        out.mkdir(parents=True, exist_ok=True)
        weights = self.get_state_dict()
        save_tensors(out / "model.safetensors", weights, metadata={"policy_version": str(self._version)})
        self._all("save_rank_state", str(out))
        write_json_atomic(out / "learner_state.json", {
            "step": self._step, "policy_version": self._version, "backend": self.config.backend,
            "world_size": self.world_size, "model_dir": self.model_dir,
        })
        return str(out)

    def load_checkpoint(self, directory: str) -> dict[str, int]:
        """Restore what `save_checkpoint` wrote (safetensors and weights-only loading only).

        Raises:
            ValueError: If the checkpoint was written by another backend or world size.
        """
        src = Path(directory) / LEARNER_SUBDIR
        meta = read_json(src / "learner_state.json")
        if meta["backend"] != self.config.backend or meta["world_size"] != self.world_size:
            raise ValueError(
                f"checkpoint {src} was written by backend={meta['backend']} world_size={meta['world_size']}, "
                f"this learner runs backend={self.config.backend} world_size={self.world_size}"
            )
        weights = load_tensors(src / "model.safetensors")
        self._all("load_full_state_dict", weights)
        self._all("load_rank_state", str(src))
        self._step = int(meta["step"])
        self._version = int(meta["policy_version"])
        return {"step": self._step, "policy_version": self._version}

    def shutdown(self) -> None:
        self._all("shutdown")
        if self._remote:
            for w in self._remote:
                ray.kill(w)
            self._remote = []


# The Ray actor the driver creates; options (num_cpus, max_restarts) are the caller's choice.
LearnerActor = ray.remote(Learner)
