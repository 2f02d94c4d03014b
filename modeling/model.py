"""The policy model: a locally trained tokenizer, a tiny Qwen-architecture LM, and token log-probs.

Nothing here touches a model hub. The CPU path trains a byte-level BPE on the task corpus (plus
Python stdlib sources for coverage: a small synthetic corpus alone only reaches ~500 merges),
builds a Qwen3 causal LM from a config, and saves both with `save_pretrained` (safetensors).

The chat format is Qwen-style ChatML. Tool results are rendered on the user side inside a
`<tool_response>` block, exactly as `tool_turn_text` renders them, so the agent loop can work
token-in/token-out: it renders the prompt once with `apply_chat_template` and afterwards only
appends generated ids and `tokenizer.encode(tool_turn_text(result), add_special_tokens=False)`.

Example:
    >>> tok_dir = train_tokenizer(corpus_texts, vocab_size=4096, output_dir="runs/tok")
    >>> model_dir = build_tiny_model("runs/tiny", tok_dir)
    >>> model, tokenizer = load_policy(model_dir)
    >>> logprobs = per_token_logprobs(model, input_ids, attention_mask)   # [B, T]
"""

from __future__ import annotations

import glob
import os
import sysconfig
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import torch
import torch.nn.functional as F

import envs._runtime  # noqa: F401  (CPU-path environment defaults before transformers loads)
from modeling.attention import SDPA_VARLEN, decoder_config, use_varlen_attention
from modeling.transformers_setup import prepare_transformers

ENDOFTEXT = "<|endoftext|>"
IM_START = "<|im_start|>"
IM_END = "<|im_end|>"
PAD = "<|pad|>"
SPECIAL_TOKENS = [ENDOFTEXT, IM_START, IM_END, PAD]
# Added (non-special) tokens: they survive decoding, so a parser sees them in the text.
TOOL_TOKENS = ["<tool_call>", "</tool_call>", "<tool_response>", "</tool_response>"]

# Qwen-style ChatML. Written for this project. Roles: system, user, assistant, tool. Consecutive
# tool messages share one user turn, each in its own <tool_response> block; assistant messages
# may carry OpenAI-style `tool_calls`, rendered as Hermes <tool_call> JSON blocks. `tools` (OpenAI
# schemas) are listed in the system turn.
CHAT_TEMPLATE = (
    "{%- set ns = namespace(system_done=false) -%}"
    "{%- if tools -%}"
    "{{- '<|im_start|>system\\n' -}}"
    "{%- if messages and messages[0]['role'] == 'system' -%}"
    "{{- messages[0]['content'] + '\\n\\n' -}}{%- set ns.system_done = true -%}"
    "{%- endif -%}"
    "{{- '# Tools\\n\\nYou may call functions. Available functions:\\n<tools>' -}}"
    "{%- for tool in tools -%}{{- '\\n' + (tool | tojson) -}}{%- endfor -%}"
    "{{- '\\n</tools>\\n\\nFor each call, return a JSON object inside <tool_call></tool_call> tags:\\n"
    "<tool_call>\\n{\"name\": <function-name>, \"arguments\": <args-json-object>}\\n</tool_call>"
    "<|im_end|>\\n' -}}"
    "{%- endif -%}"
    "{%- for message in messages -%}"
    "{%- if message['role'] == 'system' -%}"
    "{%- if not ns.system_done -%}"
    "{{- '<|im_start|>system\\n' + message['content'] + '<|im_end|>\\n' -}}{%- set ns.system_done = true -%}"
    "{%- endif -%}"
    "{%- elif message['role'] == 'user' -%}"
    "{{- '<|im_start|>user\\n' + message['content'] + '<|im_end|>\\n' -}}"
    "{%- elif message['role'] == 'assistant' -%}"
    "{{- '<|im_start|>assistant\\n' + (message['content'] or '') -}}"
    "{%- for call in (message.get('tool_calls') or []) -%}"
    "{%- set fn = call['function'] if call.get('function') else call -%}"
    "{%- if (loop.first and message['content']) or not loop.first -%}{{- '\\n' -}}{%- endif -%}"
    "{{- '<tool_call>\\n{\"name\": \"' + fn['name'] + '\", \"arguments\": ' -}}"
    "{%- if fn['arguments'] is string -%}{{- fn['arguments'] -}}{%- else -%}{{- fn['arguments'] | tojson -}}{%- endif -%}"
    "{{- '}\\n</tool_call>' -}}"
    "{%- endfor -%}"
    "{{- '<|im_end|>\\n' -}}"
    "{%- elif message['role'] == 'tool' -%}"
    "{%- if loop.first or messages[loop.index0 - 1]['role'] != 'tool' -%}{{- '<|im_start|>user' -}}{%- endif -%}"
    "{{- '\\n<tool_response>\\n' + message['content'] + '\\n</tool_response>' -}}"
    "{%- if loop.last or messages[loop.index0 + 1]['role'] != 'tool' -%}{{- '<|im_end|>\\n' -}}{%- endif -%}"
    "{%- endif -%}"
    "{%- endfor -%}"
    "{%- if add_generation_prompt -%}{{- '<|im_start|>assistant\\n' -}}{%- endif -%}"
)

