"""Which backend a config asks for. Apart from base.py so that the backends depend on the base
class and only this module depends on the backends (no import cycle)."""

from __future__ import annotations

from learner.backends.base import LearnerBackend
from modeling.config_models import LearnerConfig


def make_backend(config: LearnerConfig, model_dir: str, seed: int, rank: int = 0, world_size: int = 1,
                 master_port: int | None = None) -> LearnerBackend:
    """Instantiate the configured backend (imported lazily: the deepspeed one pulls in DeepSpeed)."""
    if config.backend == "torch":
        from learner.backends.torch_backend import TorchBackend

        return TorchBackend(config, model_dir, seed, rank, world_size)
    if config.backend == "deepspeed":
        from learner.backends.deepspeed_backend import DeepSpeedBackend

        return DeepSpeedBackend(config, model_dir, seed, rank, world_size, master_port=master_port)
    raise ValueError(f"learner.backend={config.backend!r}: expected 'torch' or 'deepspeed'")
