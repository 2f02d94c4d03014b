"""Tiny twins for the tests: the project's own builder (`modeling.model.build_twin_model`), which
`hcgym train --cpu-twin` uses too.

Each twin is built from a config (no model hub), shares the project's locally trained tokenizer, and
is saved the way real checkpoints are distributed: sharded safetensors (a small `max_shard_size`, so
there are always at least two shards) plus `model.safetensors.index.json`, `config.json`,
`generation_config.json` and the tokenizer files.

Families (`TWIN_FAMILIES`):
- "qwen3": `Qwen3ForCausalLM`, untied embeddings, names `model.layers.*`, `model.embed_tokens.*`, `lm_head.weight`.
- "qwen3_5": `Qwen3_5ForConditionalGeneration` with its vision tower: hybrid linear/full attention layers
  under `model.language_model.*`, the vision tower under `model.visual.*`, `lm_head.weight`.
- "llama_tied": `LlamaForCausalLM` with tied embeddings (`lm_head.weight` is not stored in the file).

head_dim is 64 everywhere: vLLM's CPU attention rejects head_dim 16.

Example:
    >>> from tests.training.twins import TWIN_FAMILIES, build_twin
    >>> for family in TWIN_FAMILIES:
    ...     model_dir = build_twin(family, tmp / family, tokenizer_dir)
"""

from __future__ import annotations

from modeling.model import TWIN_ARCHITECTURES, TWIN_FAMILIES, TWIN_MAX_SHARD_SIZE
from modeling.model import build_twin_model as build_twin

__all__ = ["TWIN_FAMILIES", "TWIN_ARCHITECTURES", "TWIN_MAX_SHARD_SIZE", "build_twin"]