# How a reply rendered by CHAT_TEMPLATE parses back into a message (transformers' `response_template`,
# read by `tokenizer.parse_response`; TRL's tool loop needs it and recognises only the chat templates
# it ships): optional <think> reasoning, Hermes <tool_call> JSON blocks, the text up to <|im_end|>.
RESPONSE_TEMPLATE: dict = {
    "defaults": {"role": "assistant"},
    "start_anchor": "<|im_start|>assistant\n",
    "fields": {
        "reasoning_content": {"open": "<think>", "close_pattern": r"</think>\s*", "content": "text"},
        "tool_calls": {"open": "<tool_call>", "close_pattern": r"</tool_call>\s*", "repeats": True,
                       "content": "json", "transform": {"type": "function", "function": "{content}"}},
        "content": {"close_pattern": r"<\|im_end\|>\s*", "content": "text"},
    },
}


def tool_turn_text(tool_result: str) -> str:
    """The text that follows a finished assistant turn when the environment answers with a tool result.

    The generator stops after emitting `<|im_end|>`; what the chat template would render next is
    the newline closing that turn, the user-side tool response, and the next generation prompt.
    Tokenize it with `add_special_tokens=False` and append the ids (token-in/token-out).

    Args:
        tool_result: The observation text returned by `env.step`.
    """
    return f"\n{IM_START}user\n<tool_response>\n{tool_result}\n</tool_response>{IM_END}\n{IM_START}assistant\n"


def _stdlib_texts(max_files: int, max_chars_per_file: int = 20_000) -> Iterator[str]:
    """Python stdlib sources in a fixed order: varied code and prose for BPE coverage."""
    root = sysconfig.get_paths()["stdlib"]
    files = sorted(glob.glob(os.path.join(root, "*.py")))[:max_files]
    for path in files:
        try:
            with open(path, encoding="utf-8") as handle:
                yield handle.read(max_chars_per_file)
        except (OSError, UnicodeDecodeError):
            continue  # an unreadable stdlib file only costs coverage


def train_tokenizer(
    texts: Iterable[str],
    vocab_size: int,
    output_dir: str | os.PathLike,
    *,
    include_stdlib: bool = True,
    max_stdlib_files: int = 400,
    min_frequency: int = 2,
) -> Path:
    """Train a byte-level BPE tokenizer locally and save it with a ChatML chat template.

    Args:
        texts: The task corpus (tickets, policies, tool descriptions, answers ...).
        vocab_size: Target vocabulary size including the special and tool tokens (>= 300).
        output_dir: Where `save_pretrained` writes `tokenizer.json`, `tokenizer_config.json` and
            `chat_template.jinja`.
        include_stdlib: Also train on Python stdlib sources (deterministic file order) for coverage.
        max_stdlib_files: How many stdlib files to read when `include_stdlib` is set.
        min_frequency: Minimum pair frequency for a merge.

    Returns:
        The output directory.

    Raises:
        ValueError: If `vocab_size` is too small for the byte alphabet plus special tokens, or the
            corpus is empty.
    """
    from tokenizers import AddedToken, Tokenizer, decoders, models, pre_tokenizers, trainers
    from transformers import PreTrainedTokenizerFast

    min_vocab = 256 + len(SPECIAL_TOKENS) + len(TOOL_TOKENS)
    if vocab_size < min_vocab:
        raise ValueError(f"vocab_size={vocab_size} is below the byte alphabet plus special tokens ({min_vocab})")
    corpus = [t for t in texts if t]
    if not corpus and not include_stdlib:
        raise ValueError("texts is empty and include_stdlib is False: nothing to train the tokenizer on")
    if include_stdlib:
        corpus.extend(_stdlib_texts(max_stdlib_files))

    tok = Tokenizer(models.BPE())
    tok.pre_tokenizer = pre_tokenizers.ByteLevel(add_prefix_space=False)
    tok.decoder = decoders.ByteLevel()
    trainer = trainers.BpeTrainer(
        # The tool tokens are added below as added tokens; reserve their slots in the budget.
        vocab_size=vocab_size - len(TOOL_TOKENS),
        min_frequency=min_frequency,
        special_tokens=SPECIAL_TOKENS,
        initial_alphabet=pre_tokenizers.ByteLevel.alphabet(),
        show_progress=False,
    )
    tok.train_from_iterator(corpus, trainer=trainer)
    tok.add_tokens([AddedToken(t, special=False, normalized=False) for t in TOOL_TOKENS])

    tokenizer = PreTrainedTokenizerFast(
        tokenizer_object=tok,
        eos_token=IM_END,
        pad_token=PAD,
        unk_token=None,
        bos_token=None,
        # Must be a constructor argument: set afterwards it reloads as "right" (stack notes 3).
        padding_side="left",
        model_max_length=1_000_000,
        clean_up_tokenization_spaces=False,
    )
    tokenizer.chat_template = CHAT_TEMPLATE
    tokenizer.response_template = RESPONSE_TEMPLATE
    out = Path(output_dir)
    out.mkdir(parents=True, exist_ok=True)
    tokenizer.save_pretrained(str(out))
    return out


def load_tokenizer(tokenizer_dir: str | os.PathLike):
    """Load a tokenizer saved by `train_tokenizer` (or any local HF tokenizer directory)."""
    prepare_transformers()
    from transformers import AutoTokenizer

    path = Path(tokenizer_dir)
    if not (path / "tokenizer.json").exists() and not (path / "tokenizer_config.json").exists():
        raise FileNotFoundError(f"no tokenizer in {path} (expected tokenizer.json / tokenizer_config.json)")
    tokenizer = AutoTokenizer.from_pretrained(str(path), local_files_only=True)
    if tokenizer.chat_template == CHAT_TEMPLATE and getattr(tokenizer, "response_template", None) is None:
        tokenizer.response_template = RESPONSE_TEMPLATE  # saved before the template shipped one
    return tokenizer


