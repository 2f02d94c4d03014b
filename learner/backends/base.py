"""The backend contract: model, reference, backward, optimizer step, full weights, checkpoint state.

A backend owns the trainable policy (and its optimizer) for one rank. The shared `RankWorker`
(worker.py) builds batches, calls `token_stats` on `forward_module`, computes the loss and calls
`backward` / `step`. Everything that differs between single-process torch and ZeRO-3 sits behind
this interface.
"""

from __future__ import annotations

import contextlib
from abc import ABC, abstractmethod
from collections.abc import Iterator
from pathlib import Path

import torch

from modeling.config_models import LearnerConfig

DTYPES = {"float32": torch.float32, "bfloat16": torch.bfloat16}


class LearnerBackend(ABC):
    """One rank's policy, optimizer and frozen reference.

    Args:
        config: Learner settings.
        model_dir: Checkpoint folder (config.json + sharded or single safetensors) or a cached hub id.
        seed: Seed for this rank's RNGs.
        rank: Data-parallel rank.
        world_size: Number of ranks.
    """

    name: str = "base"

    def __init__(self, config: LearnerConfig, model_dir: str, seed: int, rank: int = 0, world_size: int = 1):
        self.config = config
        self.model_dir = str(model_dir)
        self.seed = seed
        self.rank = rank
        self.world_size = world_size

    # -- model access ------------------------------------------------------------------------
    @property
    @abstractmethod
    def policy(self) -> torch.nn.Module:
        """The trainable module to run forward passes on (the HF causal LM)."""

    @property
    @abstractmethod
    def reference(self) -> torch.nn.Module | None:
        """The frozen reference model for KL_ref, or None when kl_beta is 0."""

    @property
    def device(self) -> torch.device:
        return torch.device(self.config.device)

    # -- optimisation --------------------------------------------------------------------------
    @abstractmethod
    def backward(self, loss: torch.Tensor) -> None:
        """Accumulate gradients of `loss` (already normalised as this rank's share of the batch)."""

    @abstractmethod
    def step(self) -> float:
        """Clip, apply one optimizer update, zero the gradients; return the pre-clip global grad norm."""

    @property
    def grad_scale(self) -> float:
        """Factor applied to this rank's loss so the cross-rank gradient reduction yields the batch gradient.

        Data-parallel reductions average over ranks; our losses are already shares of the global
        batch, so they are multiplied by the world size to turn the average back into a sum.
        """
        return float(self.world_size)

    # -- weights --------------------------------------------------------------------------------
    @abstractmethod
    def iter_full_parameters(self) -> Iterator[tuple[str, torch.Tensor]]:
        """Yield (name, full tensor) one module at a time (ZeRO-3: gathered, then released).

        Names are the checkpoint architecture's parameter names; a tied `lm_head.weight` is yielded
        under its own name too (receivers that tie may skip it).

        A yielded tensor is only valid until the next iteration; consumers copy or send it at once.
        Every rank must iterate (gathering is collective); all ranks see the full tensors.
        """

    def parameter_specs(self) -> list[tuple[str, list[int], torch.dtype]]:
        """(name, full shape, dtype) of what `iter_full_parameters` yields, in the same order, without gathering."""
        out = []
        # remove_duplicate=False: a tied lm_head.weight is listed (and published) under its own name.
        for name, p in self.policy.named_parameters(remove_duplicate=False):
            out.append((name, list(getattr(p, "ds_shape", p.shape)), p.dtype))
        return out

    def full_state_dict(self) -> dict[str, torch.Tensor] | None:
        """Full CPU weights gathered layer by layer; None on ranks other than 0."""
        out: dict[str, torch.Tensor] = {}
        for name, tensor in self.iter_full_parameters():
            if self.rank == 0:
                out[name] = tensor.detach().to("cpu", copy=True).contiguous()
        return out if self.rank == 0 else None

    @abstractmethod
    def load_full_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        """Overwrite the policy weights (every rank calls it; only rank 0's `state` is read under ZeRO-3)."""

    # -- checkpoint -----------------------------------------------------------------------------
    @abstractmethod
    def save_state(self, directory: Path) -> None:
        """Write this rank's optimizer state (and partitions) under `directory`."""

    @abstractmethod
    def load_state(self, directory: Path) -> None:
        """Restore what `save_state` wrote (weights-only / safetensors loading)."""

    def begin_forward(self) -> None:
        """Called before every forward on `policy` (DeepSpeed counts micro-steps there)."""

    def autocast(self):
        return contextlib.nullcontext()

    def shutdown(self) -> None:
        """Release process groups and memory."""


def load_causal_lm(model_dir: str, dtype: torch.dtype, device: str = "cpu", *,
                   train_vision_tower: bool = False) -> torch.nn.Module:
    """The policy from a checkpoint folder or cached hub id (`modeling.hf_checkpoint.load_model`),
    with the vision tower of a multimodal checkpoint frozen unless `train_vision_tower`, and its
    decoder on `sdpa_varlen` where transformers chose sdpa (packed micro-batches attend per sequence)."""
    from modeling.attention import use_varlen_attention
    from modeling.hf_checkpoint import freeze_vision_tower, load_model

    model = load_model(model_dir, dtype, device)
    use_varlen_attention(model)
    freeze_vision_tower(model, train_vision_tower=train_vision_tower)
    return model
