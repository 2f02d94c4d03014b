"""Tiny twins: randomly initialised models with the exact module layout of the checkpoints people train.

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

import json
import os
from pathlib import Path

import torch

TWIN_FAMILIES: list[str] = ["qwen3", "qwen3_5", "llama_tied"]

# Architecture class each family is saved as (config.architectures[0]).
TWIN_ARCHITECTURES: dict[str, str] = {
    "qwen3": "Qwen3ForCausalLM",
    "qwen3_5": "Qwen3_5ForConditionalGeneration",
    "llama_tied": "LlamaForCausalLM",
}

# Small enough that every twin has >= 2 shards (each embedding alone is vocab x 128 x 4 bytes).
TWIN_MAX_SHARD_SIZE = "1MB"

_TEXT = {
    "hidden_size": 128,
    "intermediate_size": 256,
    "num_hidden_layers": 2,
    "num_attention_heads": 2,
    "num_key_value_heads": 1,
    "head_dim": 64,
    "max_position_embeddings": 4096,
    "rms_norm_eps": 1e-6,
}


def _twin_config(family: str, tokenizer):
    from modeling.model import ENDOFTEXT, IM_END

    eos = [tokenizer.convert_tokens_to_ids(t) for t in (IM_END, ENDOFTEXT)]
    ids = {"vocab_size": len(tokenizer), "pad_token_id": tokenizer.pad_token_id, "eos_token_id": eos[0],
           "bos_token_id": None}
    if family == "qwen3":
        from transformers import Qwen3Config

        return Qwen3Config(**_TEXT, **ids, tie_word_embeddings=False,
                           rope_parameters={"rope_type": "default", "rope_theta": 10000.0}), eos
    if family == "llama_tied":
        from transformers import LlamaConfig

        return LlamaConfig(**_TEXT, **ids, tie_word_embeddings=True,
                           rope_parameters={"rope_type": "default", "rope_theta": 10000.0}), eos
    if family == "qwen3_5":
        from transformers import Qwen3_5Config

        text = {
            **_TEXT, **ids,
            # One layer of each kind, like the real 3:1 linear/full pattern in miniature.
            "layer_types": ["linear_attention", "full_attention"],
            "linear_conv_kernel_dim": 4,
            "linear_key_head_dim": 64,
            "linear_value_head_dim": 64,
            "linear_num_key_heads": 2,
            "linear_num_value_heads": 2,
            # Rotary over a quarter of head_dim (16 dims = 8 frequency pairs), split 3/3/2 over
            # (time, height, width) as the real checkpoints split 11/11/10 of their 32 pairs.
            "rope_parameters": {"rope_type": "default", "rope_theta": 10000.0, "partial_rotary_factor": 0.25,
                                "mrope_section": [3, 3, 2], "mrope_interleaved": True},
            "tie_word_embeddings": False,
        }
        vision = {"depth": 1, "hidden_size": 128, "intermediate_size": 256, "num_heads": 2, "in_channels": 3,
                  "patch_size": 16, "spatial_merge_size": 2, "temporal_patch_size": 2,
                  "out_hidden_size": _TEXT["hidden_size"], "num_position_embeddings": 64}
        # Image/video token ids: the tiny tokenizer has no vision tokens; text-only prompts never
        # contain these ids, so they only need to be distinct from real ones (beyond the vocab).
        n = len(tokenizer)
        return Qwen3_5Config(text_config=text, vision_config=vision, tie_word_embeddings=False,
                             image_token_id=n + 1, video_token_id=n + 2, vision_start_token_id=n + 3,
                             vision_end_token_id=n + 4), eos
    raise ValueError(f"build_twin: unknown family {family!r}; expected one of {TWIN_FAMILIES}")


def build_twin(family: str, out_dir: str | os.PathLike, tokenizer_dir: str | os.PathLike, *, seed: int = 0,
               dtype: torch.dtype = torch.float32, max_shard_size: str = TWIN_MAX_SHARD_SIZE) -> Path:
    """Build a tiny twin of `family` from a config and save it sharded with the tokenizer.

    Args:
        family: One of `TWIN_FAMILIES`.
        out_dir: Directory to write.
        tokenizer_dir: A tokenizer directory (`modeling.model.train_tokenizer` output or a model dir).
        seed: Seed of the random initialisation (same seed, same weights).
        dtype: Storage dtype of the weights.
        max_shard_size: `save_pretrained`'s shard limit.

    Returns:
        `out_dir` as a Path.

    Raises:
        ValueError: On an unknown family, or when the saved twin has fewer than two shards.
    """
    import transformers

    from modeling.model import load_tokenizer, save_model_dir

    tokenizer = load_tokenizer(tokenizer_dir)
    config, eos = _twin_config(family, tokenizer)
    cls = getattr(transformers, TWIN_ARCHITECTURES[family])
    torch.manual_seed(seed)
    model = cls(config).to(dtype)
    model.config.architectures = [TWIN_ARCHITECTURES[family]]
    out = save_model_dir(model, tokenizer, eos, out_dir, max_shard_size=max_shard_size)
    index = out / "model.safetensors.index.json"
    shards = set(json.loads(index.read_text())["weight_map"].values()) if index.exists() else set()
    if len(shards) < 2:
        raise ValueError(f"build_twin({family!r}): {out} has {len(shards)} shard(s); lower max_shard_size")
    return out