TINY_MODEL_DEFAULTS: dict[str, object] = {
    "hidden_size": 128,
    "intermediate_size": 256,
    "num_hidden_layers": 2,
    "num_attention_heads": 4,
    "num_key_value_heads": 2,
    "head_dim": 32,
    "max_position_embeddings": 8192 + 12288,
    # Untied: the embedding and the LM head are separate tensors, so safetensors, ZeRO-3 gathering
    # and the EMA update never meet a shared tensor.
    "tie_word_embeddings": False,
    "rms_norm_eps": 1e-6,
    "rope_theta": 10000.0,
}


def build_tiny_model(
    output_dir: str | os.PathLike,
    tokenizer_dir: str | os.PathLike,
    *,
    architecture: str = "qwen3",
    seed: int = 0,
    **overrides,
) -> Path:
    """Build a Qwen-architecture causal LM from a config and save it (safetensors) with its tokenizer.

    Args:
        output_dir: Model directory to write (`config.json`, `model.safetensors`, tokenizer files).
        tokenizer_dir: Directory of the tokenizer (from `train_tokenizer`); copied next to the model
            so `load_policy(output_dir)` finds both.
        architecture: "qwen3" or "qwen2".
        seed: Seed for the random initialisation (same seed, same weights).
        **overrides: Config fields replacing `TINY_MODEL_DEFAULTS` (e.g. `hidden_size=64`).

    Returns:
        The output directory.

    Raises:
        ValueError: On an unknown architecture or config field.
    """
    prepare_transformers()
    from transformers import AutoModelForCausalLM, Qwen2Config, Qwen3Config

    config_cls = {"qwen3": Qwen3Config, "qwen2": Qwen2Config}.get(architecture)
    if config_cls is None:
        raise ValueError(f"architecture={architecture!r}: expected 'qwen3' or 'qwen2'")
    tokenizer = load_tokenizer(tokenizer_dir)
    fields = {**TINY_MODEL_DEFAULTS, **overrides}
    if architecture == "qwen2":
        fields.pop("head_dim", None)  # Qwen2 derives it from hidden_size / heads
    known = set(config_cls().to_dict()) | {"rope_theta", "head_dim"}
    unknown = sorted(k for k in fields if k not in known)
    if unknown:
        raise ValueError(f"build_tiny_model: unknown config field(s) {unknown} for {config_cls.__name__}")
    eos_ids = [tokenizer.convert_tokens_to_ids(t) for t in (IM_END, ENDOFTEXT)]
    config = config_cls(
        vocab_size=len(tokenizer),
        pad_token_id=tokenizer.pad_token_id,
        eos_token_id=eos_ids[0],
        bos_token_id=None,
        **fields,
    )
    torch.manual_seed(seed)
    model = AutoModelForCausalLM.from_config(config, dtype=torch.float32)
    return save_model_dir(model, tokenizer, eos_ids, output_dir, safe_serialization=True)


def save_model_dir(model, tokenizer, eos_ids: list[int], output_dir: str | os.PathLike, **save_kwargs) -> Path:
    """Write a freshly built model and its tokenizer as one model directory that generators load
    as they are: generation stops at `eos_ids`, pads with the tokenizer's pad id, and adds no BOS.

    Args:
        model: A `PreTrainedModel`.
        tokenizer: Its tokenizer (saved next to it).
        eos_ids: Token ids that end generation.
        output_dir: Directory to write (created).
        **save_kwargs: Passed to `save_pretrained` (e.g. `max_shard_size`).

    Returns:
        `output_dir` as a Path.
    """
    model.generation_config.eos_token_id = eos_ids
    model.generation_config.pad_token_id = tokenizer.pad_token_id
    model.generation_config.bos_token_id = None
    out = Path(output_dir)
    out.mkdir(parents=True, exist_ok=True)
    model.save_pretrained(str(out), **save_kwargs)
    tokenizer.save_pretrained(str(out))
    return out


# ---------------------------------------------------------------------------------------------
# Tiny twins: randomly initialised models with the exact module layout of the checkpoints people train
# ---------------------------------------------------------------------------------------------

#: Families a twin can be built for.
TWIN_FAMILIES: list[str] = ["qwen3", "qwen3_5", "llama_tied"]

#: Architecture class each family is saved as (config.architectures[0]).
TWIN_ARCHITECTURES: dict[str, str] = {
    "qwen3": "Qwen3ForCausalLM",
    "qwen3_5": "Qwen3_5ForConditionalGeneration",
    "llama_tied": "LlamaForCausalLM",
}

# Small enough that every twin has >= 2 shards (each embedding alone is vocab x 128 x 4 bytes).
TWIN_MAX_SHARD_SIZE = "1MB"

# head_dim 64 everywhere: vLLM's CPU attention rejects head_dim 16.
_TWIN_TEXT = {
    "hidden_size": 128,
    "intermediate_size": 256,
    "num_hidden_layers": 2,
    "num_attention_heads": 2,
    "num_key_value_heads": 1,
    "head_dim": 64,
    "max_position_embeddings": 32768,
    "rms_norm_eps": 1e-6,
}


def twin_family(architecture: str) -> str:
    """The twin family of a checkpoint architecture class (`config.architectures[0]`).

    Raises:
        ValueError: naming the architecture when no twin family has it.
    """
    for family, arch in TWIN_ARCHITECTURES.items():
        if arch == architecture:
            return family
    raise ValueError(f"no tiny twin for architecture {architecture!r}; twins exist for "
                     f"{sorted(TWIN_ARCHITECTURES.values())}")


