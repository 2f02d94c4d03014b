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

from actors.types import PendingTeacherBatch, RolloutSample, TeacherBatch
from learner.backends.worker import RankWorker, combine_rank_metrics
from modeling.checkpoint import read_json, write_json_atomic
from modeling.hf_checkpoint import DEFAULT_MAX_SHARD_SIZE, read_checkpoint_tensors, save_sharded_checkpoint
from modeling.config_models import LearnerConfig
from learner.placement import (
    ActorDemand,
    NodeAddress,
    RankPlacement,
    bundle_scheduling,
    bundle_nodes,
    check_cluster_fits,
    create_placement_group,
    current_node_id,
    node_address,
    rank_bundle,
    remove_placement_group_quietly,
    wait_all_ready,
)

LEARNER_SUBDIR = "learner"
POLICY_SUBDIR = "policy"  # learner/policy/: the policy weights as a Hugging Face checkpoint


def free_port() -> int:
    """An unused TCP port on this host (single-host rendezvous; across nodes see `Learner.rendezvous_address`)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class RankActor(RankWorker):
    """A `RankWorker` started in two phases, so rank 0's address is known before any rank joins.

    Ray places the actor (its constructor does nothing heavy), the learner asks every rank where it
    runs (`address`: rank 0's node IP and a port free there), and only then `start` builds the
    backend, which joins torch.distributed at rank 0's address. Inherits every RankWorker method.
    """

    def __init__(self, rank: int) -> None:
        self.rank = rank

    def address(self, port: int | None = None) -> dict:
        """This rank's node id and IP, and `port` (or one free on this node)."""
        return node_address(port).model_dump()

    def start(self, config: LearnerConfig, model_dir: str, seed: int, world_size: int, master_port: int) -> int:
        RankWorker.__init__(self, config, model_dir, seed, self.rank, world_size, master_port)
        return self.rank


class Learner:
    """Trains the policy: GRPO + TT-OPD losses, optimizer steps, weights out, checkpoints.

    Args:
        config: `LearnerConfig` or its dict form.
        model_dir: The initial policy (also the frozen KL reference unless
            `config.reference_model_dir` names another).
        seed: Seed for every rank.
        placement: Where the DeepSpeed rank actors go (placement group strategy, custom resources,
            timeouts; `learner.placement.RankPlacement` or its dict form). Default: PACK, CPUs and
            GPUs from `config.deepspeed`, resources checked against the cluster first.
    """

    def __init__(self, config: LearnerConfig | dict, model_dir: str, seed: int = 0,
                 placement: RankPlacement | dict | None = None):
        self.config = config if isinstance(config, LearnerConfig) else LearnerConfig.model_validate(config)
        self.model_dir = str(model_dir)
        self.seed = seed
        self.placement = RankPlacement.model_validate(placement or {})
        self._placement_group = None
        self.rank_nodes: list[str] = []  # Ray node id of each rank
        self._version = 0
        self._step = 0
        ws = self.config.deepspeed.world_size if self.config.backend == "deepspeed" else 1
        self.world_size = ws
        if ws == 1:
            self._local: RankWorker | None = RankWorker(self.config, self.model_dir, seed, 0, 1,
                                                        self.config.deepspeed.master_port or free_port())
            self._remote: list = []
            self.rank_nodes = [current_node_id()]
        else:
            self._local = None
            self._remote = self._start_ranks(ws)

    def _start_ranks(self, ws: int) -> list:
        """Place the ranks (one placement-group bundle each), then start them at rank 0's address.

        Fails at once, naming what is missing, when the cluster cannot hold the ranks; when a rank
        raises while starting, fails with that rank's error as soon as it arrives (the other ranks,
        blocked in the rendezvous, are killed rather than waited for).
        """
        ds, spec = self.config.deepspeed, self.placement
        if not ray.is_initialized():
            from envs._runtime import init_ray

            # RAY_ADDRESS's cluster, else a local one on loopback (Ray's own auto-init binds all interfaces)
            init_ray()
        bundle = rank_bundle(self.config, spec.resources)
        if spec.check_resources:
            check_cluster_fits([ActorDemand(name="learner rank", count=ws, resources=bundle)],
                               {"learner rank": spec.strategy})
        self._placement_group = create_placement_group([bundle] * ws, spec.strategy, spec.placement_timeout_s,
                                                       f"learner ranks (world size {ws})")
        cls = ray.remote(RankActor)
        workers = [
            cls.options(num_cpus=ds.num_cpus_per_rank, num_gpus=ds.num_gpus_per_rank,
                        resources=dict(spec.resources) or None, max_restarts=0,
                        scheduling_strategy=bundle_scheduling(self._placement_group, r)).remote(r)
            for r in range(ws)
        ]
        names = [f"DeepSpeed rank {r}" for r in range(ws)]
        try:
            placed = wait_all_ready({n: w.address.remote(ds.master_port) for n, w in zip(names, workers)},
                                    spec.startup_timeout_s, "learner ranks (placing)")
            rank0 = NodeAddress.model_validate(placed[names[0]])
            self.rank_nodes = [placed[n]["node_id"] for n in names]
            # torch.distributed's store is served by rank 0: every rank connects to rank 0's node.
            config = self.config.model_copy(update={"deepspeed": ds.model_copy(
                update={"master_addr": rank0.ip, "master_port": rank0.port})})
            # The clock starts now that every rank process exists; it covers building the model.
            wait_all_ready({n: w.start.remote(config, self.model_dir, self.seed, ws, rank0.port)
                            for n, w in zip(names, workers)},
                           spec.startup_timeout_s, f"learner ranks (rendezvous {rank0.ip}:{rank0.port})")
        except BaseException:
            for w in workers:
                ray.kill(w)
            remove_placement_group_quietly(self._placement_group)
            self._placement_group = None
            raise
        self.config = config
        return workers

    def rendezvous_address(self) -> dict:
        """Where collective groups led by this learner meet: rank 0's node IP and a port free there.

        The weight-sync group's store is served by learner rank 0, so generators and the teacher,
        on whatever node, connect to this address (a `learner.placement.NodeAddress` as a dict).
        """
        if self._local is not None:
            return node_address().model_dump()
        return ray.get(self._remote[0].address.remote())

    def placement_report(self) -> dict[str, list]:
        """Where the ranks run: `rank_nodes` (Ray node id per rank, as each rank reported it),
        `bundle_nodes` (the node of each placement-group bundle; empty without a group) and
        `learner_node` (this actor's node: with several ranks it only fans calls out, but losing it
        stops the run too)."""
        bundles = bundle_nodes(self._placement_group) if self._placement_group is not None else []
        return {"rank_nodes": list(self.rank_nodes), "bundle_nodes": bundles, "learner_node": current_node_id()}

    def _all(self, method: str, *args) -> list[Any]:
        """Call `method` on every rank at once (collectives need all ranks), return their results."""
        if self._local is not None:
            return [getattr(self._local, method)(*args)]
        return ray.get([getattr(w, method).remote(*args) for w in self._remote])

    # -- training ------------------------------------------------------------------------------
    def train_step(
        self,
        samples: list[RolloutSample],
        teacher: TeacherBatch | PendingTeacherBatch | None = None,
        step: int | None = None,
    ) -> dict[str, float]:
        """One optimizer update (or `optim.updates_per_batch`) on a batch of whole GRPO groups.

        Args:
            samples: The batch.
            teacher: The teacher's outputs for the samples (`TeacherBatch`), required when
                `loss.distill.enabled`; or `PendingTeacherBatch(teacher.fetch.remote(...))`: the
                learner then runs its reference (and pi_old) forwards first and blocks on the teacher
                only afterwards, reporting the time as `teacher_wait_s`.
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
        self, samples: list[RolloutSample], teacher: TeacherBatch | None = None
    ) -> dict[str, float]:
        """The same metrics as `train_step` without updating (replaying stored trajectories)."""
        return combine_rank_metrics(self._all("evaluate", samples, teacher))

    def policy_version(self) -> int:
        """Version of the current weights: 0 at start, +1 per `train_step`."""
        return self._version

    # -- weights -------------------------------------------------------------------------------
    def get_state_dict(self) -> dict[str, torch.Tensor]:
        """Full CPU weights (ZeRO-3: gathered module by module, never the whole model at once).

        Keyed by the checkpoint architecture's parameter names (`model.language_model.*` for Qwen3.5),
        a tied `lm_head.weight` included."""
        return self._all("full_state_dict")[0]

    get_weights = get_state_dict

    def set_weights(self, state: dict[str, torch.Tensor]) -> None:
        """Overwrite the policy weights (the optimizer state is kept)."""
        self._all("load_full_state_dict", state)

    def join_weight_sync(self, config: dict, world_size: int, peer_names: list[str]) -> dict[str, str]:
        """Join a collective weight-sync group as its sender (call while the receivers join theirs).

        Args:
            config: `WeightSyncConfig` fields (backend, bucket_mb, timeout_s, master_addr, master_port).
            world_size: 1 + number of receivers.
            peer_names: Readable names for error messages, rank 0 (this learner) first.

        Returns:
            {"transport": "nccl" | "gloo-cpu-staged", "reason": ...}: what the members' devices chose.
        """
        return self._all("join_weight_sync", dict(config), world_size, list(peer_names))[0]

    def broadcast_weights(self) -> dict[str, float]:
        """Send the current weights (version = policy_version) through the group; receivers call
        `WeightSyncGroup.receive_into(model, version)` at the same time."""
        results = self._all("broadcast_weights", self._version)
        out = dict(results[0])
        out["version"] = float(self._version)
        return out

    # -- checkpoints ---------------------------------------------------------------------------
    def save_checkpoint(self, directory: str, max_shard_size: str | int = DEFAULT_MAX_SHARD_SIZE) -> str:
        """Write weights, optimizer and RNG states of every rank, step and version.

        The policy weights go to `directory/learner/policy/` as a Hugging Face checkpoint (sharded
        safetensors + index, config and tokenizer of the initial model), which
        `transformers.AutoModel*.from_pretrained`, vLLM and `model.path` load unchanged.

        Args:
            directory: The step's checkpoint directory; the learner writes `directory/learner/`.
            max_shard_size: Shard limit of the policy weights ('5GB', '400KB', bytes).

        Returns:
            The learner subdirectory written.
        """
        out = Path(directory) / LEARNER_SUBDIR
        out.mkdir(parents=True, exist_ok=True)
        weights = self.get_state_dict()
        save_sharded_checkpoint(out / POLICY_SUBDIR, weights, source_dir=self.model_dir, max_shard_size=max_shard_size,
                                metadata={"policy_version": str(self._version)})
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
        meta = read_json(src / "learner_state.json", required={"step": int, "policy_version": int, "backend": str,
                                                               "world_size": int})
        if meta["backend"] != self.config.backend or meta["world_size"] != self.world_size:
            raise ValueError(
                f"checkpoint {src} was written by backend={meta['backend']} world_size={meta['world_size']}, "
                f"this learner runs backend={self.config.backend} world_size={self.world_size}"
            )
        weights = read_checkpoint_tensors(src / POLICY_SUBDIR)
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
        if self._placement_group is not None:
            remove_placement_group_quietly(self._placement_group)
            self._placement_group = None


# The Ray actor the driver creates; options (num_cpus, max_restarts) are the caller's choice.
LearnerActor = ray.remote(Learner)
