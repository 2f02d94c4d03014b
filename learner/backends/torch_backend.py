"""Single-process PyTorch backend: the policy, AdamW, gradient clipping, a frozen reference copy."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import torch

from learner.backends.base import DTYPES, LearnerBackend, load_causal_lm
from modeling.checkpoint import load_torch_state, save_torch_state
from modeling.config_models import LearnerConfig
from modeling.hf_checkpoint import tied_parameter_aliases


class TorchBackend(LearnerBackend):
    """Plain PyTorch on one device (CPU for the tests and the demo)."""

    name = "torch"

    def __init__(self, config: LearnerConfig, model_dir: str, seed: int, rank: int = 0, world_size: int = 1):
        if world_size != 1:
            raise ValueError(f"the torch backend runs a single rank; got world_size={world_size}")
        super().__init__(config, model_dir, seed, rank, world_size)
        torch.manual_seed(seed)
        dtype = DTYPES[config.dtype]
        self._model = load_causal_lm(model_dir, dtype, config.device, train_vision_tower=config.train_vision_tower)
        if config.gradient_checkpointing:
            self._model.gradient_checkpointing_enable()
        self._model.train()
        o = config.optim
        self._optimizer = torch.optim.AdamW(
            [p for p in self._model.parameters() if p.requires_grad],
            lr=o.lr, betas=o.betas, eps=o.eps, weight_decay=o.weight_decay,
        )
        self._reference = None
        if config.loss.grpo.kl_beta > 0:
            self._reference = load_causal_lm(config.reference_model_dir or model_dir, dtype, config.device)
            self._reference.eval().requires_grad_(False)

    @property
    def policy(self) -> torch.nn.Module:
        return self._model

    @property
    def reference(self) -> torch.nn.Module | None:
        return self._reference

    @property
    def grad_scale(self) -> float:
        return 1.0

    def backward(self, loss: torch.Tensor) -> None:
        loss.backward()

    def step(self) -> float:
        params = [p for p in self._model.parameters() if p.requires_grad]
        norm = torch.nn.utils.clip_grad_norm_(params, self.config.optim.max_grad_norm)
        self._optimizer.step()
        self._optimizer.zero_grad(set_to_none=True)
        return float(norm)

    def iter_full_parameters(self) -> Iterator[tuple[str, torch.Tensor]]:
        yield from self._model.state_dict().items()

    def parameter_specs(self) -> list[tuple[str, list[int], torch.dtype]]:
        return [(k, list(v.shape), v.dtype) for k, v in self._model.state_dict().items()]

    def load_full_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        missing, unexpected = self._model.load_state_dict(state, strict=False)
        # A tied alias (lm_head.weight) may be absent: it is loaded through the tensor it shares.
        aliases = tied_parameter_aliases(self._model)
        missing = [m for m in missing if m not in aliases]
        if missing or unexpected:
            raise ValueError(f"weights do not match the policy: missing {missing[:5]}, unexpected {unexpected[:5]}")

    def save_state(self, directory: Path) -> None:
        save_torch_state(Path(directory) / "optimizer.pt", self._optimizer.state_dict())

    def load_state(self, directory: Path) -> None:
        self._optimizer.load_state_dict(load_torch_state(Path(directory) / "optimizer.pt"))