def _twin_config(family: str, tokenizer):
    eos = [tokenizer.convert_tokens_to_ids(t) for t in (IM_END, ENDOFTEXT)]
    ids = {"vocab_size": len(tokenizer), "pad_token_id": tokenizer.pad_token_id, "eos_token_id": eos[0],
           "bos_token_id": None}
    if family == "qwen3":
        from transformers import Qwen3Config

        return Qwen3Config(**_TWIN_TEXT, **ids, tie_word_embeddings=False,
                           rope_parameters={"rope_type": "default", "rope_theta": 10000.0}), eos
    if family == "llama_tied":
        from transformers import LlamaConfig

        return LlamaConfig(**_TWIN_TEXT, **ids, tie_word_embeddings=True,
                           rope_parameters={"rope_type": "default", "rope_theta": 10000.0}), eos
    if family == "qwen3_5":
        from transformers import Qwen3_5Config

        text = {
            **_TWIN_TEXT, **ids,
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
                  "out_hidden_size": _TWIN_TEXT["hidden_size"], "num_position_embeddings": 64}
        # Image/video token ids: the tiny tokenizer has no vision tokens; text-only prompts never
        # contain these ids, so they only need to be distinct from real ones (beyond the vocab).
        n = len(tokenizer)
        return Qwen3_5Config(text_config=text, vision_config=vision, tie_word_embeddings=False,
                             image_token_id=n + 1, video_token_id=n + 2, vision_start_token_id=n + 3,
                             vision_end_token_id=n + 4), eos
    raise ValueError(f"build_twin_model: unknown family {family!r}; expected one of {TWIN_FAMILIES}")


def build_twin_model(family: str, out_dir: str | os.PathLike, tokenizer_dir: str | os.PathLike, *, seed: int = 0,
                     dtype: torch.dtype = torch.float32, max_shard_size: str = TWIN_MAX_SHARD_SIZE) -> Path:
    """Build a tiny twin of `family` from a config and save it sharded with the tokenizer.

    A twin has the exact module layout (names, layer kinds, tied or not, vision tower) of the
    family's real checkpoints at hidden size 128 and 2 layers, saved the way real checkpoints are
    distributed: sharded safetensors (at least two shards) plus index, config, generation config and
    tokenizer. `hcgym train --cpu-twin` (learner/cpu_twin.py) runs a cluster config on one.

    Args:
        family: One of `TWIN_FAMILIES`.
        out_dir: Directory to write.
        tokenizer_dir: A tokenizer directory (`train_tokenizer` output or a model dir).
        seed: Seed of the random initialisation (same seed, same weights).
        dtype: Storage dtype of the weights.
        max_shard_size: `save_pretrained`'s shard limit.

    Returns:
        `out_dir` as a Path.

    Raises:
        ValueError: On an unknown family, or when the saved twin has fewer than two shards.
    """
    import json

    prepare_transformers()
    import transformers

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
        raise ValueError(f"build_twin_model({family!r}): {out} has {len(shards)} shard(s); lower max_shard_size")
    return out


def load_policy(model_dir: str | os.PathLike, dtype: torch.dtype = torch.float32, *, tokenizer_dir=None):
    """Load a policy (the checkpoint's own architecture class) and its tokenizer.

    Goes through `modeling.hf_checkpoint.load_model`, the one loading path: sharded or single-file
    safetensors, tied or untied embeddings, multimodal wrappers (Qwen3.5, Qwen2.5-VL), a local
    folder or a hub id already in the Hugging Face cache.

    Args:
        model_dir: A checkpoint folder (`build_tiny_model`, `save_pretrained`, `save_sharded_checkpoint`)
            or a cached hub id.
        dtype: Parameter dtype.
        tokenizer_dir: Tokenizer directory when it is not stored next to the model.

    Returns:
        `(model, tokenizer)`; the model is in eval mode, its decoder on `sdpa_varlen` where
        transformers chose sdpa (`use_varlen_attention`: packed rows attend per sequence).
    """
    from modeling.hf_checkpoint import load_model, resolve_model_path

    prepare_transformers()
    path = resolve_model_path(model_dir)
    model = load_model(path, dtype)
    use_varlen_attention(model)
    tokenizer = load_tokenizer(tokenizer_dir or path)
    return model, tokenizer


# ----------------------------------------------------------------------------------------------
# Token log-probs
# ----------------------------------------------------------------------------------------------


@dataclass
class TokenStats:
    """Per-position statistics of a forward pass; position t describes the prediction of token t.

    All tensors are [B, T] (or [B, T, K]); position 0 has no prediction and holds 0.
    """

    logprobs: torch.Tensor                     # log p(x_t | x_<t)
    entropy: torch.Tensor | None = None        # H(p(. | x_<t))
    gathered: torch.Tensor | None = None       # log p(v | x_<t) at the requested ids, [B, T, K]
    topk_logprobs: torch.Tensor | None = None  # the model's own top-k log-probs, [B, T, K]
    topk_ids: torch.Tensor | None = None       # their token ids, [B, T, K]


def position_ids_from_mask(attention_mask: torch.Tensor) -> torch.Tensor:
    """Positions counting only real tokens, so left- and right-padded rows see the same positions."""
    return (attention_mask.long().cumsum(-1) - 1).clamp(min=0)


def _decoder_and_head(model):
    decoder = model.get_decoder() if hasattr(model, "get_decoder") else None
    head = model.get_output_embeddings() if hasattr(model, "get_output_embeddings") else None
    return decoder, head


#: Layer kinds whose attention is masked per token pair, so a block-diagonal mask (or a varlen
#: kernel) keeps packed sequences apart.
PACKABLE_LAYER_TYPES = frozenset({"full_attention", "sliding_attention"})

#: Recurrent layer kinds that run packed rows one sequence per row (`_run_linear_attention_per_sequence`).
#: Qwen3.5's Gated DeltaNet ("linear_attention", module `linear_attn`) carries a recurrent state and
#: a causal conv1d window along the row, and transformers' CPU path cannot be told where sequences
#: end (transformers 5.19, models/qwen3_5/modeling_qwen3_5.py): the layer passes `cu_seq_lens_q` on
#: as `cu_seqlens` to the delta rule only (lines 625, 638), never to the conv (line 580); the torch
#: fallbacks `causal_conv1d_fn` (line 260) and `torch_chunk_gated_delta_rule` (line 291) declare no
#: `seq_idx` / `cu_seqlens`, and the kernel wrapper drops every argument an implementation does not
#: declare (integrations/hub_kernels.py, `use_kernel_func_from_hub_with_fallback`). A packed row
#: through them as they are leaks each sequence's state and last conv inputs into the next.
PER_SEQUENCE_LAYER_TYPES = {"linear_attention": "linear_attn"}


#: Attention implementations that run packed sequences as variable-length batches (no dense mask):
#: flash attention's varlen kernels on GPU, and `sdpa_varlen` (modeling/attention.py), the one the
#: learner and teacher load with where transformers would use sdpa, CPU included, whose cost is the
#: sum of the sequences' L^2. Under the others (plain sdpa, eager) a packed row of N tokens attends
#: through a dense block-diagonal [N, N] mask, so its attention grows with N^2 against B * T^2
#: padded, and "auto" packs only where N^2 <= B * T^2 (docs/benchmarks.md, "Sequence packing").
VARLEN_ATTENTION = frozenset({"flash_attention_2", "flash_attention_3", SDPA_VARLEN})


def packs_sequences(setting: bool | str, model, attention_mask: torch.Tensor) -> bool:
    """Whether this batch of `model` runs packed under a `pack_sequences` setting: True, False, or "auto":
    always with a varlen attention (`VARLEN_ATTENTION`, read from the decoder's config), else when the
    packed row's attention area N^2 is no larger than the padded batch's B * T^2. Never where
    `packing_unsupported` names a reason."""
    if setting == "auto":
        if getattr(decoder_config(model), "_attn_implementation", None) in VARLEN_ATTENTION:
            wanted = True
        else:
            rows, width = attention_mask.shape
            wanted = int(attention_mask.sum()) ** 2 <= rows * width * width
    else:
        wanted = bool(setting)
    return wanted and packing_unsupported(model) is None


def packing_unsupported(model) -> str | None:
    """Why `model` cannot run packed sequences (`token_stats(packed=True)`), or None when it can."""
    config = model.config.get_text_config() if hasattr(model.config, "get_text_config") else model.config
    layer_types = list(getattr(config, "layer_types", None) or ())
    recurrent = sorted(set(layer_types) - PACKABLE_LAYER_TYPES - set(PER_SEQUENCE_LAYER_TYPES))
    if recurrent:
        return (f"{type(model).__name__} has {'/'.join(recurrent)} layers, whose state would cross from one "
                f"packed sequence into the next; run it padded")
    decoder = _decoder_and_head(model)[0]
    if decoder is None:
        return f"{type(model).__name__} has no separate decoder to run on the packed tokens"
    for kind, attribute in PER_SEQUENCE_LAYER_TYPES.items():
        wanted = layer_types.count(kind)
        found = len(_per_sequence_modules(decoder, attribute))
        if wanted and found != wanted:
            return (f"{type(model).__name__} has {wanted} {kind} layers but {found} '{attribute}' modules to run "
                    f"one sequence per row; run it padded")
    return None


def _per_sequence_modules(decoder, attribute: str) -> list[torch.nn.Module]:
    """The decoder layers' `attribute` submodules (Qwen3.5: each linear-attention layer's `linear_attn`)."""
    return [getattr(layer, attribute) for layer in getattr(decoder, "layers", ()) if hasattr(layer, attribute)]


def _run_linear_attention_per_sequence(module: torch.nn.Module) -> None:
    """Make `module` (a Gated DeltaNet) honour `cu_seq_lens_q` on a packed row: the row's sequences are
    laid out one per row (right-padded, with their padding mask) for one call of its own forward,
    and its output packed back. The recurrent state and the conv window then start from zero at every
    sequence start, exactly as in the padded pass (the padding's inputs are zeroed). These layers
    compute on padding (linear in its length); the attention, MLP, norms and LM head do not. One call
    per layer, as padded: ZeRO-3 gathers the same parameters in the same order on every rank however
    many sequences each packs. Without `cu_seq_lens_q` (generation, padded batches) it runs unchanged.
    Set on the instance, and the boundaries travel in the layer's kwargs, so a gradient-checkpointing
    recompute, DeepSpeed's module hooks and copies of the model see the same computation. Idempotent."""
    if getattr(module, "_runs_per_sequence", False):
        return
    whole = module.forward

    def forward(hidden_states, cache_params=None, attention_mask=None, **kwargs):
        bounds = kwargs.pop("cu_seq_lens_q", None)
        if bounds is None:
            return whole(hidden_states, cache_params=cache_params, attention_mask=attention_mask, **kwargs)
        if hidden_states.shape[0] != 1 or cache_params is not None or attention_mask is not None:
            raise ValueError(f"{type(module).__name__}: cu_seq_lens_q needs one packed row [1, N, H] without a cache "
                             f"or padding mask; got hidden_states {tuple(hidden_states.shape)}, cache "
                             f"{cache_params is not None}, mask {attention_mask is not None}")
        for key in ("cu_seq_lens_k", "max_length_q", "max_length_k"):
            kwargs.pop(key, None)
        device = hidden_states.device
        lengths = bounds.diff().long().to(device)
        rows = torch.arange(lengths.numel(), device=device).repeat_interleave(lengths)
        cols = torch.arange(hidden_states.shape[1], device=device) - bounds[:-1].long().to(device).repeat_interleave(lengths)
        mask = torch.zeros((lengths.numel(), int(lengths.max())), dtype=torch.long, device=device)
        mask[rows, cols] = 1
        # Out of place: gradients reach the packed hidden states.
        padded = hidden_states.new_zeros((*mask.shape, hidden_states.shape[-1])).index_put((rows, cols), hidden_states[0])
        return whole(padded, attention_mask=mask, **kwargs)[rows, cols].unsqueeze(0)

    module.forward = forward
    module._runs_per_sequence = True


def _decoder_hidden(decoder, input_ids: torch.Tensor, attention_mask: torch.Tensor, position_ids: torch.Tensor,
                    packed: bool) -> torch.Tensor:
    """The decoder's last hidden states, [B, T, H]; `packed`: computed on the real tokens only.

    Packed, the rows' real tokens run as one sequence [1, N] whose position ids restart at each
    row and with no attention mask, and with the rows' boundaries as transformers' varlen kwargs
    (`cu_seq_lens_q/k`, `max_length_q/k`): `sdpa_varlen` and flash attention's varlen kernel attend
    within each sequence from them, plain sdpa and eager through the dense block-diagonal mask
    transformers builds from the restarting position ids, so a token attends only to its own row's
    earlier tokens, as in the padded pass. Recurrent layers (`PER_SEQUENCE_LAYER_TYPES`) lay each
    sequence out in a row of its own from the same boundaries.
    Padding positions come back as zeros (no prediction reads them).
    """
    if not packed:
        return decoder(input_ids=input_ids, attention_mask=attention_mask, position_ids=position_ids).last_hidden_state
    real = attention_mask.bool()
    for attribute in PER_SEQUENCE_LAYER_TYPES.values():
        for module in _per_sequence_modules(decoder, attribute):
            _run_linear_attention_per_sequence(module)
    lengths = real.sum(-1)
    lengths = lengths[lengths > 0]
    cu = F.pad(lengths.cumsum(0), (1, 0)).to(torch.int32)
    longest = int(lengths.max())
    boundaries = {"cu_seq_lens_q": cu, "cu_seq_lens_k": cu, "max_length_q": longest, "max_length_k": longest}
    flat = decoder(input_ids=input_ids[real].unsqueeze(0), attention_mask=None,
                   position_ids=position_ids[real].unsqueeze(0), use_cache=False, **boundaries).last_hidden_state[0]
    out = flat.new_zeros((*input_ids.shape, flat.shape[-1]))
    return out.index_put(real.nonzero(as_tuple=True), flat)  # out of place: gradients reach `flat`


def padding_fraction(attention_mask: torch.Tensor, packed: bool = False) -> tuple[int, int]:
    """(padding positions, positions) the decoder computes on for this batch: packed, none are padding."""
    real = int(attention_mask.sum())
    computed = real if packed else int(attention_mask.numel())
    return computed - real, computed


def token_stats(
    model,
    input_ids: torch.Tensor,
    attention_mask: torch.Tensor,
    *,
    temperature: float = 1.0,
    with_entropy: bool = False,
    gather_ids: torch.Tensor | None = None,
    topk: int = 0,
    chunk_size: int = 1024,
    entropy_requires_grad: bool = False,
    positions: torch.Tensor | None = None,
    packed: bool = False,
) -> TokenStats:
    """One forward pass, then log-probs (and optional entropy / top-k) computed chunk by chunk.

    Computing the LM head and log-softmax over chunks of positions keeps the [T, vocab] logits
    of a long multi-turn episode (20K tokens x 150K vocab on the GPU configs) from being
    materialised at once.

    Args:
        model: A causal LM (transformers).
        input_ids: [B, T] token ids.
        attention_mask: [B, T] 1 on real tokens (left or right padding both work).
        temperature: Logits are divided by it, matching the sampler's distribution.
        with_entropy: Also return the entropy of the predictive distribution.
        gather_ids: Optional [B, T, K] ids whose log-probs to return (the teacher's top-k).
        topk: If > 0, also return the model's own top-k log-probs and ids.
        chunk_size: Positions per LM-head chunk.
        entropy_requires_grad: Keep the entropy in the autograd graph (only for an entropy bonus;
            otherwise it is computed without grad so its [chunk, vocab] intermediates are not kept).
        positions: Optional [B, T] mask of the positions whose statistics are needed (the trained
            tokens: the loss mask). The LM head and log-softmax then run only on the hidden states
            that predict them, and every other position holds 0. The decoder still reads the whole
            sequence, so the values at these positions are the full pass's (up to float rounding).
            In a multi-turn episode most positions are prompt and tool text: skipping their
            [vocab]-wide head and softmax is most of the reference and teacher cost.
        packed: Run the decoder on the real tokens only: the rows' tokens concatenated into one
            sequence whose position ids restart at each row, so no layer computes on padding
            (`_decoder_hidden`; `packing_unsupported` says which models cannot). The
            statistics come back in the [B, T] layout, equal to the padded pass's within float
            rounding.

    Returns:
        A `TokenStats` whose position t is the prediction of token t given tokens < t.
    """
    if input_ids.dim() != 2 or attention_mask.shape != input_ids.shape:
        raise ValueError(
            f"input_ids must be [B, T] and attention_mask the same shape; got {tuple(input_ids.shape)} "
            f"and {tuple(attention_mask.shape)}"
        )
    if temperature <= 0:
        raise ValueError(f"temperature must be > 0, got {temperature}")
    if gather_ids is not None and gather_ids.shape[:2] != input_ids.shape:
        raise ValueError(f"gather_ids must be [B, T, K] with [B, T]={tuple(input_ids.shape)}, got {tuple(gather_ids.shape)}")
    if positions is not None and positions.shape != input_ids.shape:
        raise ValueError(f"positions must be [B, T]={tuple(input_ids.shape)}, got {tuple(positions.shape)}")
    position_ids = position_ids_from_mask(attention_mask)
    decoder, head = _decoder_and_head(model)
    if packed:
        why = packing_unsupported(model)
        if why is not None:
            raise ValueError(f"packed sequences: {why}")
    B, T = input_ids.shape
    if positions is not None:
        return _sliced_token_stats(model, decoder, head, input_ids, attention_mask, position_ids, positions,
                                   temperature=temperature, with_entropy=with_entropy, gather_ids=gather_ids,
                                   topk=topk, chunk_size=chunk_size, entropy_requires_grad=entropy_requires_grad,
                                   packed=packed)
    if decoder is not None and head is not None:
        hidden = _decoder_hidden(decoder, input_ids, attention_mask, position_ids, packed)
        logits_of = lambda lo, hi: head(hidden[:, lo:hi])
    else:  # a model without the decoder/head split: full logits in one go
        full = model(input_ids=input_ids, attention_mask=attention_mask, position_ids=position_ids).logits
        logits_of = lambda lo, hi: full[:, lo:hi]

    # Predictions for targets 1..T-1 come from positions 0..T-2.
    targets = input_ids[:, 1:]
    lp_parts, ent_parts, gat_parts, tkv_parts, tki_parts = [], [], [], [], []
    for lo in range(0, T - 1, chunk_size):
        hi = min(lo + chunk_size, T - 1)
        logp = F.log_softmax(logits_of(lo, hi).float() / temperature, dim=-1)
        lp_parts.append(logp.gather(-1, targets[:, lo:hi].unsqueeze(-1)).squeeze(-1))
        if with_entropy:
            with torch.set_grad_enabled(entropy_requires_grad and torch.is_grad_enabled()):
                ent_parts.append(-(logp.exp() * logp).sum(-1))
        if gather_ids is not None:
            gat_parts.append(logp.gather(-1, gather_ids[:, lo + 1 : hi + 1]))
        if topk:
            vals, ids = logp.topk(topk, dim=-1)
            tkv_parts.append(vals)
            tki_parts.append(ids)

    def stitch(parts, trailing=()):
        zero = torch.zeros((B, 1, *trailing), dtype=torch.float32, device=input_ids.device)
        return torch.cat([zero, *parts], dim=1) if parts else zero.expand(B, T, *trailing).clone()

    # A prediction exists only where both the token and its predecessor are real: padding and the
    # first real token of a left-padded row get 0, like position 0.
    valid = _valid_predictions(attention_mask)
    stats = TokenStats(logprobs=stitch(lp_parts) * valid)
    if with_entropy:
        stats.entropy = stitch(ent_parts) * valid
    if gather_ids is not None:
        stats.gathered = stitch(gat_parts, (gather_ids.shape[-1],)) * valid.unsqueeze(-1)
    if topk:
        stats.topk_logprobs = stitch(tkv_parts, (topk,)) * valid.unsqueeze(-1)
        ids = torch.cat([torch.zeros((B, 1, topk), dtype=torch.long, device=input_ids.device), *tki_parts], 1)
        stats.topk_ids = ids * valid.long().unsqueeze(-1)
    return stats


def _valid_predictions(attention_mask: torch.Tensor) -> torch.Tensor:
    """1 where a prediction exists: the token and its predecessor are real (never position 0)."""
    valid = attention_mask.clone().float()
    valid[:, 1:] *= attention_mask[:, :-1].float()
    valid[:, 0] = 0.0
    return valid


def _sliced_token_stats(model, decoder, head, input_ids, attention_mask, position_ids, positions, *,
                        temperature: float, with_entropy: bool, gather_ids, topk: int, chunk_size: int,
                        entropy_requires_grad: bool, packed: bool = False) -> TokenStats:
    """`token_stats` at the requested positions only: the decoder's hidden states that predict them
    are gathered into one [N, hidden] block before the LM head, and the results scattered back."""
    B, T = input_ids.shape
    device = input_ids.device
    selected = (positions.to(device).bool() & _valid_predictions(attention_mask).bool())
    rows, cols = selected.nonzero(as_tuple=True)      # cols >= 1: the predicted token's position
    if decoder is not None and head is not None:
        hidden = _decoder_hidden(decoder, input_ids, attention_mask, position_ids, packed)
        picked = hidden[rows, cols - 1]                # the hidden state that predicts token cols
        logits_of = lambda lo, hi: head(picked[lo:hi])
    else:  # a model without the decoder/head split: slice its full logits
        full = model(input_ids=input_ids, attention_mask=attention_mask, position_ids=position_ids).logits
        picked = full[rows, cols - 1]
        logits_of = lambda lo, hi: picked[lo:hi]
    targets = input_ids[rows, cols]
    n = int(rows.numel())
    lp_parts, ent_parts, gat_parts, tkv_parts, tki_parts = [], [], [], [], []
    for lo in range(0, n, chunk_size):
        hi = min(lo + chunk_size, n)
        logp = F.log_softmax(logits_of(lo, hi).float() / temperature, dim=-1)
        lp_parts.append(logp.gather(-1, targets[lo:hi].unsqueeze(-1)).squeeze(-1))
        if with_entropy:
            with torch.set_grad_enabled(entropy_requires_grad and torch.is_grad_enabled()):
                ent_parts.append(-(logp.exp() * logp).sum(-1))
        if gather_ids is not None:
            gat_parts.append(logp.gather(-1, gather_ids[rows[lo:hi], cols[lo:hi]]))
        if topk:
            vals, ids = logp.topk(topk, dim=-1)
            tkv_parts.append(vals)
            tki_parts.append(ids)

    def scatter(parts, trailing=(), dtype=torch.float32):
        values = torch.cat(parts) if parts else torch.zeros((0, *trailing), dtype=dtype, device=device)
        out = torch.zeros((B, T, *trailing), dtype=dtype, device=device)
        return out.index_put((rows, cols), values.to(dtype))  # out of place: gradients reach `values`

    stats = TokenStats(logprobs=scatter(lp_parts))
    if with_entropy:
        stats.entropy = scatter(ent_parts)
    if gather_ids is not None:
        stats.gathered = scatter(gat_parts, (gather_ids.shape[-1],))
    if topk:
        stats.topk_logprobs = scatter(tkv_parts, (topk,))
        stats.topk_ids = scatter(tki_parts, (topk,), dtype=torch.long)
    return stats


def per_token_logprobs(
    model, input_ids: torch.Tensor, attention_mask: torch.Tensor, *, temperature: float = 1.0
) -> torch.Tensor:
    """Log-prob of token t given tokens < t, as [B, T] float32; position 0 gets 0.

    Args:
        model: A causal LM.
        input_ids: [B, T] token ids.
        attention_mask: [B, T] mask of real tokens.
        temperature: The sampling temperature the ids were drawn at.
    """
    return token_stats(model, input_ids, attention_mask, temperature=temperature).logprobs


def per_token_entropy(
    model, input_ids: torch.Tensor, attention_mask: torch.Tensor, *, temperature: float = 1.0
) -> torch.Tensor:
    """Entropy of the predictive distribution for token t, [B, T]; position 0 gets 0."""
    return token_stats(model, input_ids, attention_mask, temperature=temperature, with_entropy=True).entropy


def split_by_budget(indices: list[int], lengths: list[int], max_samples: int,
                    max_tokens: int | None = None) -> list[list[int]]:
    """`indices` in order, cut into groups of at most `max_samples` samples and, with `max_tokens`, at
    most that many tokens (`lengths[i]` each; a longer sample is a group alone)."""
    groups: list[list[int]] = []
    current: list[int] = []
    tokens = 0
    for i in indices:
        full = len(current) >= max_samples or (max_tokens is not None and current and tokens + lengths[i] > max_tokens)
        if full:
            groups.append(current)
            current, tokens = [], 0
        current.append(i)
        tokens += lengths[i]
    if current:
        groups.append(current)
    return groups


def split_by_length(indices: list[int], lengths: list[int], max_samples: int,
                    max_tokens: int | None = None) -> list[list[int]]:
    """`indices` sorted longest first (ties keep their order), then cut as `split_by_budget` cuts: each
    group holds sequences of about one length, so padding a group to its longest adds little. The
    longest group comes first, so a micro-batch that does not fit in memory fails at once."""
    return split_by_budget(sorted(indices, key=lambda i: -lengths[i]), lengths, max_samples, max_tokens)


def split_batches(order: str, indices: list[int], lengths: list[int], max_samples: int,
                  max_tokens: int | None = None) -> list[list[int]]:
    """`split_by_length` (order "length") or `split_by_budget` (order "index")."""
    if order == "length":
        return split_by_length(indices, lengths, max_samples, max_tokens)
    if order == "index":
        return split_by_budget(indices, lengths, max_samples, max_tokens)
    raise ValueError(f"batch order must be 'length' or 'index', got {order!r}")


def pad_batch(sequences: list[list[int]], pad_id: int, *, side: str = "right") -> tuple[torch.Tensor, torch.Tensor]:
    """Pad id lists into ([B, T] ids, [B, T] mask); right padding keeps position t at column t."""
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    if not sequences:
        raise ValueError("pad_batch: no sequences")
    T = max(len(s) for s in sequences)
    ids = torch.full((len(sequences), T), pad_id, dtype=torch.long)
    mask = torch.zeros((len(sequences), T), dtype=torch.long)
    for i, seq in enumerate(sequences):
        if side == "right":
            ids[i, : len(seq)] = torch.tensor(seq, dtype=torch.long)
            mask[i, : len(seq)] = 1
        else:
            ids[i, T - len(seq) :] = torch.tensor(seq, dtype=torch.long)
            mask[i, T - len(seq) :] = 1
    return ids, mask
